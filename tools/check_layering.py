#!/usr/bin/env python3
"""Checks the library's layering (docs/design.md, "Stages"):

- a stage includes only itself and stages before it in the data flow
  (core, scene, geometry, transport, imaging, io, pipeline);
- nlohmann/json.hpp appears in no public header, and in sources only in scene/ (parsing) and
  io/json_records.cpp (writing render.json and sensor.json);
- only scene/ and pipeline/ include the scene parser (scene/parse_json.h);
- OpenMP (omp.h) appears in no public header;
- MPI (mpi.h) appears only in pipeline/ranks_mpi.cpp (pipeline/ranks.h is the interface);
- no include climbs out of its folder with "../" (which would hide a stage from these checks).

    tools/check_layering.py [LIB_DIR]      (default: lib next to this script's folder)

Prints every violation and exits 1 when there is one."""
import pathlib
import re
import sys

STAGES = ["core", "scene", "geometry", "transport", "imaging", "io", "pipeline"]
JSON_SOURCES = {"io/json_records.cpp"}
MPI_SOURCES = {"pipeline/ranks_mpi.cpp"}


def stage_of(path, lib):
    rel = path.relative_to(lib)
    parts = rel.parts
    if parts[0] == "include":
        return parts[2], "/".join(parts[2:])
    return parts[1], "/".join(parts[1:])


def main():
    lib = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parent.parent / "lib")
    problems = []
    files = sorted(list(lib.rglob("*.h")) + list(lib.rglob("*.cpp")))
    for f in files:
        stage, rel = stage_of(f, lib)
        if stage not in STAGES:
            problems.append(f"{f}: not in a stage folder ({', '.join(STAGES)})")
            continue
        public = f.relative_to(lib).parts[0] == "include"
        for n, line in enumerate(f.read_text().splitlines(), 1):
            m = re.match(r'\s*#\s*include\s*[<"]([^>"]+)[>"]', line)
            if not m:
                continue
            inc = m.group(1)
            where = f"{f}:{n}"
            if ".." in pathlib.PurePosixPath(inc).parts:
                problems.append(f"{where}: includes {inc}: name another stage's header as tprf/<stage>/...")
            t = re.match(r"tprf/([a-z_]+)/", inc)
            if t:
                other = t.group(1)
                if other not in STAGES:
                    problems.append(f"{where}: includes {inc}, which is in no stage")
                elif STAGES.index(other) > STAGES.index(stage):
                    problems.append(f"{where}: {stage}/ includes {inc}, a later stage")
                if inc == "tprf/scene/parse_json.h" and stage not in ("scene", "pipeline"):
                    problems.append(f"{where}: only scene/ and pipeline/ may include the scene parser")
            if inc.startswith("nlohmann/"):
                if public:
                    problems.append(f"{where}: a public header includes {inc}")
                elif stage != "scene" and rel not in JSON_SOURCES:
                    problems.append(f"{where}: {inc} outside the scene parser and io/json_records.cpp")
            if inc == "omp.h" and public:
                problems.append(f"{where}: a public header includes omp.h")
            if inc == "mpi.h" and (public or rel not in MPI_SOURCES):
                problems.append(f"{where}: mpi.h outside pipeline/ranks_mpi.cpp")
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
