#!/usr/bin/env python3
"""Prints Mitsuba 3.9.1's BSDF values and densities for a few models and direction pairs, as
Rust table rows for `common/src/bsdf/goldens.rs`.

    python3 -m venv venv && venv/bin/pip install mitsuba numpy
    venv/bin/python scripts/bsdf-goldens.py

Directions are in the local frame (z = normal, x = the tangent alpha_u acts along). Mitsuba's
`si.wi` is Tessera's `wo` and Mitsuba's `wo` is Tessera's `wi`; Mitsuba's value includes the
cosine of its `wo`, which is divided out here.
"""
import math
import mitsuba as mi

mi.set_variant("scalar_rgb")

MODELS = [
    ("roughplastic_ggx", {"type": "roughplastic", "distribution": "ggx", "alpha": 0.35, "int_ior": 1.5,
                          "diffuse_reflectance": {"type": "rgb", "value": [0.4, 0.42, 0.45]}}),
    ("roughplastic_beckmann_nonlinear", {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.2,
                                         "int_ior": 1.33, "nonlinear": True,
                                         "diffuse_reflectance": {"type": "rgb", "value": [0.8, 0.5, 0.2]}}),
    ("plastic", {"type": "plastic", "int_ior": 1.5,
                 "diffuse_reflectance": {"type": "rgb", "value": [0.4, 0.42, 0.45]}}),
    ("roughconductor_anisotropic", {"type": "roughconductor", "distribution": "ggx", "alpha_u": 0.04,
                                    "alpha_v": 0.35, "material": "Cu"}),
    ("roughdielectric", {"type": "roughdielectric", "distribution": "ggx", "alpha": 0.2, "int_ior": 1.5}),
]


def direction(theta, phi):
    t, p = math.radians(theta), math.radians(phi)
    return mi.Vector3f(math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


# (θ, φ) of Tessera's wo, then of wi; a negative θ means the lower hemisphere
PAIRS = [((0, 0), (0, 0)), ((30, 0), (10, 180)), ((60, 0), (20, 120)), ((80, 30), (10, 200)),
         ((85, 0), (85, 180)), ((45, 90), (45, 270)), ((40, 10), (150, 190)), ((20, 0), (170, 0))]

ctx = mi.BSDFContext()
for name, props in MODELS:
    bsdf = mi.load_dict(props)
    print(f"    // {name}")
    for (to, po), (ti, pi) in PAIRS:
        si = mi.SurfaceInteraction3f()
        si.wi = direction(to, po)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        wo = direction(ti, pi)
        value = bsdf.eval(ctx, si, wo)
        pdf = bsdf.pdf(ctx, si, wo)
        cos = abs(wo.z)
        v = [value[i] / cos for i in range(3)]
        print(f"    (\"{name}\", ({to}.0, {po}.0), ({ti}.0, {pi}.0), [{v[0]:.7e}, {v[1]:.7e}, {v[2]:.7e}], {pdf:.7e}),")
