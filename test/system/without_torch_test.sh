#!/usr/bin/env bash
# System test: everything but the neural stage's torch side builds and runs without libtorch.
#
#   test/system/without_torch_test.sh WORKSPACE NOTORCH_DIR
#
# WORKSPACE is the built catkin workspace (scripts/test's .ws); NOTORCH_DIR a scratch directory.
# No source of the package reads MAGCOMP_WITH_TORCH: the option only decides which targets exist
# and what they link. So the check is on the build graph, not a second compilation of the same
# sources:
#  1. the package configures and generates with -DMAGCOMP_WITH_TORCH=OFF (a target that names a
#     torch-side target, e.g. add_dependencies on magcomp_train, fails here);
#  2. in that configuration no compile or link line of any target mentions torch, c10 or the
#     torch-side targets (a target_link_libraries(... magcomp_neural) becomes -lmagcomp_neural:
#     found here, not at link time);
#  3. in the built workspace, the core library, the command-line tool and the nodes load no
#     libtorch (ldd: the neural stage is dlopened only for a model that has one), and the
#     TL-only command runs (`magcomp calibrate` then `magcomp evaluate` on the shipped flight).
set -euo pipefail
ws="$1"
scratch="$2"
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
fail() {
  echo "without-torch test: FAIL: $*"
  exit 1
}

# 1. Configure and generate without libtorch.
rm -rf "$scratch"
mkdir -p "$scratch/src"
ln -sfn "$repo" "$scratch/src/magcomp"
ln -sfn /usr/share/catkin/cmake/toplevel.cmake "$scratch/src/CMakeLists.txt"
cmake -S "$scratch/src" -B "$scratch/build" -DCATKIN_DEVEL_PREFIX="$scratch/devel" \
  -DCMAKE_INSTALL_PREFIX="$scratch/install" -DCMAKE_BUILD_TYPE=Release \
  -DPYTHON_EXECUTABLE=/usr/bin/python3 -DMAGCOMP_WITH_TORCH=OFF > "$scratch/configure.log" 2>&1 ||
  { tail -n 20 "$scratch/configure.log"; fail "the package does not configure with -DMAGCOMP_WITH_TORCH=OFF"; }
if grep -q "^Torch_DIR:" "$scratch/build/CMakeCache.txt"; then
  fail "find_package(Torch) ran with -DMAGCOMP_WITH_TORCH=OFF"
fi

# 2. No target's compile or link line mentions the torch side.
targets=(magcomp_core magcomp_ros magcomp magcomp_convert compensator_node navigator_node
  calibrator_node mounts_node magcomp_nodelets test_core test_ros_io)
dir="$scratch/build/magcomp/CMakeFiles"
torch_side='libtorch|libc10|/torch(/| |$)|magcomp_neural|magcomp_train'
for t in "${targets[@]}"; do
  [ -f "$dir/$t.dir/flags.make" ] || fail "target $t is not generated without libtorch"
  for f in "$dir/$t.dir/flags.make" "$dir/$t.dir/link.txt"; do
    [ -f "$f" ] || continue
    if grep -Eq "$torch_side" "$f"; then
      fail "$t's $(basename "$f") names the torch side without libtorch: $(grep -Eo \
        "[^ ]*($torch_side)[^ ]*" "$f" | head -n 1)"
    fi
  done
done
for t in magcomp_neural magcomp_train test_neural; do
  [ -d "$dir/$t.dir" ] && fail "target $t exists with -DMAGCOMP_WITH_TORCH=OFF"
done

# 3. The built binaries load no libtorch, and the TL path runs.
lib="$ws/devel/lib"
for b in "$lib/libmagcomp_core.so" "$lib/libmagcomp_ros.so" "$ws/devel/bin/magcomp" \
  "$lib/magcomp/compensator_node" "$lib/magcomp/navigator_node" "$lib/magcomp/calibrator_node"; do
  [ -e "$b" ] || fail "$b was not built"
  if ldd "$b" | grep -Eq "libtorch|libc10"; then
    fail "$(basename "$b") loads libtorch: $(ldd "$b" | grep -Eo 'lib(torch|c10)[^ ]*' | head -n 1)"
  fi
done
data="$ws/devel/share/magcomp/rostest"
"$ws/devel/bin/magcomp" calibrate --model "$data/model_tl.yaml" --data "$data/flight.h5" \
  --out "$scratch/tl.yaml" > "$scratch/calibrate.log" 2>&1 || fail "magcomp calibrate failed"
"$ws/devel/bin/magcomp" evaluate --model "$scratch/tl.yaml" --data "$data/flight.h5" \
  > "$scratch/evaluate.log" 2>&1 || fail "magcomp evaluate failed"
echo "without-torch test: PASS (${#targets[@]} targets configured without the torch side;" \
  "core, CLI and nodes load no libtorch; TL calibrate and evaluate ran)"
