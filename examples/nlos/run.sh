#!/bin/sh
# Render the hidden-letter scene's confocal capture with tprf, then reconstruct it by filtered backprojection.
#   examples/nlos/run.sh [OUTDIR]       (default OUTDIR: out/ beside this script)
# TPRF: the tprf binary (default: ../../build/bin/tprf from this script's folder).
# PYTHON: a Python 3 with numpy, h5py and matplotlib (default: the first of python3, /usr/bin/python3 that has them).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
out=${1:-"$here/out"}
tprf=${TPRF:-"$here/../../build/bin/tprf"}

if [ -z "${PYTHON:-}" ]; then
    for p in python3 /usr/bin/python3; do
        if command -v "$p" >/dev/null 2>&1 && "$p" -c 'import numpy, h5py, matplotlib' 2>/dev/null; then
            PYTHON=$p
            break
        fi
    done
fi
if [ -z "${PYTHON:-}" ]; then
    echo "run.sh: no python3 with numpy, h5py and matplotlib (Debian: apt-get install python3-h5py python3-matplotlib); set PYTHON" >&2
    exit 2
fi
if [ ! -x "$tprf" ]; then
    echo "run.sh: no tprf binary at $tprf (build the project, or set TPRF)" >&2
    exit 2
fi

"$tprf" render "$here/letter.json" -o "$out/render"
"$PYTHON" "$here/reconstruct.py" "$out/render/capture.hdf5" -o "$out" --expect-depth 0.8

# The same capture through a SPAD: Poisson photon counts (about 200 at the hidden signal's peak), dark
# counts and 30 ps (9 mm) of jitter. tprf sensor writes the noisy capture as a capture.hdf5 of its own,
# which the same reconstruction reads.
cat > "$out/spad.json" <<'SPAD'
{"exposure": {"type": "spad", "photons": 2e5, "jitter_fwhm": 0.009, "dark_rate": 5e9, "seed": 1}}
SPAD
"$tprf" sensor "$out/render" "$out/spad.json" --cube capture --name spad
"$PYTHON" "$here/reconstruct.py" "$out/render/sensor-spad/capture.hdf5" -o "$out/spad" --expect-depth 0.8
