"""Mesh helpers of the asset scripts (make-assets.py, make-realistic.py): OBJ, PLY and Mitsuba
`serialized` writers, and small generated meshes (grids, icospheres, lathes, boxes)."""
import struct
import zlib

import numpy as np


def write_obj(path, groups, header=""):
    """groups: list of (name, material, V, N or None, UV or None, F); faces are 0-based per group."""
    lines = [f"# {header}"] if header else []
    lines.append("mtllib none.mtl")
    vo = no = to = 0
    for name, mat, V, N, UV, F in groups:
        lines += [f"o {name}", f"g {name}", f"usemtl {mat}", "s off"]
        lines += ["v %.6f %.6f %.6f" % tuple(p) for p in V]
        if UV is not None:
            lines += ["vt %.6f %.6f" % tuple(t) for t in UV]
        if N is not None:
            lines += ["vn %.6f %.6f %.6f" % tuple(n) for n in N]
        for f in F:
            idx = []
            for k in f:
                s = str(k + 1 + vo)
                if UV is not None and N is not None:
                    s += f"/{k + 1 + to}/{k + 1 + no}"
                elif N is not None:
                    s += f"//{k + 1 + no}"
                elif UV is not None:
                    s += f"/{k + 1 + to}"
                idx.append(s)
            lines.append("f " + " ".join(idx))
        vo += len(V)
        no += 0 if N is None else len(N)
        to += 0 if UV is None else len(UV)
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")


def write_ply(path, V, F, vprops=None, fprops=None, comment=""):
    """Binary little-endian PLY. vprops/fprops: list of (name, float array (n,)) stored as float32."""
    vprops = vprops or []
    fprops = fprops or []
    hdr = ["ply", "format binary_little_endian 1.0"]
    if comment:
        hdr.append(f"comment {comment}")
    hdr.append(f"element vertex {len(V)}")
    hdr += [f"property float {n}" for n in ("x", "y", "z")]
    hdr += [f"property float {n}" for n, _ in vprops]
    hdr.append(f"element face {len(F)}")
    hdr.append("property list uchar int vertex_indices")
    hdr += [f"property float {n}" for n, _ in fprops]
    hdr.append("end_header")
    vcols = np.column_stack([V] + [a for _, a in vprops]).astype("<f4")
    body = bytearray(vcols.tobytes())
    fcols = np.column_stack([a for _, a in fprops]).astype("<f4") if fprops else None
    for i, f in enumerate(F):
        body += struct.pack("<Biii", 3, *[int(k) for k in f])
        if fcols is not None:
            body += fcols[i].tobytes()
    with open(path, "wb") as fh:
        fh.write(("\n".join(hdr) + "\n").encode("ascii") + bytes(body))


def serialized_block(name, V, F, N=None, UV=None, double=False):
    """One mesh of Mitsuba's `serialized` format, version 4 (zlib stream after a 4-byte header)."""
    flags = (0x2000 if double else 0x1000) | (0x1 if N is not None else 0) | (0x2 if UV is not None else 0)
    dt = "<f8" if double else "<f4"
    payload = struct.pack("<I", flags) + name.encode("utf-8") + b"\0" + struct.pack("<QQ", len(V), len(F))
    payload += np.ascontiguousarray(V, dtype=dt).tobytes()
    if N is not None:
        payload += np.ascontiguousarray(N, dtype=dt).tobytes()
    if UV is not None:
        payload += np.ascontiguousarray(UV, dtype=dt).tobytes()
    payload += np.ascontiguousarray(F, dtype="<u4").tobytes()
    return struct.pack("<HH", 0x041C, 4) + zlib.compress(payload, 9)


def write_serialized(path, blocks):
    data, offsets = b"", []
    for b in blocks:
        offsets.append(len(data))
        data += b
    data += struct.pack("<%dQ" % len(offsets), *offsets) + struct.pack("<I", len(offsets))
    with open(path, "wb") as f:
        f.write(data)


def grid_faces(nu, nv):
    """Triangles of an (nu+1) x (nv+1) vertex grid, vertex (i, j) at index j*(nu+1)+i."""
    F = []
    for j in range(nv):
        for i in range(nu):
            a = j * (nu + 1) + i
            b, c, d = a + 1, a + nu + 1, a + nu + 2
            F += [(a, b, d), (a, d, c)]
    return np.array(F, dtype=np.int64)


def icosphere(subdiv):
    t = (1 + 5 ** 0.5) / 2
    V = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    V = [np.array(v, float) / np.linalg.norm(v) for v in V]
    F = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
         (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdiv):
        cache, nf = {}, []

        def mid(a, b):
            k = (min(a, b), max(a, b))
            if k not in cache:
                m = V[a] + V[b]
                V.append(m / np.linalg.norm(m))
                cache[k] = len(V) - 1
            return cache[k]
        for a, b, c in F:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        F = nf
    return np.array(V), np.array(F)


def vertex_normals(V, F):
    N = np.zeros_like(V)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    for k in range(3):
        np.add.at(N, F[:, k], fn)
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def lathe(profile, segments):
    """Surface of revolution about +y. profile: (n, 2) of (radius, height). Returns V, F."""
    n = len(profile)
    ang = np.linspace(0, 2 * np.pi, segments + 1)
    V = np.array([(r * np.cos(a), y, -r * np.sin(a)) for (r, y) in profile for a in ang])
    # faces: ring j (profile index), segment i; outward for a profile going up
    F = []
    for j in range(n - 1):
        for i in range(segments):
            a = j * (segments + 1) + i
            b, c, d = a + 1, a + segments + 1, a + segments + 2
            F += [(a, b, d), (a, d, c)]
    F = np.array(F)
    return V, F


def box(lo, hi):
    """Axis-aligned box as 6 quads with per-face normals: returns V (24), N (24), F (12 tris)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    V, N, F = [], [], []
    for axis in range(3):
        for s in (0, 1):
            n = np.zeros(3)
            n[axis] = 1 if s else -1
            u, v = [(1, 2), (2, 0), (0, 1)][axis]
            quad = []
            for a, b in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = np.zeros(3)
                p[axis] = hi[axis] if s else lo[axis]
                p[u] = hi[u] if a else lo[u]
                p[v] = hi[v] if b else lo[v]
                quad.append(p)
            base = len(V)
            V += quad
            N += [n] * 4
            # orient CCW around n
            if np.dot(np.cross(quad[1] - quad[0], quad[2] - quad[0]), n) > 0:
                F += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
            else:
                F += [(base, base + 2, base + 1), (base, base + 3, base + 2)]
    return np.array(V), np.array(N), np.array(F)
