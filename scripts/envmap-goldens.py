#!/usr/bin/env python3
"""Prints the radiance Mitsuba 3's `envmap` returns for chosen directions, as Rust table rows for
`common/src/light/envmap/tests.rs`. The map is a 5x4 image of distinct colours, built here (the
same numbers are in the Rust test), with scale 2 and a rotation.

    python3 -m venv venv && venv/bin/pip install mitsuba numpy
    venv/bin/python scripts/envmap-goldens.py
"""
import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")
W, H = 5, 4
img = np.array([[[0.1 + 0.2 * x + 0.05 * y, 1.0 - 0.15 * y, 0.3 + 0.1 * ((x * 7 + y * 3) % 5)] for x in range(W)]
                for y in range(H)], dtype=np.float32)
for rotate in [False, True]:
    to_world = mi.ScalarTransform4f().rotate((np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])).tolist(), 37.0) if rotate else mi.ScalarTransform4f()
    env = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(img), "scale": 2.0, "to_world": to_world})
    rows = []
    for d in [(0, 1, 0), (0, -1, 0), (0, 0, -1), (1, 0, 0), (0, 0, 1), (-1, 0, 0), (0.3, 0.5, -0.81),
              (-0.7, 0.1, 0.2), (0.05, -0.9, 0.4), (-0.01, 0.2, -0.98)]:
        d = np.array(d, dtype=float)
        d /= np.linalg.norm(d)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(-d)
        v = env.eval(si)
        rows.append(f"(({d[0]:.9}, {d[1]:.9}, {d[2]:.9}), ({v[0]:.9e}, {v[1]:.9e}, {v[2]:.9e}))")
    print(("ROTATED" if rotate else "PLAIN") + ": &[" + ", ".join(rows) + "],")
