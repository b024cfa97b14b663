#!/usr/bin/env python3
"""The speed-ups of emis-vcm over vcm and emis-bdpt over bdpt, before and after, from the
outputs of scripts/before-after-equal-time.sh (usage: equal-time-table.py OUTDIR)."""
import re, sys, math, os
d = sys.argv[1]
scenes = ['caustic-glass', 'cornell-box', 'env-lit', 'glossy-interreflection', 'indirect-room', 'veach-mis']
cols = ['pt', 'bdpt', 'vcm', 'emis-bdpt', 'emis-vcm']
def parse(p):
    for line in open(p):
        if line.startswith('| ') and not line.startswith('| scene'):
            cells = [c.strip() for c in line.strip().strip('|').split('|')]
            return {k: float(v.split()[0]) for k, v in zip(cols, cells[1:])}
rows = []
print('| scene | emis-vcm/vcm before | after | emis-bdpt/bdpt before | after | relMSE emis-vcm before | after |')
print('|---|---|---|---|---|---|---|')
g = {'bv': [], 'av': [], 'bb': [], 'ab': []}
for s in scenes:
    b, a = parse(os.path.join(d, f'{s}.before.txt')), parse(os.path.join(d, f'{s}.after.txt'))
    bv, av = b['vcm'] / b['emis-vcm'], a['vcm'] / a['emis-vcm']
    bb, ab = b['bdpt'] / b['emis-bdpt'], a['bdpt'] / a['emis-bdpt']
    for k, v in zip(('bv', 'av', 'bb', 'ab'), (bv, av, bb, ab)): g[k].append(v)
    print(f'| {s} | {bv:.2f}× | {av:.2f}× | {bb:.2f}× | {ab:.2f}× | {b["emis-vcm"]:.5f} | {a["emis-vcm"]:.5f} |')
gm = lambda v: math.exp(sum(map(math.log, v)) / len(v))
print(f'| geometric mean | {gm(g["bv"]):.2f}× | {gm(g["av"]):.2f}× | {gm(g["bb"]):.2f}× | {gm(g["ab"]):.2f}× | | |')
