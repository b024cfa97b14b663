#!/usr/bin/env python3
"""Prints the uv Mitsuba 3 reports where rays hit the shapes of common/tests/data/uv/scene.xml,
as Rust table rows for common/tests/uv.rs.

    venv/bin/python scripts/uv-goldens.py
"""
from pathlib import Path

import mitsuba as mi

mi.set_variant("scalar_rgb")
scene = mi.load_file(str(Path(__file__).resolve().parent.parent / "common/tests/data/uv/scene.xml"))
rows = []
for cx in [-6, -3, 0, 3, 6, 9, 12.5]:
    for dx, dy in [(0.13, 0.21), (-0.31, 0.07), (0.05, -0.38), (-0.22, -0.19)]:
        for oz, dz in [(5.0, -1.0), (-5.0, 1.0)]:
            o = mi.Point3f(cx + dx, dy, oz)
            si = scene.ray_intersect(mi.Ray3f(o, mi.Vector3f(0.02, -0.01, dz)))
            if si.is_valid():
                rows.append(f"(({o[0]:.6}, {o[1]:.6}, {o[2]:.6}), {dz:.1}, ({si.uv[0]:.7e}, {si.uv[1]:.7e}))")
print(",\n".join(rows))
