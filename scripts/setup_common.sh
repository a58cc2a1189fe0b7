# magcomp: shared set-up for scripts/test and scripts/demo (sourced, not run).
# Installs the Debian packages the package needs when missing, then builds it in an
# out-of-source catkin workspace under build/ws (the repository is linked in as src/magcomp).
set -euo pipefail

MAGCOMP_REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
MAGCOMP_WS="${MAGCOMP_WS:-$MAGCOMP_REPO/build/ws}"
MAGCOMP_REFERENCE_DIR="${MAGCOMP_REFERENCE_DIR:-$MAGCOMP_REPO/../shared/reference}"
# Debian's python3 first: the pyenv python3 on PATH lacks catkin_pkg and friends.
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"

MAGCOMP_APT_PACKAGES=(
  build-essential cmake catkin ros-cmake-modules libroscpp-dev librosbag-dev librosbag-storage-dev
  libtf2-dev libtf2-ros-dev libtf2-msgs-dev libtf2-geometry-msgs-dev libmessage-filters-dev
  librostest-dev python3-rostest ros-message-generation ros-message-runtime python3-genmsg
  python3-gencpp python3-genpy ros-std-msgs libstd-msgs-dev ros-sensor-msgs libsensor-msgs-dev
  ros-geometry-msgs libgeometry-msgs-dev python3-roslaunch python3-rosmaster rosout python3-rosbag
  python3-rospy python3-rostopic python3-rosnode python3-rosparam python3-rosmsg rosbash
  rospack-tools libgtest-dev googletest libeigen3-dev libhdf5-dev python3-h5py python3-numpy
  python3-scipy python3-matplotlib python3-yaml libdiagnostic-updater-dev python3-diagnostic-msgs
  libnodeletlib-dev libnodelet-dev ros-nav-msgs libnav-msgs-dev ros-visualization-msgs
  libvisualization-msgs-dev libstd-srvs-dev ros-std-srvs libyaml-cpp-dev nlohmann-json3-dev
  libcli11-dev libtorch-dev libros-rosgraph-msgs-dev
)

magcomp_install_packages() {
  local missing=()
  for p in "${MAGCOMP_APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    return 0
  fi
  echo "magcomp: installing ${#missing[@]} Debian package(s): ${missing[*]}"
  if [ "$(id -u)" -ne 0 ]; then
    if command -v sudo >/dev/null 2>&1; then
      SUDO=sudo
    else
      echo "magcomp: error: packages missing and not root (no sudo): ${missing[*]}" >&2
      exit 1
    fi
  else
    SUDO=""
  fi
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get update -q
  $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
}

magcomp_build() {
  mkdir -p "$MAGCOMP_WS/src"
  if [ ! -e "$MAGCOMP_WS/src/magcomp" ]; then
    ln -s "$MAGCOMP_REPO" "$MAGCOMP_WS/src/magcomp"
  fi
  (cd "$MAGCOMP_WS" && catkin_make -j2 -DCMAKE_BUILD_TYPE=Release \
      -DPYTHON_EXECUTABLE=/usr/bin/python3 \
      -DMAGCOMP_REFERENCE_DIR="$MAGCOMP_REFERENCE_DIR" "$@")
  # shellcheck disable=SC1091
  set +u
  source "$MAGCOMP_WS/devel/setup.bash"
  set -u
  MAGCOMP_BIN="$MAGCOMP_WS/devel/lib/magcomp"
  export MAGCOMP_BIN
}
