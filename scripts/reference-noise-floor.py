#!/usr/bin/env python3
"""Prints how much of an equal-time relMSE is the reference's own noise: per scene, the mean over
pixels of se^2 / (ref^2 + 1e-4) (channel mean, the same denominator as `film::compare::relmse`),
from `reference.stderr.exr`. A render x independent of the reference has
E[(x - ref)^2] = E[(x - truth)^2] + Var(ref), so this floor is added to every column of a row
alike and pulls every ratio between them towards 1.

    pip install numpy OpenEXR
    python3 scripts/reference-noise-floor.py scenes/{cornell-box,caustic-glass}

With `--relmse NAME=VALUE,...` per scene (e.g. `--relmse cornell-box:vcm=1.92e-3,emis-vcm=8.24e-4`)
it also prints each value's floor share and the ratios with the floor subtracted. That
subtraction is approximate: it ignores the top 0.1 % of pixel errors the bench drops, and the
standard errors come from the spread of 128-spp passes, which understates heavy tails.
"""
import argparse
import importlib.util
import os

import numpy as np

_tools = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared", "tools", "exrcompare.py")
_spec = importlib.util.spec_from_file_location("exrcompare", _tools)
exrcompare = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(exrcompare)


def floor(scene_dir):
    ref = exrcompare.load_rgb(os.path.join(scene_dir, "reference.exr"))
    se = exrcompare.load_rgb(os.path.join(scene_dir, "reference.stderr.exr"))
    f = (se ** 2 / (ref ** 2 + 1e-4)).mean(axis=-1).ravel()
    return f.mean(), np.median(f)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+", help="scene folders holding reference.exr and reference.stderr.exr")
    ap.add_argument("--relmse", action="append", default=[],
                    help="SCENE:NAME=VALUE,NAME=VALUE... measured relMSEs of one scene")
    args = ap.parse_args()
    measured = {}
    for item in args.relmse:
        scene, _, pairs = item.partition(":")
        measured[scene] = {k: float(v) for k, v in (p.split("=") for p in pairs.split(","))}
    for d in args.scenes:
        name = os.path.basename(os.path.normpath(d))
        mean, median = floor(d)
        line = f"{name:24s} floor {mean:.3e} (median pixel {median:.3e})"
        values = measured.get(name, {})
        for k, v in values.items():
            line += f"  {k} {v:.3e} ({mean / v:.0%} floor)"
        names = list(values)
        for a in names:
            for b in names:
                if a < b:
                    raw = values[b] / values[a]
                    corrected = (values[b] - mean) / (values[a] - mean)
                    line += f"  {a} over {b}: raw {raw:.2f}, without the floor {corrected:.2f}"
        print(line)


if __name__ == "__main__":
    main()
