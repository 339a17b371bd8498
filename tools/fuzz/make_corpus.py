#!/usr/bin/env python3
"""Writes the seed corpora of the fuzz targets into tools/fuzz/corpus/: mesh/ (tprf_fuzz_mesh) holds
the small sample meshes of meshes/ and a few hand-made variants per format, each seed one byte
choosing the format (0 .obj, 1 .off, 2 .ply, 3 .stl; mesh_fuzz.cpp) followed by the file; scene/ the
sample scenes; sensor/ the sample sensor blocks and those inside the sample scenes; mitsuba/ the sample
Mitsuba XML scenes and a seed with every element of the XML subset. Standard library
only; rerun it to reproduce the corpora."""
import json
import pathlib
import struct

ROOT = pathlib.Path(__file__).resolve().parents[2]
CORPUS = ROOT / "tools" / "fuzz" / "corpus"
FORMAT = {".obj": 0, ".off": 1, ".ply": 2, ".stl": 3}
LARGEST = 20_000  # bytes: larger sample meshes only slow the fuzzer down


def binary_ply(endian):
    order = "<" if endian == "little" else ">"
    head = (f"ply\nformat binary_{endian}_endian 1.0\nelement vertex 4\nproperty uchar red\nproperty double x\n"
            "property float y\nproperty float z\nelement face 2\nproperty list uchar float texcoord\n"
            "property list ushort uint vertex_index\nelement edge 1\nproperty int a\nproperty int b\n"
            "end_header\n").encode()
    body = b"".join(struct.pack(order + "Bdff", 9, x, y, 0.0) for x, y in [(0, 0), (1, 0), (1, 1), (0, 1)])
    for f in [(0, 1, 2), (0, 2, 3)]:
        body += struct.pack(order + "Bff", 2, 0.5, 0.5) + struct.pack(order + "H3I", 3, *f)
    return head + body + struct.pack(order + "ii", 0, 1)


def binary_stl(header):
    tris = [(0, 0, 0, 1, 0, 0, 1, 1, 0), (0, 0, 0, 1, 1, 0, 0, 1, 0)]
    out = header.ljust(80, b" ") + struct.pack("<I", len(tris))
    for t in tris:
        out += struct.pack("<12fH", 0, 0, 1, *t, 0)
    return out


HAND_MADE = {
    "square_coff.off": b"COFF\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n0 1 0 9 9 9 255\n"
                       b"3 0 1 2 255 0 0\n3 0 2 3\n",
    "square_comments.off": b"# tool\n\nOFF 4 1 0 # counts\n0 0 0\n1 0 0 # c\n\n1 1 0\n0 1 0\n4 0 1 2 3\n",
    "square_4noff.off": b"4nOFF\n3\n4 1\n0 0 0 1\n2 0 0 2\n3 3 0 3\n0 1 0 1\n4 0 1 2 3\n",
    "square_forms.obj": b"mtllib none.mtl\no a\nv 0 0 0 1\nv 1 0 0 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n"
                        b"f 1/1 2/1 3/1\nf -4//1 -2//1 -1//1\nl 1 2\ng b\nf 1/1/1 3/1/1 \\\n 4/1/1\n",
    "square_ascii.ply": b"ply\nformat ascii 1.0\ncomment c\nelement vertex 4\nproperty float nx\nproperty int x\n"
                        b"property int y\nproperty int z\nelement face 1\nproperty list uchar int vertex_indices\n"
                        b"property float q\nend_header\n0 0 0 0\n0 1 0 0\n0 1 1 0\n0 0 1 0\n4 0 1 2 3 0.5 7 7\n",
    "square_le.ply": binary_ply("little"),
    "square_be.ply": binary_ply("big"),
    "square_solid_header.stl": binary_stl(b"solid but binary"),
    "square_ascii.stl": b"solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\n"
                        b"endloop\nendfacet\nendsolid s\nsolid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                        b"vertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n",
}


# Mitsuba 3 XML seeds beside meshes/cornell-box.xml: every element and attribute of the subset
# (docs/mitsuba.md) once, with meshes that the fuzz target finds in meshes/.
MITSUBA = {
    "subset.xml": b"""<scene version="3.0.0">
  <default name="res" value="8"/>
  <default name="depth" value="4"/>
  <integrator type="transient_path">
    <integer name="max_depth" value="$depth"/><integer name="rr_depth" value="5"/>
    <boolean name="camera_unwarp" value="true"/>
    <string name="temporal_filter" value="box"/><float name="gaussian_stddev" value="2"/>
  </integrator>
  <sensor type="perspective" id="cam">
    <float name="fov" value="45"/><string name="fov_axis" value="smaller"/>
    <float name="near_clip" value="0.1"/><float name="far_clip" value="100"/>
    <float name="focus_distance" value="3"/>
    <transform name="to_world"><rotate y="1" angle="180"/><translate value="0 0.5 3"/></transform>
    <sampler type="stratified"><integer name="sample_count" value="4"/><integer name="seed" value="1"/></sampler>
    <film type="transient_hdr_film">
      <integer name="width" value="$res"/><integer name="height" value="6"/>
      <integer name="temporal_bins" value="32"/><float name="start_opl" value="1"/>
      <float name="bin_width_opl" value="0.25"/><rfilter type="box"/>
    </film>
  </sensor>
  <bsdf type="twosided" id="paper"><bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf></bsdf>
  <shape type="cube" id="box">
    <transform name="to_world"><scale x="0.3" y="0.2" z="0.1"/><rotate value="1, 1, 0" angle="30"/></transform>
    <ref id="paper" name="bsdf"/>
  </shape>
  <shape type="rectangle">
    <transform name="to_world"><matrix value="1 0 0 0 0 0 1 0 0 -1 0 0 0 0 0 1"/></transform>
    <bsdf type="diffuse"><float name="reflectance" value="0.5"/></bsdf>
    <emitter type="area"><rgb name="radiance" value="2"/></emitter>
  </shape>
  <shape type="obj">
    <string name="filename" value="tetra.obj"/><boolean name="face_normals" value="true"/>
    <transform name="to_world"><lookat origin="0, 1, 0" target="0, 0, 0"/></transform>
  </shape>
  <shape type="ply"><string name="filename" value="tetra.ply"/><ref id="paper"/></shape>
  <emitter type="point"><point name="position" x="0" y="1" z="1"/><rgb name="intensity" value="1, 2, 3"/></emitter>
  <emitter type="point"><transform name="to_world"><translate x="1"/></transform>
    <float name="intensity" value="1"/></emitter>
</scene>
""",
}


def mesh_files(scene):
    return [o["file"] for o in json.loads(scene.read_bytes()).get("objects", []) if o.get("type") == "mesh"]


def write(folder, seeds):
    out = CORPUS / folder
    out.mkdir(parents=True, exist_ok=True)
    for old in out.iterdir():
        old.unlink()
    for name, data in seeds.items():
        (out / name).write_bytes(data)
    print(f"{len(seeds)} seeds, {sum(len(d) for d in seeds.values())} bytes in {out}")


def main():
    samples = sorted((ROOT / "meshes").iterdir())
    meshes = {p.name: p.read_bytes() for p in samples if p.suffix.lower() in FORMAT and p.stat().st_size <= LARGEST}
    meshes.update(HAND_MADE)
    write("mesh", {name: bytes([FORMAT[pathlib.Path(name).suffix.lower()]]) + data for name, data in meshes.items()})
    # Scenes whose mesh files are small: every execution loads them (the statue's 54k faces take 50 ms).
    scenes = {p.name: p.read_bytes() for p in samples if p.suffix == ".json" and not p.name.startswith("sensor-")
              and all((ROOT / "meshes" / m).stat().st_size <= LARGEST for m in mesh_files(p))}
    write("scene", scenes)
    sensors = {p.name: p.read_bytes() for p in samples if p.name.startswith("sensor-")}
    for name, data in scenes.items():
        if "sensor" in json.loads(data):
            sensors["in-" + name] = json.dumps(json.loads(data)["sensor"], indent=1).encode()
    write("sensor", sensors)
    mitsuba = dict(MITSUBA)
    mitsuba.update({p.name: p.read_bytes() for p in samples if p.suffix == ".xml"})
    write("mitsuba", mitsuba)


if __name__ == "__main__":
    main()
