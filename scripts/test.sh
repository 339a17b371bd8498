#!/usr/bin/env bash
# Quick start, step 2: the same set-up, then the whole test suite through CTest, the same suite again
# under AddressSanitizer + UndefinedBehaviorSanitizer (build-asan), and each fuzz target for a fixed
# number of executions (build-fuzz, clang).
set -euo pipefail
cd "$(dirname "$0")/.."
TPRF_TEST_PACKAGES=1 scripts/setup.sh build
# The set-up made the Python module importable from anywhere, without PYTHONPATH.
(cd / && env -u PYTHONPATH python3 -c "import tprf; print('python: tprf', tprf.__version__, 'from', tprf.__file__)")
ctest --test-dir build --output-on-failure -j"$(nproc)"
cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=RelWithDebInfo -DTPRF_SANITIZE=ON -DTPRF_BUILD_BENCH=OFF >/dev/null
cmake --build build-asan -j"$(nproc)"
ctest --test-dir build-asan --output-on-failure -j"$(nproc)"
scripts/fuzz_smoke.sh 20000
