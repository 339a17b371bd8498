#!/usr/bin/env bash
# The link stage and the solver under ThreadSanitizer (docs/reliability.md, "ThreadSanitizer"): not
# part of CI (a TSan build takes about 20 minutes on 2 cores), run by hand after changes to parallel
# code. clang, with OpenMP from LLVM's libomp, whose Archer tool tells TSan about OpenMP's barriers
# (GCC's libgomp cannot). TSan also reports inside the libraries that are not instrumented (libomp's
# runtime, Embree and TBB), whose own synchronisation it cannot see; tools/tsan/classify.py sorts the
# reports and fails this script on any report with tprf's code at the access.
set -euo pipefail
cd "$(dirname "$0")/.."
CC=clang CXX=clang++ cmake -S . -B build-tsan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTPRF_TSAN=ON \
    -DTPRF_BUILD_BENCH=OFF >/dev/null
cmake --build build-tsan -j"$(nproc)" --target tprf_tests tprf_app
archer=$(find /usr/lib/llvm-*/lib -name libarcher.so 2>/dev/null | head -n 1)
[ -n "$archer" ] || { echo "libarcher.so not found (Debian: libomp-dev)" >&2; exit 2; }
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
export OMP_TOOL_LIBRARIES="$archer" TSAN_OPTIONS="halt_on_error=0 exitcode=0 log_path=$out/tsan"
build-tsan/tests/tprf_tests --gtest_filter='Solver.*:SolverBatch.*:Links.*:Hierarchy.*'
# Whole renders: the corner (hierarchical links, the default) with the camera gather, the sensor model, and a capture.
build-tsan/bin/tprf render meshes/corner.json -o "$out/corner" -q --threads 2
build-tsan/bin/tprf sensor "$out/corner" meshes/sensor-spad.json -q --threads 2
build-tsan/bin/tprf render examples/nlos/letter.json -o "$out/nlos" -q --threads 2 --max-edge 0.1
shopt -s nullglob
logs=("$out"/tsan.*)
python3 tools/tsan/classify.py /dev/null "${logs[@]}"
