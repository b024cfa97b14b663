#!/usr/bin/env python3
"""Merge independent Mitsuba renders of one scene into a longer reference.

Each input is a `render_reference.py` output: `X.exr`, its `X.stderr.exr` (per-pixel standard
error from the spread of equal passes) and the JSON line it printed (`X.json`). The runs must
use disjoint pass seeds (`--seed`), the same variant, integrator and resolution. The merged
image is the spp-weighted mean; the per-pixel standard errors combine as
sqrt(sum n_i^2 se_i^2) / sum n_i, as the means are independent. The merged JSON keeps the
first run's fields, sums spp, passes and render_s, and lists every run under `merged_from`.

    pip install numpy OpenEXR
    python3 scripts/merge-references.py scenes/cornell-box/reference \\
        /work/refs/cornell-box --seed-starts 0,100000 --out scenes/cornell-box/reference

(each argument is a path without `.exr`; `--out` writes OUT.exr, OUT.stderr.exr, OUT.json,
and rewrites OUT.png when `--png` is given and Mitsuba is importable).
"""
import argparse
import json
import os
import sys
import time

import numpy as np
import OpenEXR


def read_rgb(path):
    with OpenEXR.File(path) as f:
        channels = f.channels()
        if "RGB" in channels:
            return np.asarray(channels["RGB"].pixels, dtype=np.float64)
        return np.stack([np.asarray(channels[c].pixels, dtype=np.float64) for c in "RGB"], axis=-1)


def write_rgb(path, rgb):
    header = {"compression": OpenEXR.PIZ_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {c: np.ascontiguousarray(rgb[..., i].astype(np.float32)) for i, c in enumerate("RGB")}
    with OpenEXR.File(header, channels) as f:
        f.write(path)


def read_json(path):
    with open(path) as f:
        text = f.read().strip()
    # a pretty-printed reference.json, or the JSON line render_reference.py printed last
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return json.loads(text.splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="runs to merge, each a path without .exr")
    ap.add_argument("--out", required=True, help="output path without .exr")
    ap.add_argument("--png", action="store_true", help="also write OUT.png (needs mitsuba)")
    ap.add_argument("--seed-starts", default=None,
                    help="comma-separated first pass seed of each run without merged_from (recorded)")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seed_starts.split(",")] if args.seed_starts else [None] * len(args.runs)
    if len(seeds) != len(args.runs):
        sys.exit("error: --seed-starts needs one seed per run")
    runs = []
    for r, seed in zip(args.runs, seeds):
        meta = read_json(r + ".json")
        meta.setdefault("date_utc", time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(os.path.getmtime(r + ".exr"))))
        if seed is not None and "merged_from" not in meta:
            meta["seed_start"] = seed
        runs.append((meta, read_rgb(r + ".exr"), read_rgb(r + ".stderr.exr")))
    first = runs[0][0]
    for meta, img, _ in runs[1:]:
        for key in ("variant", "integrator", "width", "height", "max_depth"):
            if key in first and key in meta and meta[key] != first[key]:
                sys.exit(f"error: {key} differs: {first[key]} against {meta[key]}")
        if img.shape != runs[0][1].shape:
            sys.exit(f"error: image sizes differ: {runs[0][1].shape} against {img.shape}")
    n = np.array([m["spp"] for m, _, _ in runs], dtype=np.float64)
    total = n.sum()
    mean = sum(ni * img for ni, (_, img, _) in zip(n, runs)) / total
    stderr = np.sqrt(sum((ni * se) ** 2 for ni, (_, _, se) in zip(n, runs))) / total
    out = dict(first)
    out.pop("merged_from", None)
    out.pop("out", None)
    out.pop("stderr_out", None)
    out.pop("seed_start", None)
    merged_from = []
    for meta, _, _ in runs:
        if "merged_from" in meta:
            merged_from.extend(meta["merged_from"])
        else:
            entry = {k: meta[k] for k in ("spp", "render_s", "passes", "date_utc", "seed_start") if k in meta}
            merged_from.append(entry)
    lum = lambda a: a[..., 0] * 0.2126 + a[..., 1] * 0.7152 + a[..., 2] * 0.0722
    out.update({
        "spp": int(total),
        "passes": int(sum(m["passes"] for m, _, _ in runs)),
        "render_s": round(sum(m["render_s"] for m, _, _ in runs), 2),
        "samples_per_s": round(first["width"] * first["height"] * total / sum(m["render_s"] for m, _, _ in runs)),
        "mean_rgb": [float(x) for x in mean.reshape(-1, 3).mean(0)],
        "rel_stderr_of_image_mean": float(np.sqrt((lum(stderr) ** 2).sum()) / max(lum(mean).sum(), 1e-12)),
        "median_pixel_rel_stderr": float(np.median(lum(stderr) / np.maximum(lum(mean), 1e-3))),
        "date_utc": max(e["date_utc"] for e in merged_from if "date_utc" in e),
        "merged_from": merged_from,
    })
    write_rgb(args.out + ".exr", mean)
    write_rgb(args.out + ".stderr.exr", stderr)
    with open(args.out + ".json", "w") as f:
        f.write(json.dumps(out, indent=1) + "\n")
    if args.png:
        import mitsuba as mi
        mi.set_variant("scalar_rgb")
        mi.util.write_bitmap(args.out + ".png", mean.astype(np.float32))
    print(json.dumps({"out": args.out, "spp": int(total), "runs": len(runs)}))


if __name__ == "__main__":
    main()
