#!/usr/bin/env python3
"""Whether two EXRs hold bit-identical R, G, B (first part): prints 'same' or the count that differ."""
import sys, OpenEXR, numpy as np
def rgb(p):
    f = OpenEXR.File(p)
    ch = f.parts[0].channels
    return [np.asarray(ch[c].pixels).view(np.uint32) for c in ('R', 'G', 'B')] if 'R' in ch else [np.asarray(ch['RGB'].pixels).view(np.uint32)]
a, b = rgb(sys.argv[1]), rgb(sys.argv[2])
diff = sum(int((x != y).sum()) for x, y in zip(a, b))
print('same' if diff == 0 else f'{diff} values differ')
