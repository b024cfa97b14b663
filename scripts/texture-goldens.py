#!/usr/bin/env python3
"""Golden values for Tessera's texture module, computed by Mitsuba 3.9.1 (scalar_rgb).

Evaluates `bitmap`, `checkerboard` and `mesh_attribute` textures through
`mi.SurfaceInteraction3f` at fixed uvs and prints the results as JSON, which
`common/tests/textures.rs` compares against. The test images are tiny files committed under
`common/tests/data/textures/`; `--regenerate` rewrites them (BMP and TGA by hand, as Mitsuba
cannot write those; the rest with `mi.Bitmap.write`).

    pip install mitsuba numpy
    python3 scripts/texture-goldens.py > common/tests/data/texture-goldens.json
"""

import argparse
import json
import struct
import sys
from pathlib import Path

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
mi.set_log_level(mi.LogLevel.Error)  # out-of-range HDR texels only warn

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "common" / "tests" / "data" / "textures"

# inside, on edges and corners, and outside [0,1]² in every direction
UVS = [
    (0.0, 0.0),
    (0.13, 0.71),
    (0.5, 0.5),
    (0.99, 0.02),
    (0.37, 0.999),
    (-0.3, 1.45),
    (1.7, -0.6),
    (2.26, 3.9),
    (-1.15, -2.35),
]

WRAPS = ["repeat", "mirror", "clamp"]
FILTERS = ["bilinear", "nearest"]

# a general 4x4 (its z row and column must be ignored) and a 3x3 affine to_uv
TO_UV_4 = [[1.5, -0.5, 0.7, 0.3], [0.25, 2.0, -0.9, -0.2], [0.1, 0.2, 3.0, 5.0], [0.0, 0.0, 0.0, 1.0]]
TO_UV_3 = [[0.0, -3.0, 0.25], [2.0, 0.5, -0.1], [0.0, 0.0, 1.0]]


def rng_image(seed, h, w, c, dtype, hi):
    rng = np.random.default_rng(seed)
    img = rng.integers(0, hi + 1, size=(h, w, c)).astype(dtype)
    img.flat[0] = 0
    img.flat[-1] = hi
    return img


def write_bmp(path, rgb):
    """24-bit bottom-up BMP (BITMAPINFOHEADER), rows padded to 4 bytes."""
    h, w, _ = rgb.shape
    row = w * 3
    pad = (-row) % 4
    pixels = b"".join(rgb[y, :, ::-1].tobytes() + b"\0" * pad for y in reversed(range(h)))
    header = struct.pack("<2sIHHI", b"BM", 54 + len(pixels), 0, 0, 54)
    info = struct.pack("<IiiHHIIiiII", 40, w, h, 1, 24, 0, len(pixels), 2835, 2835, 0, 0)
    path.write_bytes(header + info + pixels)


def write_tga(path, rgb, rle):
    """TGA 2 (with footer), 24-bit; bottom-left origin uncompressed, top-left origin RLE."""
    h, w, _ = rgb.shape
    bgr = rgb[:, :, ::-1]
    if not rle:
        body = b"".join(bgr[y].tobytes() for y in reversed(range(h)))
        header = struct.pack("<BBBHHBHHHHBB", 0, 0, 2, 0, 0, 0, 0, 0, w, h, 24, 0)
    else:
        px = [bgr[y, x].tobytes() for y in range(h) for x in range(w)]
        body, i = b"", 0
        while i < len(px):
            j = i
            while j + 1 < len(px) and px[j + 1] == px[i] and j - i < 127:
                j += 1
            if j > i:  # run packet
                body += bytes([0x80 | (j - i)]) + px[i]
                i = j + 1
            else:  # raw packet of one pixel
                body += bytes([0]) + px[i]
                i += 1
        header = struct.pack("<BBBHHBHHHHBB", 0, 0, 10, 0, 0, 0, 0, 0, w, h, 24, 0x20)
    footer = struct.pack("<II", 0, 0) + b"TRUEVISION-XFILE.\0"
    path.write_bytes(header + body + footer)


def regenerate():
    DATA.mkdir(parents=True, exist_ok=True)
    PF = mi.Bitmap.PixelFormat
    rgb8 = rng_image(1, 3, 4, 3, np.uint8, 255)
    mi.Bitmap(rgb8, pixel_format=PF.RGB).write(str(DATA / "rgb8.png"))
    mi.Bitmap(rng_image(2, 2, 3, 4, np.uint8, 255), pixel_format=PF.RGBA).write(str(DATA / "rgba8.png"))
    mi.Bitmap(rng_image(3, 3, 4, 3, np.uint16, 65535), pixel_format=PF.RGB).write(str(DATA / "rgb16.png"))
    mi.Bitmap(rng_image(4, 2, 3, 1, np.uint8, 255), pixel_format=PF.Y).write(str(DATA / "gray8.png"))
    mi.Bitmap(rng_image(5, 2, 3, 2, np.uint16, 65535), pixel_format=PF.YA).write(str(DATA / "ya16.png"))
    mi.Bitmap(rng_image(6, 3, 1, 3, np.uint8, 255), pixel_format=PF.RGB).write(str(DATA / "tiny1x3.png"))
    mi.Bitmap(rng_image(7, 1, 1, 3, np.uint8, 255), pixel_format=PF.RGB).write(str(DATA / "tiny1x1.png"))
    rng = np.random.default_rng(8)
    f32 = (rng.random((3, 4, 3)) * 4.0).astype(np.float32)
    mi.Bitmap(f32, pixel_format=PF.RGB).write(str(DATA / "rgb32.exr"))
    mi.Bitmap((rng.random((2, 3, 4)) * 2.0).astype(np.float16), pixel_format=PF.RGBA).write(str(DATA / "rgba16.exr"))
    mi.Bitmap((rng.random((3, 2, 1)) * 3.0).astype(np.float32), pixel_format=PF.Y).write(str(DATA / "y32.exr"))
    mi.Bitmap((rng.random((3, 4, 3)) * 8.0).astype(np.float32), pixel_format=PF.RGB).write(str(DATA / "rgb.hdr"))
    mi.Bitmap((rng.random((2, 3, 1)) * 2.0).astype(np.float32), pixel_format=PF.Y).write(str(DATA / "gray.pfm"))
    mi.Bitmap(rng_image(9, 3, 4, 3, np.uint8, 255), pixel_format=PF.RGB).write(str(DATA / "rgb.ppm"))
    # smooth content so that decoders' IDCT and chroma upsampling differences stay small
    yy, xx = np.mgrid[0:8, 0:8]
    jpg = np.stack([xx * 30 + 10, yy * 28 + 20, 200 - xx * 10 - yy * 10], axis=-1).astype(np.uint8)
    mi.Bitmap(jpg, pixel_format=PF.RGB).write(str(DATA / "rgb.jpg"), quality=100)
    write_bmp(DATA / "rgb.bmp", rng_image(10, 3, 4, 3, np.uint8, 255))
    write_tga(DATA / "rgb.tga", rng_image(11, 3, 4, 3, np.uint8, 255), rle=False)
    tga = rng_image(12, 3, 4, 3, np.uint8, 255)
    tga[0, 1:4] = tga[0, 0]  # a run for the RLE encoder
    write_tga(DATA / "rgb_rle.tga", tga, rle=True)


def f32(x):
    """`x` rounded to f32, as the shortest decimal that reads back as that f32."""
    return float(str(np.float32(x)))


def f32s(xs):
    return [f32(x) for x in xs]


def si_at(uv):
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(*uv)
    return si


def samples(tex):
    out = []
    for uv in UVS:
        si = si_at(uv)
        c = tex.eval(si)
        out.append([f32s(uv), f32s([c[0], c[1], c[2]]), f32(tex.eval_1(si))])
    return out


def half_rounding_differs(file):
    """True when Mitsuba's stored halves for this 16-bit sRGB file differ from the correctly
    rounded sRGB decoding Tessera stores. Mitsuba decodes with a rational fit of the sRGB
    curve, which sends 46 of the 65536 codes to the neighbouring half float."""
    codes = np.array(mi.Bitmap(str(DATA / file)), copy=False)
    channels = 1 if codes.ndim == 2 or codes.shape[2] <= 2 else 3
    codes = codes.reshape(codes.shape[0], codes.shape[1], -1)[:, :, :channels]
    x = (codes.astype(np.float32) / np.float32(65535)).astype(np.float64)
    ours = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float16)
    stored = np.array(mi.traverse(mi.load_dict({"type": "bitmap", "filename": str(DATA / file)}))["data"])
    return bool(np.any(stored.reshape(ours.shape) != ours))


def uv_spec(d, to_uv):
    """Adds `to_uv` to Mitsuba's dict `d`; returns it as the test reads it."""
    if to_uv is None:
        return None
    if len(to_uv) == 4:
        d["to_uv"] = mi.ScalarTransform4f(np.array(to_uv))
        return {"mat4": [f32s(r) for r in to_uv]}
    d["to_uv"] = mi.ScalarTransform3f(np.array(to_uv))
    return {"mat3": [f32s(r) for r in to_uv]}


def bitmap_case(file, wrap="repeat", filt="bilinear", raw=False, to_uv=None, half=False):
    d = {"type": "bitmap", "filename": str(DATA / file), "wrap_mode": wrap, "filter_type": filt, "raw": raw}
    uv = uv_spec(d, to_uv)
    tex = mi.load_dict(d)
    return {"file": file, "wrap": wrap, "filter": filt, "raw": raw, "to_uv": uv, "half_rounding": half,
            "mean": f32(tex.mean()), "samples": samples(tex)}


def color_spec(c):
    """A checkerboard colour: Mitsuba's value and the test's."""
    if c is None:
        return None, None
    kind, value = c
    if kind == "float":
        return value, {"float": f32(value)}
    if kind == "rgb":
        return {"type": "rgb", "value": value}, {"rgb": f32s(value)}
    return {"type": "bitmap", "filename": str(DATA / value)}, {"bitmap": value}


def checkerboard_case(color0=None, color1=None, to_uv=None):
    d = {"type": "checkerboard"}
    c0, r0 = color_spec(color0)
    c1, r1 = color_spec(color1)
    if c0 is not None:
        d["color0"] = c0
    if c1 is not None:
        d["color1"] = c1
    uv = uv_spec(d, to_uv)
    tex = mi.load_dict(d)
    return {"color0": r0, "color1": r1, "to_uv": uv, "mean": f32(tex.mean()), "samples": samples(tex)}


def mesh_attribute_cases():
    """A unit quad in z = 0 (two triangles) with vertex and face attributes, hit by rays
    straight down at points given by barycentric coordinates."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)
    attrs = {
        "vertex_color": (3, [0.9, 0.1, 0.2, 0.3, 0.8, 0.4, 0.05, 0.6, 0.95, 0.5, 0.5, 0.25]),
        "vertex_w": (1, [0.0, 1.0, 3.0, 7.0]),
        "face_id": (1, [0.25, 0.75]),
        "face_rgb": (3, [0.1, 0.2, 0.3, 0.6, 0.5, 0.4]),
    }
    mesh = mi.Mesh("quad", 4, 2, has_vertex_normals=False, has_vertex_texcoords=False)
    params = mi.traverse(mesh)
    params["vertex_positions"] = positions.ravel()
    params["faces"] = faces.ravel()
    params.update()
    for name, (comp, data) in attrs.items():
        mesh.add_attribute(name, comp, data)
    scene = mi.load_dict({"type": "scene", "quad": mesh})
    points = [(0, (0.2, 0.3, 0.5)), (0, (0.6, 0.1, 0.3)), (1, (0.1, 0.45, 0.45)), (1, (0.7, 0.2, 0.1))]
    rows = []
    for name, scale in [("vertex_color", 1.0), ("vertex_w", 0.5), ("face_id", 2.0), ("face_rgb", 1.0)]:
        tex = mi.load_dict({"type": "mesh_attribute", "name": name, "scale": scale})
        for face, b in points:
            p = sum(bi * positions[v] for bi, v in zip(b, faces[face]))
            si = scene.ray_intersect(mi.Ray3f(mi.Point3f(p[0], p[1], 1.0), mi.Vector3f(0, 0, -1)))
            assert si.is_valid() and si.prim_index == face
            c = tex.eval(si)
            # Mitsuba throws for eval_1 of a 3-component attribute: null
            y = f32(tex.eval_1(si)) if attrs[name][0] == 1 else None
            rows.append([name, f32(scale), face, list(map(int, faces[face])), f32s(b), f32s([c[0], c[1], c[2]]), y])
    attr_rows = [[n, c, f32s(d)] for n, (c, d) in attrs.items()]
    return attr_rows, rows


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--regenerate", action="store_true", help="rewrite the test images first")
    args = ap.parse_args()
    if args.regenerate or not (DATA / "rgb8.png").exists():
        regenerate()

    cases = []
    for file, half in [("rgb8.png", False), ("rgb16.png", True)]:
        for raw in [False, True]:
            for wrap in WRAPS:
                for filt in FILTERS:
                    cases.append(bitmap_case(file, wrap, filt, raw, half=half and not raw and half_rounding_differs(file)))
    for wrap in WRAPS:
        for filt in FILTERS:
            cases.append(bitmap_case("gray8.png", wrap, filt))
            cases.append(bitmap_case("rgb32.exr", wrap, filt))
    cases.append(bitmap_case("gray8.png", raw=True))
    for filt in FILTERS:
        cases.append(bitmap_case("rgba8.png", "clamp", filt))
        cases.append(bitmap_case("ya16.png", "mirror", filt, half=half_rounding_differs("ya16.png")))
        cases.append(bitmap_case("ya16.png", "repeat", filt, raw=True))
        for file in ["rgba16.exr", "y32.exr", "rgb.hdr", "gray.pfm", "rgb.ppm", "rgb.bmp", "rgb.tga",
                     "rgb_rle.tga", "rgb.jpg", "tiny1x3.png", "tiny1x1.png"]:
            cases.append(bitmap_case(file, "repeat", filt))
        cases.append(bitmap_case("rgb8.png", "repeat", filt, to_uv=TO_UV_4))
        cases.append(bitmap_case("rgb8.png", "mirror", filt, to_uv=TO_UV_3))

    boards = [
        checkerboard_case(),
        checkerboard_case(("rgb", [0.9, 0.1, 0.2]), ("float", 0.7)),
        checkerboard_case(("rgb", [0.25, 0.5, 1.0]), ("rgb", [0.0, 0.3, 0.6]), to_uv=TO_UV_4),
        checkerboard_case(("float", 0.1), ("bitmap", "rgb8.png")),
    ]
    attr_rows, mesh_rows = mesh_attribute_cases()

    goldens = {
        "generator": "scripts/texture-goldens.py, Mitsuba " + mi.__version__ + " (scalar_rgb)",
        "bitmap": cases,
        "checkerboard": boards,
        "mesh_attributes": attr_rows,
        "mesh_lookups": mesh_rows,
    }
    # one case per line: diffs of a regenerated file stay readable
    out = sys.stdout
    out.write("{\n")
    items = list(goldens.items())
    for i, (key, value) in enumerate(items):
        end = ",\n" if i + 1 < len(items) else "\n"
        if isinstance(value, list):
            rows = ",\n".join("  " + json.dumps(v) for v in value)
            out.write(f"{json.dumps(key)}: [\n{rows}\n]{end}")
        else:
            out.write(f"{json.dumps(key)}: {json.dumps(value)}{end}")
    out.write("}\n")


if __name__ == "__main__":
    main()
