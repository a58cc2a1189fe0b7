#!/usr/bin/env bash
# Install-space test: `catkin_make install` into a temporary prefix, then, with the source tree and
# the build workspace hidden (an empty tmpfs mounted over the repository in a private mount
# namespace), run from the install space: simulate, calibrate, evaluate --report, convert, and
# `roslaunch magcomp replay.launch` by package name, which must publish compensated samples.
# Usage: test/system/install_test.sh (after the build). Needs root (or sudo) for the namespace;
# without it, prints "skipped" and exits 0.
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
WS="${MAGCOMP_WS:-$REPO/.ws}"
export PATH="/usr/bin:/bin:/usr/sbin:/sbin:$PATH"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if sudo -n true 2>/dev/null; then SUDO="sudo -n"; else
    echo "install test: skipped (needs root for a private mount namespace)"
    exit 0
  fi
fi
PREFIX=$(mktemp -d "${TMPDIR:-/tmp}/magcomp_install.XXXXXX")
trap 'rm -rf "$PREFIX" "$PREFIX.log" "$PREFIX.run.sh"' EXIT   # pass or fail
set +u
source "$WS/devel/setup.bash"
set -u
(cd "$WS" && catkin_make install -DCMAKE_INSTALL_PREFIX="$PREFIX" > "$PREFIX.log" 2>&1) ||
  { tail -n 30 "$PREFIX.log"; exit 1; }
cat > "$PREFIX.run.sh" <<SCRIPT
set -euo pipefail
mount -t tmpfs tmpfs "$REPO"
test ! -e "$REPO/package.xml"   # the source tree is gone
env -i HOME="\$HOME" PATH=/usr/bin:/bin bash -c '
  set -eo pipefail
  source "$PREFIX/setup.bash"
  export ROS_MASTER_URI="http://localhost:\$(( 20000 + RANDOM % 10000 ))"
  share=\$(rospack find magcomp)
  case "\$share" in "$PREFIX"/*) ;; *) echo "rospack found magcomp at \$share, not in the install space"; exit 1;; esac
  mkdir "$PREFIX/run" && cd "$PREFIX/run"
  magcomp simulate --scenario "\$share/config/scenarios/rostest_short.yaml" --out f.h5
  magcomp calibrate --data f.h5 --model "\$share/config/models/tl_sim.yaml" --out m.yaml
  magcomp evaluate --data f.h5 --model m.yaml --report report | tail -n 1
  test -s report/index.html
  magcomp convert f.h5 f.bag
  timeout 40 roslaunch magcomp replay.launch bag:=\$PWD/f.bag model:=\$PWD/m.yaml rate:=20 > launch.log 2>&1 &
  sleep 10
  n=\$(timeout 20 rostopic echo -n 3 /magcomp/compensated | grep -c compensated_nT || true)
  kill %1 2>/dev/null || true
  echo "install test: \$n compensated samples from roslaunch magcomp replay.launch (install space)"
  [ "\$n" -ge 3 ]
'
SCRIPT
set +e
$SUDO unshare -m --propagation private bash "$PREFIX.run.sh"
rc=$?
set -e
[ $rc -eq 0 ] && echo "install test: PASS" || echo "install test: FAIL"
exit $rc
