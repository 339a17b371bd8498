#!/usr/bin/env bash
# Installs whatever tprf needs that this Debian 12 machine lacks, then configures and builds (Release).
# Idempotent: installed packages are left alone, and an existing build directory is reused.
#   scripts/setup.sh [BUILD_DIR]      (default: build)
set -euo pipefail
cd "$(dirname "$0")/.."
build_dir=${1:-build}

packages=(build-essential cmake pkg-config libopenmesh-dev libeigen3-dev libopenexr-dev libflann-dev
          libembree-dev libtbb-dev nlohmann-json3-dev libcli11-dev libgtest-dev libgmock-dev
          libbenchmark-dev libpng-dev libhdf5-dev python3-matplotlib python3-numpy python3-pytest
          python3-h5py python3-yaml libopenmpi-dev openmpi-bin pybind11-dev python3-dev libpugixml-dev)
# The test script's extras: clang and its libFuzzer runtime for the fuzz targets (tools/fuzz).
if [ "${TPRF_TEST_PACKAGES:-0}" = 1 ]; then packages+=(clang libclang-rt-14-dev); fi
missing=()
for p in "${packages[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
    echo "setup: installing ${missing[*]}" >&2
    sudo=()
    if [ "$(id -u)" -ne 0 ]; then
        command -v sudo >/dev/null || { echo "setup: need root (or sudo) to install: ${missing[*]}" >&2; exit 1; }
        sudo=(sudo)
    fi
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -qq
    "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$build_dir" -j"$(nproc)"

# `import tprf` from any directory and any Python script: the build's python/ folder (the module, see
# docs/python.md) goes on Python's path through a .pth file in the user's site-packages. The last
# set-up run decides which build that is.
if [ -d "$build_dir/python/tprf" ]; then
    site=$(python3 -c 'import site; print(site.getusersitepackages())')
    mkdir -p "$site"
    (cd "$build_dir/python" && pwd) > "$site/tprf.pth"
fi
