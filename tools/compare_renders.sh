#!/usr/bin/env bash
# Renders the sample scenes with two tprf binaries and compares every output byte for byte
# (render.json without its timings and peak memory), so that a change that must not alter results
# can be shown not to. Besides the sample scenes it builds small NLOS captures (a hidden corner behind
# a relay wall: confocal every bounce, wider march bins with a marched lattice, exhaustive, through a
# tinted mirror) and compares their capture.hdf5 and capture.npy too (capture.hdf5's scene_info holds
# the project version and the scene file's path, the same for both binaries). Exit 0 when every
# output is identical.
#   tools/compare_renders.sh OLD_TPRF NEW_TPRF [WORKDIR]
set -euo pipefail
old=$(realpath "$1"); new=$(realpath "$2")
work=${3:-$(mktemp -d)}
cd "$(dirname "$0")/.."
mkdir -p "$work"
python_bin=${TPRF_PYTHON:-python3}
status=0
render() {  # BINARY TAG SCENE NAME [FLAGS...]
    local bin=$1 tag=$2 scene=$3 name=$4; shift 4
    "$bin" render "$scene" -o "$work/$tag/$name" -q "$@" >/dev/null
}
# A scene with the solver's per-bounce cubes and picosecond units, built from the corner; and the
# captures, a few seconds each.
"$python_bin" - "$work" <<'PY'
import json, os, sys
work = sys.argv[1]
s = json.load(open("meshes/corner.json"))
s["solver"] = {"bounces": True, "max_bounces": 3}
json.dump(s, open(os.path.join(work, "corner-bounces.json"), "w"))
def rect(origin, u, v, albedo=None, material=None):
    r = {"type": "rectangle", "origin": origin, "u": u, "v": v}
    if albedo is not None: r["albedo"] = albedo
    if material is not None: r["material"] = material
    return r
wall = rect([-1, -1, 0], [2, 0, 0], [0, 2, 0], 0.8)
hidden = [rect([-0.5, -0.5, 0.5], [0, 1, 0], [1, 0, 0.2], 0.6), rect([-0.5, 0.5, 0.1], [1, 0, 0], [0, 0, 0.5], 0.7)]
devices = {"laser": {"position": [0, -1.5, 0.3]}, "sensor": {"position": [0, -1.5, 0.3]}}
def capture_scene(name, capture, objects=None, links=None, time=None, max_edge=0.1):
    scene = {"time": time or {"bins": 150, "bin_width": 0.02}, "objects": [wall] + (objects or hidden),
             "patches": {"max_edge": max_edge}, "links": links or {"method": "hierarchical", "tolerance": 0.001},
             "capture": dict(devices, **capture)}
    json.dump(scene, open(os.path.join(work, name + ".json"), "w"), indent=1)
grid = lambda n: {"origin": [-0.4, -0.4, 0], "u": [0.8, 0, 0], "v": [0, 0.8, 0], "nu": n, "nv": n}
capture_scene("capture-confocal", {"type": "confocal", "grid": grid(5), "max_bounces": None},
              time={"bins": 100, "bin_width": 0.03})
capture_scene("capture-march", {"type": "confocal", "grid": grid(7), "march_bin_factor": 4, "march_grid_step": 3,
                                "account_first_and_last_bounces": True},
              time={"bins": 200, "bin_width": 0.01, "start": 3.0})
capture_scene("capture-exhaustive", {"type": "exhaustive", "grid": grid(3), "sensor_grid": grid(2),
                                     "laser": {"position": [-0.3, -1.4, 0.35], "power": [1.0, 0.5, 0.25]},
                                     "account_first_and_last_bounces": True},
              links={"method": "flat"}, time={"bins": 150, "bin_width": 0.02, "start": 3.0})
mirror = rect([1, -1.5, 0.2], [0, 0, 1.8], [0, 3, 0], material={"type": "mirror", "reflectance": [0.9, 0.6, 0.3]})
plane = rect([0.5, -0.3, 0.5], [0, 0.6, 0], [0.2, 0, 0.4], 0.6)
capture_scene("capture-mirror", {"type": "confocal", "grid": grid(4)}, objects=[plane, mirror],
              time={"bins": 160, "bin_width": 0.03}, max_edge=0.15)
PY
for tag in old new; do
    bin=$old; [ "$tag" = new ] && bin=$new
    for scene in cornell-box corner plates mesh-on-floor; do
        render "$bin" "$tag" "meshes/$scene.json" "$scene" --patch-profiles --frames --streaks --threads 2
    done
    render "$bin" "$tag" "$work/corner-bounces.json" corner-bounces --patch-profiles --threads 2
    for scene in capture-confocal capture-march capture-exhaustive capture-mirror; do
        render "$bin" "$tag" "$work/$scene.json" "$scene" --threads 2
    done
    for s in gates amcw spad; do
        cp -r "$work/$tag/cornell-box" "$work/$tag/cornell-box-$s"
        "$bin" sensor "$work/$tag/cornell-box-$s" "meshes/sensor-$s.json" --plot-pixel 64,70 >/dev/null
    done
done
strip_json() { "$python_bin" -c '
import json, sys
j = json.load(open(sys.argv[1]))
for k in ("seconds", "peak_rss_mb", "version", "scene"): j.pop(k, None)
j.get("solver", {}).pop("working_mb", None)
c = j.get("capture", {})
c.pop("seconds", None)
for share in c.get("shares", []): share.pop("seconds", None)
print(json.dumps(j, sort_keys=True))' "$1"; }
cd "$work/old"
while IFS= read -r f; do
    if [ ! -e "$work/new/$f" ]; then echo "MISSING in new: $f"; status=1; continue; fi
    case "$f" in
        */render.json) [ "$(strip_json "$f")" = "$(strip_json "$work/new/$f")" ] || { echo "DIFFERS: $f"; status=1; } ;;
        *) cmp -s "$f" "$work/new/$f" || { echo "DIFFERS: $f"; status=1; } ;;
    esac
done < <(find . -type f | sort)
(cd "$work/new" && find . -type f | sort) | while IFS= read -r f; do [ -e "$work/old/$f" ] || echo "NEW in new: $f"; done
[ $status -eq 0 ] && echo "all outputs identical ($work)"
exit $status
