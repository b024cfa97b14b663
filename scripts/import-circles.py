#!/usr/bin/env python3
"""Usage: scripts/import-circles.py CRATE/src. Import circles between modules of one crate (file granularity). An edge A -> B means a
file of module A names module B (use crate::..., super::...). Edges between a module and its
own ancestors or descendants are ignored: those are the module tree, not circles."""
import os, re, sys
root = sys.argv[1]
mods = {}
for d, _, fs in os.walk(root):
    for f in fs:
        if not f.endswith('.rs'): continue
        p = os.path.join(d, f); rel = os.path.relpath(p, root)[:-3].split(os.sep)
        if rel[-1] in ('mod', 'lib', 'main'): rel = rel[:-1]
        mods[tuple(rel)] = p
def resolve(path):
    path = list(path)
    while path and tuple(path) not in mods: path.pop()
    return tuple(path)
edges = {m: set() for m in mods}
for m, p in mods.items():
    src = open(p).read()
    src = re.sub(r'#\[cfg\(test\)\]\s*mod tests\s*\{.*', '', src, flags=re.S)
    src = re.sub(r'//[^\n]*', '', src)
    is_dir = os.path.basename(p) in ('mod.rs', 'lib.rs')
    for mt in re.finditer(r'\b((?:crate|super)(?:::\w+)+)', src):
        parts = mt.group(1).split('::')
        base = list(m) if is_dir else list(m[:-1])
        if parts[0] == 'crate': base = []; parts = parts[1:]
        while parts and parts[0] == 'super': base = base[:-1]; parts = parts[1:]
        t = resolve(base + parts)
        if t == m or t[:len(m)] == m or m[:len(t)] == t: continue
        edges[m].add(t)
    for mt in re.finditer(r'\buse\s+\{?\s*(\w+)::', src):
        pass
# Tarjan
idx, low, st, on, out, c = {}, {}, [], set(), [], [0]
sys.setrecursionlimit(10000)
def sc(v):
    idx[v] = low[v] = c[0]; c[0] += 1; st.append(v); on.add(v)
    for w in edges[v]:
        if w not in idx: sc(w); low[v] = min(low[v], low[w])
        elif w in on: low[v] = min(low[v], idx[w])
    if low[v] == idx[v]:
        comp = []
        while True:
            w = st.pop(); on.discard(w); comp.append(w)
            if w == v: break
        if len(comp) > 1: out.append(comp)
for v in mods:
    if v not in idx: sc(v)
for comp in out: print(' <-> '.join('::'.join(x) or 'crate' for x in comp))
print(f'{len(out)} circle(s) in {root}')
