#!/usr/bin/env bash
# Renders the sample scenes with two tprf binaries and compares every output byte for byte
# (render.json without its timings and peak memory), so that a change that must not alter results
# can be shown not to. Exit 0 when every output is identical.
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
# A scene with the solver's per-bounce cubes and picosecond units, built from the corner.
"$python_bin" - "$work/corner-bounces.json" <<'PY'
import json, sys
s = json.load(open("meshes/corner.json"))
s["solver"] = {"bounces": True, "max_bounces": 3}
json.dump(s, open(sys.argv[1], "w"))
PY
for tag in old new; do
    bin=$old; [ "$tag" = new ] && bin=$new
    for scene in cornell-box corner plates mesh-on-floor; do
        render "$bin" "$tag" "meshes/$scene.json" "$scene" --patch-profiles --frames --streaks --threads 2
    done
    render "$bin" "$tag" "$work/corner-bounces.json" corner-bounces --patch-profiles --threads 2
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
