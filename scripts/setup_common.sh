# magcomp: shared set-up for scripts/test and scripts/demo (sourced, not run).
# Installs the Debian packages the package needs when missing, then builds it in a
# catkin workspace under .ws (the repository is linked in as src/magcomp; the dot keeps
# roslaunch's resource search from walking back into it).
set -euo pipefail

MAGCOMP_REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
MAGCOMP_WS="${MAGCOMP_WS:-$MAGCOMP_REPO/.ws}"
# Debian's python3 first: the pyenv python3 on PATH lacks catkin_pkg and friends.
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"

# Debian packages: derived from package.xml (scripts/deps), the one place dependencies are listed.
magcomp_install_packages() {
  "$MAGCOMP_REPO/scripts/deps" --install
  "$MAGCOMP_REPO/scripts/deps" --check
}

magcomp_build() {
  mkdir -p "$MAGCOMP_WS/src"
  if [ ! -e "$MAGCOMP_WS/src/magcomp" ]; then
    ln -s "$MAGCOMP_REPO" "$MAGCOMP_WS/src/magcomp"
  fi
  (cd "$MAGCOMP_WS" && catkin_make -j2 -DCMAKE_BUILD_TYPE=Release \
      -DPYTHON_EXECUTABLE=/usr/bin/python3 "$@")
  # shellcheck disable=SC1091
  set +u
  source "$MAGCOMP_WS/devel/setup.bash"
  set -u
  MAGCOMP_BIN="$MAGCOMP_WS/devel/lib/magcomp"   # nodes, benchmarks
  MAGCOMP_CLI="$MAGCOMP_WS/devel/bin/magcomp"   # the command-line tool (on PATH after setup.bash)
  export MAGCOMP_BIN MAGCOMP_CLI
}
