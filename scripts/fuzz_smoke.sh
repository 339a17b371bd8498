#!/usr/bin/env bash
# Runs each libFuzzer target of tools/fuzz on a copy of its seed corpus for a fixed number of
# executions (default 20000): what CI does on every change. Builds them first into build-fuzz (clang).
#   scripts/fuzz_smoke.sh [RUNS]
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-20000}
targets=(mesh scene sensor mitsuba)
CC=clang CXX=clang++ cmake -S . -B build-fuzz -DTPRF_FUZZ=ON -DTPRF_BUILD_TESTS=OFF -DTPRF_BUILD_BENCH=OFF \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target "${targets[@]/#/tprf_fuzz_}"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
for t in "${targets[@]}"; do
    mkdir -p "$work/$t"
    cp tools/fuzz/corpus/"$t"/* "$work/$t/"
    echo "fuzz: tprf_fuzz_$t, $runs executions" >&2
    build-fuzz/tools/fuzz/tprf_fuzz_"$t" "$work/$t" -runs="$runs" -max_len=4096 -rss_limit_mb=2048 -timeout=10 \
        -artifact_prefix="$work/$t-" 2>"$work/$t.log" || { tail -n 60 "$work/$t.log" >&2; exit 1; }
    grep -E "^Done" "$work/$t.log" >&2
done
