#!/usr/bin/env python3
"""Writes the seed corpus of the fuzz targets (fuzz/corpus/<target>/): tiny valid files copied
from the repository's test data and scenes, and hand-made ones written here with the standard
library only. The wire targets' seeds (tile_payload, emis_wire) come from the project's own
encoders: `cargo run --example wire_seeds` in fuzz/ (see fuzz/README.md).

Run from anywhere: python3 fuzz/make-corpus.py"""

import pathlib
import re
import shutil
import struct
import zlib

FUZZ = pathlib.Path(__file__).resolve().parent
ROOT = FUZZ.parent
CORPUS = FUZZ / "corpus"


def put(target, name, data):
    path = CORPUS / target / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data if isinstance(data, bytes) else data.encode())


def copy(target, source, name=None):
    put(target, name or pathlib.Path(source).name, (ROOT / source).read_bytes())


def ply_corpus():
    copy("mesh_ply", "common/tests/data/uv/quad.ply", "quad-ascii.ply")
    copy("mesh_ply", "scenes/mesh-colors/facets.ply", "facets-binary.ply")
    copy("mesh_ply", "scenes/included-scene/parts/pedestal.ply")
    header = lambda fmt, props, faceprops="": (
        f"ply\nformat {fmt} 1.0\ncomment tessera fuzz seed\nelement vertex 4\n{props}"
        f"element face 1\nproperty list uchar int vertex_indices\n{faceprops}end_header\n"
    )
    vprops = "".join(f"property float {p}\n" for p in ["x", "y", "z", "nx", "ny", "nz"])
    vprops += "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    quad = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    for fmt, end in [("binary_little_endian", "<"), ("binary_big_endian", ">")]:
        body = b"".join(struct.pack(end + "6f3B", *p, 0, 0, 1, 255, 128, i * 60) for i, p in enumerate(quad))
        body += struct.pack(end + "B4i", 4, 0, 1, 2, 3) + struct.pack(end + "f", 0.5)
        name = "colors-binary.ply" if end == "<" else "colors-big-endian.ply"
        put("mesh_ply", name, header(fmt, vprops, "property float quality\n").encode() + body)
    ascii_props = "".join(f"property double {p}\n" for p in ["x", "y", "z", "s", "t"])
    ascii_props += "property float attr_x\nproperty float attr_y\nproperty float attr_z\n"
    rows = "".join(f"{x} {y} {z} 0.5 0.25 1 2 3\n" for x, y, z in quad) + "4 3 2 1 0\n"
    put("mesh_ply", "attributes-ascii.ply", header("ascii", ascii_props) + rows)


def obj_corpus():
    copy("mesh_obj", "common/tests/data/uv/quad.obj")
    put("mesh_obj", "normals-negative.obj",
        "# normals, uvs, negative indices, a quad and a pentagon\n"
        "o thing\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\n"
        "vn 0 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 1\n"
        "usemtl none\ns 1\nf -5/-5/-1 -4/-4/-1 -3/-3/-1 -2/-2/-1\n"
        "g roof\nf 4//1 3//1 5//1\nl 1 2\np 3\n")
    put("mesh_obj", "plain.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")


def serialized_corpus():
    for name in ["two-meshes.serialized", "two-meshes-v3.serialized"]:
        copy("mesh_serialized", f"common/tests/data/meshes/{name}")
    # one triangle in double precision with a name, normals, uvs and colours (flags 0x200b)
    tri = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    body = struct.pack("<I", 0x2000 | 0x1 | 0x2 | 0x8) + b"tri\0" + struct.pack("<QQ", 3, 1)
    body += b"".join(struct.pack("<3d", *p) for p in tri)
    body += struct.pack("<9d", *[0, 0, 1] * 3) + struct.pack("<6d", 0, 0, 1, 0, 0, 1)
    body += struct.pack("<9d", *[0.5] * 9) + struct.pack("<3I", 0, 1, 2)
    put("mesh_serialized", "double-all-fields.serialized", struct.pack("<HH", 0x041C, 4) + zlib.compress(body))


def bitmap_corpus():
    for path in sorted((ROOT / "common/tests/data/textures").iterdir()):
        copy("bitmap", path.relative_to(ROOT))
    # a TGA without the TGA 2 footer (found by the .tga name only) and a colour PFM
    tga = struct.pack("<BBBHHBHHHHBB", 0, 0, 2, 0, 0, 0, 0, 0, 2, 1, 24, 0x20) + bytes([0, 0, 255, 0, 255, 0])
    put("bitmap", "no-footer.tga", tga)
    put("bitmap", "rgb-be.pfm", b"PF\n2 1\n1.0\n" + struct.pack(">6f", 0.1, 0.2, 0.3, 1.5, 2.5, 3.5))
    put("bitmap", "gray16.ppm", b"P6\n1 1\n65535\n" + struct.pack(">3H", 1000, 20000, 65535))


# scene files name these instead of their own (fuzz/src/lib.rs writes them beside the input)
ASSET_FOR_SUFFIX = {
    ".obj": "mesh.obj", ".ply": "mesh.ply", ".serialized": "mesh.serialized", ".png": "tex.png",
    ".jpg": "tex.jpg", ".exr": "tex.exr", ".hdr": "tex.hdr", ".bmp": "tex.bmp", ".tga": "tex.tga",
    ".pfm": "tex.pfm", ".ppm": "tex.ppm", ".spd": "spec.spd", ".xml": "part.xml",
}

HAND_MADE_SCENE = """<scene version="3.0.0">
    <default name="spp" value="4"/>
    <include filename="part.xml"/>
    <path value="."/>
    <integrator type="path"><integer name="max_depth" value="5"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="45"/>
        <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="3"/>
            <rfilter type="gaussian"/></film>
    </sensor>
    <bsdf type="roughconductor" id="metal"><float name="alpha" value="0.2"/></bsdf>
    <alias id="metal" as="shiny"/>
    <texture type="bitmap" id="wood"><string name="filename" value="tex.png"/></texture>
    <shape type="ply"><string name="filename" value="mesh-binary.ply"/><ref id="part-bsdf"/></shape>
    <shape type="obj"><string name="filename" value="mesh.obj"/><ref id="shiny"/></shape>
    <shape type="serialized"><string name="filename" value="mesh.serialized"/>
        <integer name="shape_index" value="1"/>
        <bsdf type="diffuse"><ref name="reflectance" id="wood"/></bsdf></shape>
    <shape type="sphere"><float name="radius" value="0.5"/>
        <bsdf type="diffuse"><texture type="bitmap" name="reflectance">
            <string name="filename" value="tex.exr"/></texture></bsdf></shape>
    <shape type="rectangle"><emitter type="area"><spectrum name="radiance" filename="spec.spd"/></emitter></shape>
    <emitter type="envmap"><string name="filename" value="tex.hdr"/></emitter>
</scene>
"""


# several files in one input, split at NUL bytes: scene.xml, inc1.xml, inc2.xml, inc3.xml
INCLUDES_SCENE = "\0".join([
    '<scene version="3.0.0"><include filename="inc1.xml"/><shape type="sphere"><ref id="inc-bsdf"/></shape></scene>',
    '<scene version="3.0.0"><include filename="inc2.xml"/><include filename="inc3.xml"/>'
    '<bsdf type="diffuse" id="inc-bsdf"/></scene>',
    '<scene version="3.0.0"><bsdf type="roughplastic" id="plastic"/><alias id="plastic" as="p2"/></scene>',
    '<bsdf version="3.0.0" type="conductor" id="metal"/>',
])


def scene_corpus():
    sources = sorted(ROOT.glob("scenes/*/scene.xml")) + [ROOT / "common/tests/data/uv/scene.xml"]
    for source in sources:
        text = re.sub(r'(filename"? value|filename)="([^"]*)"',
                      lambda m: f'{m.group(1)}="{asset(m.group(2))}"', source.read_text())
        name = ("uv" if "uv" in source.parts else source.parent.name) + ".xml"
        put("scene_build", name, text)
        put("scene_xml", name, text)
    put("scene_build", "hand-made.xml", HAND_MADE_SCENE)
    put("scene_xml", "hand-made.xml", HAND_MADE_SCENE)
    put("scene_build", "includes", INCLUDES_SCENE)
    put("scene_xml", "includes", INCLUDES_SCENE)


def asset(filename):
    return ASSET_FOR_SUFFIX.get(pathlib.PurePath(filename).suffix.lower(), filename)


def main():
    for target in ["mesh_ply", "mesh_obj", "mesh_serialized", "bitmap", "scene_build", "scene_xml"]:
        shutil.rmtree(CORPUS / target, ignore_errors=True)
    ply_corpus()
    obj_corpus()
    serialized_corpus()
    bitmap_corpus()
    scene_corpus()


if __name__ == "__main__":
    main()
