#!/usr/bin/env python3
"""Writes common/tests/data/meshes/two-meshes.serialized (Mitsuba's serialized format, version 4,
two meshes: float32 with normals and uvs, float64 without) and a version-3 copy of the second,
then prints what Mitsuba 3 loads from them, for common/src/scene/load/serialized.rs's tests.

    venv/bin/python scripts/serialized-fixture.py
"""
import struct
import zlib
from pathlib import Path

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
out = Path(__file__).resolve().parent.parent / "common/tests/data/meshes"


def mesh_block(version, name, positions, faces, normals=None, uvs=None, double=False):
    flags = (0x1 if normals is not None else 0) | (0x2 if uvs is not None else 0) | (0x2000 if double else 0x1000)
    body = struct.pack("<I", flags)
    if version == 4:
        body += name.encode() + b"\0"
    body += struct.pack("<QQ", len(positions), len(faces))
    fmt = "<%dd" if double else "<%df"
    for arr in [positions, normals, uvs]:
        if arr is not None:
            flat = np.asarray(arr, dtype=float).ravel()
            body += struct.pack(fmt % len(flat), *flat)
    body += struct.pack("<%dI" % (3 * len(faces)), *np.asarray(faces).ravel())
    return struct.pack("<HH", 0x041C, version) + zlib.compress(body)


quad = dict(positions=[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], faces=[[0, 1, 2], [0, 2, 3]],
            normals=[[0, 0, 1]] * 4, uvs=[[0, 0], [1, 0], [1, 1], [0.25, 0.75]])
tri = dict(positions=[[0, 0, 2], [2, 0, 2], [0, 3, 2]], faces=[[0, 2, 1]])
for version, path in [(4, "two-meshes.serialized"), (3, "two-meshes-v3.serialized")]:
    blocks = [mesh_block(version, "quad", **quad), mesh_block(version, "tri", double=True, **tri)]
    offsets, data = [], b""
    for b in blocks:
        offsets.append(len(data))
        data += b
    table = b"".join(struct.pack("<Q" if version == 4 else "<I", o) for o in offsets)
    (out / path).write_bytes(data + table + struct.pack("<I", len(blocks)))
    for index in range(2):
        m = mi.load_dict({"type": "serialized", "filename": str(out / path), "shape_index": index})
        params = mi.traverse(m)
        print(path, index, "positions", list(np.array(params["vertex_positions"])),
              "uvs", list(np.array(params["vertex_texcoords"])), "faces", list(np.array(params["faces"])))
