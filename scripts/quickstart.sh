#!/usr/bin/env bash
# Quick start, step 1: set up (install what is missing, build Release) and run the main job on the
# default scene, meshes/cornell-box.json.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh build
build/bin/tprf info meshes/cornell-box.json
build/bin/tprf render meshes/cornell-box.json -o out/cornell-box
