#!/usr/bin/env bash
# Runs exactly the README's quick-start lines (between <!-- quickstart --> and <!-- /quickstart -->)
# from the repository root, in a private ROS master, and checks that the replay published
# compensated samples. Usage: test/system/quickstart_test.sh (after the build).
set -euo pipefail
REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
block=$(awk '/<!-- quickstart -->/{f=1; next} /<!-- \/quickstart -->/{f=0} f' "$REPO/README.md" |
        sed '/^```/d')
[ -n "$block" ] || { echo "quickstart test: no quick-start block in README.md" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
out="$work/output.txt"
cd "$REPO"
export PATH="/usr/bin:/bin:$PATH"
export ROS_MASTER_URI="http://localhost:$(( 20000 + RANDOM % 10000 ))"
# A private master: roslaunch starts it on ROS_MASTER_URI's port, rostopic finds it there.
set +eu
( set -e; eval "$block" ) > "$out" 2>&1
rc=$?
set -eu
pkill -f "roslaunch magcomp replay.launch bag:=$REPO/out/flight.bag" 2>/dev/null || true
sleep 2
n=$(grep -c "compensated_nT" "$out" || true)
echo "quickstart test: the README's lines ran (exit $rc); $n compensated samples echoed"
if [ "$rc" -ne 0 ] || [ "$n" -lt 3 ]; then
  tail -n 30 "$out"
  exit 1
fi
