#!/bin/sh
# Re-runs the examples whose READMEs quote a figure and prints those figures, to compare with
# examples/mirrors/README.md, examples/nlos/README.md and docs/python.md.
#   examples/check_figures.sh [OUTDIR]      (default: a new folder under /tmp, kept)
# TPRF: the tprf binary (default: build/bin/tprf from the repository root).
# PYTHON: a Python 3 with numpy, h5py and matplotlib (default: /usr/bin/python3).
# PYTHONPATH: where the tprf module is (default: build/python), for the Python example.
# NLOS=0 skips the NLOS example (its backprojection takes 15-60 s on 2 cores).
# OMP_WAIT_POLICY defaults to passive here: the render times then stay near their idle values on a
# machine whose cores are shared (docs/mpi.md); the figures do not depend on it.
set -eu
OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive}
export OMP_WAIT_POLICY
root=$(cd "$(dirname "$0")/.." && pwd)
out=${1:-$(mktemp -d /tmp/tprf-figures.XXXXXX)}
tprf=${TPRF:-"$root/build/bin/tprf"}
py=${PYTHON:-/usr/bin/python3}
mkdir -p "$out"
[ -x "$tprf" ] || { echo "check_figures.sh: no tprf binary at $tprf (build it, or set TPRF)" >&2; exit 2; }

# render.json's total seconds and patch count, as "N patches, S s".
render_summary() {
    "$py" -c 'import json, sys; r = json.load(open(sys.argv[1]))
print("{:,} patches, {:.2f} s".format(r["patches"], r["seconds"]["total"]))' "$1/render.json"
}

echo "== examples/mirrors: mirror_depth (README: X within 0.26 mm)"
"$tprf" render "$root/examples/mirrors/mirror_depth.json" -o "$out/mirror_depth" --quiet
echo "render: $(render_summary "$out/mirror_depth")"
"$py" "$root/examples/mirrors/mirror_depth.py" "$out/mirror_depth" | grep -E "^(error|true W)"

echo "== examples/mirrors: hidden_mirror (README: 0.462 degrees, 4.96 mm; point samples 0.018 degrees, 0.21 mm)"
"$tprf" render "$root/examples/mirrors/hidden_mirror.json" -o "$out/hidden_mirror" --quiet
echo "render: $(render_summary "$out/hidden_mirror")"
"$py" "$root/examples/mirrors/hidden_mirror.py" "$out/hidden_mirror" | grep -E "^(normal|[0-9]+ points)"
# The same with point samples: each pixel exactly its centre ray.
"$py" -c 'import json, sys; s = json.load(open(sys.argv[1])); s["camera"]["footprint"] = False
json.dump(s, open(sys.argv[2], "w"))' "$root/examples/mirrors/hidden_mirror.json" "$out/hidden_mirror_points.json"
"$tprf" render "$out/hidden_mirror_points.json" -o "$out/hidden_mirror_points" --quiet
printf "point samples: "
"$py" "$root/examples/mirrors/hidden_mirror.py" "$out/hidden_mirror_points" --scene "$out/hidden_mirror_points.json" \
    | grep -E "^normal"

if [ "${NLOS:-1}" != 0 ]; then
    echo "== examples/nlos (README: depth 0.8006 m, error +0.06 cm)"
    TPRF="$tprf" PYTHON="$py" "$root/examples/nlos/run.sh" "$out/nlos" > "$out/nlos.log" 2>&1
    echo "render: $(render_summary "$out/nlos/render")"
    grep -E "^(target|depth|error|seconds)" "$out/nlos.log"
fi

echo "== examples/python/corner.py (docs/python.md)"
start=$(date +%s.%N)
PYTHONPATH=${PYTHONPATH:-"$root/build/python"} "$py" "$root/examples/python/corner.py" "$out/corner-python" \
    | grep -E "^pixel"
end=$(date +%s.%N)
"$py" -c 'import sys; print(f"wall {float(sys.argv[2]) - float(sys.argv[1]):.1f} s, from start to the figures written")' \
    "$start" "$end"
echo "outputs in $out"
