#!/usr/bin/env python3
"""Prints the weights Mitsuba 3 gives the pixels around one sample, for every reconstruction
filter, as Rust table rows for `common/src/film/filter.rs`'s golden test.

    python3 -m venv venv && venv/bin/pip install mitsuba numpy
    apt-get install -y libllvm19
    venv/bin/python scripts/filter-goldens.py

The sample lies at raster position (3.3, 4.6) of an 8x8 block without border; the variant is
llvm_ad_rgb, the one the references are rendered with (scalar variants use a step table).
"""
import mitsuba as mi
import numpy as np

mi.set_variant("llvm_ad_rgb")
FILTERS = [
    ("gaussian", {"type": "gaussian"}),
    ("tent", {"type": "tent", "radius": 1.3}),
    ("mitchell", {"type": "mitchell"}),
    ("catmullrom", {"type": "catmullrom"}),
    ("lanczos", {"type": "lanczos"}),
]
for name, spec in FILTERS:
    block = mi.ImageBlock(size=[8, 8], offset=[0, 0], channel_count=4, rfilter=mi.load_dict(spec), border=False)
    block.clear()
    block.put(pos=mi.Point2f(3.3, 4.6), values=[1.0, 2.0, 3.0, 1.0])
    weight = np.array(block.tensor())[..., 3]
    cells = ", ".join(f"({x}, {y}, {weight[y, x]:.9e})" for y, x in np.argwhere(weight != 0))
    print(f'("{name}", &[{cells}]),')
