#!/usr/bin/env python3
"""Generate the three larger scenes "like the paper's" (Grittmann et al. 2022): living-room,
pool and kitchen, 640x480 each, with procedural meshes (height fields, lathe-revolved glasses,
displaced grids) and procedural textures. Deterministic: fixed seeds, re-running rewrites the
same files.

    /work/venv/bin/python scenes/make-realistic.py          # from the repository root

Meshes are Mitsuba `serialized` files (zlib-compressed, float32, explicit vertex normals where a
surface is meant to be smooth), textures 8-bit PNG/JPEG, environment maps RGBE (.hdr). The image,
mesh and envmap helpers come from `make-assets.py` (same conventions: texture v = 0 is the top
image row, envmap u = 0 looks along -z, u = 1/4 along +x).
"""
import importlib.util
import os

import numpy as np

_spec = importlib.util.spec_from_file_location(
    "make_assets", os.path.join(os.path.dirname(os.path.abspath(__file__)), "make-assets.py"))
A = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(A)

out, to_u8, write_ldr, write_float = A.out, A.to_u8, A.write_ldr, A.write_float
value_noise, sky = A.value_noise, A.sky
serialized_block, write_serialized = A.serialized_block, A.write_serialized

WIDTH, HEIGHT = 640, 480


# ----------------------------------------------------------------------------- mesh helpers

def grid(nu, nv):
    """Faces of an (nu+1) x (nv+1) vertex grid (vertex (i, j) at j*(nu+1)+i), vectorised."""
    j, i = np.mgrid[0:nv, 0:nu]
    a = (j * (nu + 1) + i).ravel()
    b, c, d = a + 1, a + nu + 1, a + nu + 2
    return np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]).astype(np.int64)


def normals(V, F):
    """Area-weighted vertex normals (oriented like the faces' winding)."""
    N = np.zeros_like(V)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    for k in range(3):
        np.add.at(N, F[:, k], fn)
    return N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-20)


def height_field(x0, x1, z0, z1, nx, nz, h):
    """Surface y = h(x, z) over a rectangle, faces wound so that the normals point up (+y).
    Returns V, N, UV, F; uv = ((x-x0)/(x1-x0), (z-z0)/(z1-z0))."""
    xs, zs = np.linspace(x0, x1, nx + 1), np.linspace(z0, z1, nz + 1)
    X, Z = np.meshgrid(xs, zs)
    V = np.stack([X, h(X, Z), Z], -1).reshape(-1, 3)
    F = grid(nx, nz)
    # grid winding with i along +x, j along +z gives normals along (+x) x (+z) = -y: flip
    F = F[:, [0, 2, 1]]
    UV = np.stack([(X - x0) / (x1 - x0), (Z - z0) / (z1 - z0)], -1).reshape(-1, 2)
    return V, normals(V, F), UV, F


def chaikin(P, iters, closed=False):
    """Corner cutting: rounds a polyline's corners (keeps the end points of an open one)."""
    P = np.asarray(P, float)
    for _ in range(iters):
        Q = [P[0]] if not closed else []
        for k in range(len(P) - (0 if closed else 1)):
            a, b = P[k], P[(k + 1) % len(P)]
            Q += [0.75 * a + 0.25 * b, 0.25 * a + 0.75 * b]
        if not closed:
            Q.append(P[-1])
        P = np.array(Q)
    return P


def resample(P, n):
    """n points evenly spaced by arc length along polyline P."""
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    t = np.linspace(0, s[-1], n)
    return np.stack([np.interp(t, s, P[:, 0]), np.interp(t, s, P[:, 1])], 1)


def revolve(profile, segments):
    """Closed surface of revolution about +y of a (radius, height) profile that starts and ends
    on the axis, traced so that the outside is on its right when walking along it with +y up
    (e.g. up the outer wall). Returns V, N, F with outward normals; faces at the poles that
    collapse to a line are dropped."""
    P = np.asarray(profile, float)
    n = len(P)
    ang = np.linspace(0, 2 * np.pi, segments + 1)[:-1]
    ca, sa = np.cos(ang), -np.sin(ang)
    V = np.stack([P[:, 0:1] * ca, np.repeat(P[:, 1:2], segments, 1), P[:, 0:1] * sa], -1).reshape(-1, 3)
    # 2-D normals of the profile: tangent (dr, dy) turned to the right -> (dy, -dr)
    T = np.gradient(P, axis=0)
    n2 = np.stack([T[:, 1], -T[:, 0]], 1)
    n2 /= np.maximum(np.linalg.norm(n2, axis=1, keepdims=True), 1e-20)
    N = np.stack([n2[:, 0:1] * ca, np.repeat(n2[:, 1:2], segments, 1), n2[:, 0:1] * sa], -1).reshape(-1, 3)
    j, i = np.mgrid[0:n - 1, 0:segments]
    a = (j * segments + i).ravel()
    b = (j * segments + (i + 1) % segments).ravel()
    c, d = a + segments, b + segments
    F = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    # orient: the face normal must agree with the vertex normals
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    if np.sum(fn * (N[F[:, 0]] + N[F[:, 1]] + N[F[:, 2]])) < 0:
        F = F[:, [0, 2, 1]]
        fn = -fn
    F = F[np.linalg.norm(fn, axis=1) > 1e-12]
    # on the axis every vertex of a ring is the same point: give them the pole's normal
    pole = P[:, 0] < 1e-9
    N = N.reshape(n, segments, 3)
    N[pole] = np.array([0.0, 1.0, 0.0])[None] * np.sign(n2[pole, 1])[:, None, None]
    return V, N.reshape(-1, 3), F.astype(np.int64)


def glass_profile(radius, height, wall, base, n=120, belly=0.0):
    """Drinking glass / vase: up the outside from the bottom centre, over the rim, down the
    inside to the inner bottom centre. belly bulges the walls (fraction of the radius)."""
    def r_out(y):
        t = y / height
        return radius * (1 + belly * np.sin(np.pi * t) * (1 - 0.4 * t))
    ys = np.linspace(0, height, 16)
    outer = [(0.0, 0.0)] + [(r_out(y), y) for y in ys]
    inner = [(r_out(y) - wall, y) for y in ys[::-1] if y >= base] + [(0.0, base)]
    P = chaikin(np.array(outer + inner), 3)
    return resample(P, n)


def transformed(V, N, scale=1.0, translate=(0, 0, 0)):
    return V * scale + np.asarray(translate, float), N


def merge(parts):
    """Concatenates (V, N, F) meshes into one."""
    Vs, Ns, Fs, off = [], [], [], 0
    for V, N, F in parts:
        Vs.append(V)
        Ns.append(N)
        Fs.append(F + off)
        off += len(V)
    return np.concatenate(Vs), np.concatenate(Ns), np.concatenate(Fs)


def trunc(a, bits):
    """float32 with the low `bits` of the mantissa cleared: the zlib stream shrinks by a third."""
    if a is None:
        return None
    u = np.ascontiguousarray(a, dtype=np.float32).view(np.uint32) & np.uint32(0xFFFFFFFF ^ ((1 << bits) - 1))
    return u.view(np.float32)


def ser(path, name, V, F, N=None, UV=None):
    """One-mesh `serialized` file; positions and uvs keep 13 mantissa bits, normals 11."""
    write_serialized(path, [serialized_block(name, trunc(V, 10), F, trunc(N, 12), trunc(UV, 10))])
    return len(F)


# ----------------------------------------------------------------------------- XML helpers

ROT = {"+z": "", "-z": '<rotate x="0" y="1" z="0" angle="180"/>', "+x": '<rotate x="0" y="1" z="0" angle="90"/>',
       "-x": '<rotate x="0" y="1" z="0" angle="-90"/>', "+y": '<rotate x="1" y="0" z="0" angle="-90"/>',
       "-y": '<rotate x="1" y="0" z="0" angle="90"/>'}


def rect(center, facing, a, b, inner, comment=""):
    """A `rectangle` facing `facing` with half extents a (local x) and b (local y): for +-z they
    lie along (x, y), for +-x along (z, y), for +-y along (x, z)."""
    c = ", ".join("%g" % v for v in center)
    x, y, z = center
    tr = f'<scale x="{a:g}" y="{b:g}" z="1"/>{ROT[facing]}<translate x="{x:g}" y="{y:g}" z="{z:g}"/>'
    com = f"    <!-- {comment} -->\n" if comment else ""
    del c
    return f'{com}    <shape type="rectangle">\n        <transform name="to_world">{tr}</transform>\n        {inner}\n    </shape>\n'


def cube(lo, hi, inner, comment=""):
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    com = f"    <!-- {comment} -->\n" if comment else ""
    return (f'{com}    <shape type="cube">\n        <transform name="to_world"><scale x="{h[0]:g}" y="{h[1]:g}" z="{h[2]:g}"/>'
            f'<translate x="{c[0]:g}" y="{c[1]:g}" z="{c[2]:g}"/></transform>\n        {inner}\n    </shape>\n')


def mesh(filename, inner, comment=""):
    com = f"    <!-- {comment} -->\n" if comment else ""
    return (f'{com}    <shape type="serialized">\n        <string name="filename" value="{filename}"/>\n'
            f'        {inner}\n    </shape>\n')


def header(comment, origin, target, fov, max_depth=12):
    o = ", ".join("%g" % v for v in origin)
    t = ", ".join("%g" % v for v in target)
    return f"""<?xml version="1.0" encoding="utf-8"?>
<!-- {comment} -->
<scene version="3.0.0">
    <integrator type="path">
        <integer name="max_depth" value="{max_depth}"/>
    </integrator>

    <sensor type="perspective">
        <float name="fov" value="{fov:g}"/>
        <string name="fov_axis" value="x"/>
        <transform name="to_world">
            <lookat origin="{o}" target="{t}" up="0, 1, 0"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="64"/>
        </sampler>
        <film type="hdrfilm">
            <integer name="width" value="{WIDTH}"/>
            <integer name="height" value="{HEIGHT}"/>
            <string name="pixel_format" value="rgb"/>
            <string name="component_format" value="float32"/>
            <rfilter type="box"/>
        </film>
    </sensor>

"""


def diffuse(rgb=None, tex=None, uv_scale=None):
    if tex:
        return f'<bsdf type="diffuse">{bitmap("reflectance", tex, uv_scale)}</bsdf>'
    return f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb}"/></bsdf>'


def bitmap(name, tex, uv_scale=None):
    uv = ""
    if uv_scale:
        uv = f'<transform name="to_uv"><scale x="{uv_scale[0]:g}" y="{uv_scale[1]:g}"/></transform>'
    return f'<texture type="bitmap" name="{name}"><string name="filename" value="{tex}"/>{uv}</texture>'


def roughplastic(alpha, rgb=None, tex=None, uv_scale=None):
    refl = bitmap("diffuse_reflectance", tex, uv_scale) if tex else f'<rgb name="diffuse_reflectance" value="{rgb}"/>'
    return (f'<bsdf type="roughplastic"><string name="distribution" value="ggx"/><float name="alpha" value="{alpha:g}"/>'
            f'<float name="int_ior" value="1.5"/><float name="ext_ior" value="1.0"/>{refl}</bsdf>')


def roughconductor(material, alpha):
    return (f'<bsdf type="roughconductor"><string name="material" value="{material}"/>'
            f'<string name="distribution" value="ggx"/><float name="alpha" value="{alpha:g}"/></bsdf>')


GLASS = '<bsdf type="dielectric"><float name="int_ior" value="1.5"/><float name="ext_ior" value="1.0"/></bsdf>'
WATER = '<bsdf type="dielectric"><float name="int_ior" value="1.33"/><float name="ext_ior" value="1.0"/></bsdf>'


def write_scene(d, text):
    with open(out(d, "scene.xml"), "w") as f:
        f.write(text + "</scene>\n")


# ----------------------------------------------------------------------------- textures

def planks(n, seed):
    """Wooden floor boards: 8 boards across, staggered joints, grain along the board."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:n, 0:n]
    bw = n // 8
    board = x // bw
    off = rng.integers(0, n, 8)[board]
    along = (y + off) % n
    joint = (along % (n // 2)) < 2
    gap = (x % bw) < 2
    grain = value_noise(n, n, 4, seed + 1, 5)
    streak = 0.5 + 0.5 * np.sin((x % bw) * 0.35 + 6 * grain + board * 1.7)
    tint = rng.uniform(0.8, 1.15, 8)[board]
    base = np.array([0.55, 0.36, 0.2])
    img = base * (tint * (0.8 + 0.25 * streak + 0.15 * grain))[..., None]
    img = np.where((joint | gap)[..., None], base * 0.35, img)
    return img


def tiles(h, w, ty, tx, colour, grout, seed, stagger=False, jitter=0.12):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    th, tw = h // ty, w // tx
    row = y // th
    xs = x + ((row % 2) * (tw // 2) if stagger else 0)
    col = (xs // tw) % tx
    g = ((y % th) < 3) | ((xs % tw) < 3)
    tint = rng.uniform(1 - jitter, 1 + jitter, (ty, tx))[row, col]
    noise = value_noise(h, w, 8, seed + 1)
    img = np.asarray(colour) * (tint * (0.92 + 0.16 * noise))[..., None]
    return np.where(g[..., None], np.asarray(grout), img)


# ============================================================================= living room

def living_room():
    d = "living-room"
    # textures
    write_ldr(out(d, "floor_planks.jpg"), to_u8(np.clip(planks(1024, 101), 0, 1)), quality=88)
    n = 256
    y, x = np.mgrid[0:n, 0:n]
    stripes = 0.5 + 0.5 * np.cos(2 * np.pi * x / 64)
    wall = np.array([0.78, 0.74, 0.64]) * (0.9 + 0.1 * stripes)[..., None] * (0.95 + 0.1 * value_noise(n, n, 8, 103))[..., None]
    write_ldr(out(d, "wallpaper.png"), to_u8(wall))
    # rug: bordered geometric pattern
    h, w = 256, 512
    y, x = np.mgrid[0:h, 0:w]
    u, v = x / w, y / h
    border = (np.minimum(np.minimum(u, 1 - u) * 2, np.minimum(v, 1 - v)) < 0.08)
    diamond = (np.abs(((u * 6) % 1) - 0.5) + np.abs(((v * 3) % 1) - 0.5)) < 0.3
    rug = np.where(border[..., None], [0.55, 0.12, 0.1], np.where(diamond[..., None], [0.8, 0.65, 0.35], [0.15, 0.22, 0.4]))
    rug = rug * (0.85 + 0.3 * value_noise(h, w, 32, 104))[..., None]
    write_ldr(out(d, "rug.png"), to_u8(rug))
    # painting: abstract blobs
    h, w = 192, 256
    p = np.stack([value_noise(h, w, 3, 105 + k, 3) for k in range(3)], -1)
    p = np.clip((p - 0.3) * 2.2, 0, 1) * [0.9, 0.6, 0.4] + [0.05, 0.08, 0.15]
    write_ldr(out(d, "painting.png"), to_u8(np.clip(p, 0, 1)))
    # fabric for the sofa
    n = 128
    y, x = np.mgrid[0:n, 0:n]
    weave = 0.5 + 0.25 * np.sin(x * np.pi / 2) * np.sin(y * np.pi / 2)
    fab = np.array([0.35, 0.45, 0.38]) * (0.8 + 0.4 * weave * value_noise(n, n, 8, 106))[..., None]
    write_ldr(out(d, "fabric.png"), to_u8(fab))
    # sky: sun 38 degrees up, shining in through the +x window (from +x, slightly from +z)
    el, az = np.radians(27), np.radians(12)
    sun = (np.cos(el) * np.cos(az), np.sin(el), np.cos(el) * np.sin(az))
    env = sky(512, 256, sun, 6.0, (280.0, 254.0, 219.0), zenith=np.array([0.18, 0.32, 0.7]),
              horizon=np.array([0.75, 0.8, 0.9]), ground=np.array([0.22, 0.2, 0.16]), glow=1.5)
    write_float(out(d, "sky.hdr"), env)

    # meshes: shaggy rug (displaced grid, 72k triangles), glass vase, two glass tumblers
    pile = value_noise(512, 512, 64, 107, 3)

    def rug_h(X, Z):
        u = ((X + 1.6) / 3.2 * 511).astype(int).clip(0, 511)
        v = ((Z + 2.2) / 2.0 * 511).astype(int).clip(0, 511)
        edge = np.minimum(np.minimum(X + 1.6, 1.6 - X), np.minimum(Z + 2.2, -0.2 - Z))
        return 0.004 + 0.012 * pile[v, u] * np.clip(edge / 0.05, 0, 1)
    V, N, UV, F = height_field(-1.6, 1.6, -2.2, -0.2, 240, 150, rug_h)
    tri_rug = ser(out(d, "rug.serialized"), "rug", V, F, N, UV)
    vase = revolve(glass_profile(0.09, 0.32, 0.008, 0.02, n=140, belly=0.45), 192)
    cup1 = revolve(glass_profile(0.04, 0.11, 0.004, 0.012, n=90), 128)
    cup2 = revolve(glass_profile(0.038, 0.1, 0.004, 0.012, n=90), 128)
    top = 0.46
    V, N, F = merge([transformed(vase[0], vase[1], 1, (1.05, top, -0.95)) + (vase[2],),
                     transformed(cup1[0], cup1[1], 1, (1.35, top, -0.6)) + (cup1[2],),
                     transformed(cup2[0], cup2[1], 1, (0.75, top, -0.55)) + (cup2[2],)])
    tri_glass = ser(out(d, "glass.serialized"), "glassware", V, F, N)

    x = header("Mitsuba 3 oracle scene (make-realistic.py). A living room lit mostly indirectly: an RGBE "
               "sky with a hazy sun (6 degrees, 27 degrees up) shines through an open window in the +x wall onto a textured "
               "plank floor, a displaced rug (%d triangles) and a coffee table carrying a glass vase and two "
               "tumblers (%d triangles) that cast caustics; wallpaper, a painting, a fabric sofa, a rough "
               "aluminium lamp." % (tri_rug, tri_glass),
               (-1.7, 1.35, 1.5), (0.9, 0.55, -1.0), 64)
    x += '    <emitter type="envmap"><string name="filename" value="sky.hdr"/></emitter>\n\n'
    x += '    <bsdf type="diffuse" id="ceiling"><rgb name="reflectance" value="0.8, 0.8, 0.78"/></bsdf>\n'
    x += f'    <bsdf type="diffuse" id="wall">{bitmap("reflectance", "wallpaper.png", (3, 2))}</bsdf>\n'
    floor = roughplastic(0.25, tex="floor_planks.jpg", uv_scale=(2, 2)).replace("<bsdf ", '<bsdf id="floor" ', 1)
    x += f"    {floor}\n\n"
    # room x, z in [-3, 3], y in [0, 2.6]
    x += rect((0, 0, 0), "+y", 3, 3, '<ref id="floor"/>', "floor, planks")
    x += rect((0, 2.6, 0), "-y", 3, 3, '<ref id="ceiling"/>', "ceiling")
    x += rect((0, 1.3, -3), "+z", 3, 1.3, '<ref id="wall"/>', "back wall")
    x += rect((0, 1.3, 3), "-z", 3, 1.3, '<ref id="wall"/>', "front wall (behind the camera)")
    x += rect((-3, 1.3, 0), "+x", 3, 1.3, '<ref id="wall"/>', "left wall")
    # +x wall with a window z in [-2.2, 0.4], y in [0.7, 2.3]
    x += rect((3, 0.35, 0), "-x", 3, 0.35, '<ref id="wall"/>', "window wall: below the sill")
    x += rect((3, 2.45, 0), "-x", 3, 0.15, '<ref id="wall"/>', "above the window")
    x += rect((3, 1.5, -2.6), "-x", 0.4, 0.8, '<ref id="wall"/>', "beside the window (back)")
    x += rect((3, 1.5, 1.7), "-x", 1.3, 0.8, '<ref id="wall"/>', "beside the window (front)")
    x += cube((3, 0.66, -2.25), (3.12, 0.7, 0.45), diffuse("0.85, 0.85, 0.82"), "window sill")
    x += mesh("rug.serialized", diffuse(tex="rug.png"), "shaggy rug: height field, uv over the rug")
    # coffee table: wooden top and legs
    x += cube((0.55, top - 0.04, -1.35), (1.65, top, -0.25), roughplastic(0.12, "0.32, 0.18, 0.09"), "coffee table top")
    for lx in (0.6, 1.6):
        for lz in (-1.3, -0.3):
            x += cube((lx - 0.03, 0, lz - 0.03), (lx + 0.03, top - 0.04, lz + 0.03), diffuse("0.25, 0.14, 0.07"))
    x += mesh("glass.serialized", GLASS, "glass vase and two tumblers (hollow, walls 8 and 4 mm)")
    # sofa against the back wall
    sofa = diffuse(tex="fabric.png", uv_scale=(3, 3))
    x += cube((-1.9, 0.1, -2.95), (1.1, 0.45, -2.1), sofa, "sofa seat")
    x += cube((-1.9, 0.45, -2.95), (1.1, 1.0, -2.7), sofa, "sofa back")
    x += cube((-2.2, 0.1, -2.95), (-1.9, 0.7, -2.1), sofa, "sofa arms")
    x += cube((1.1, 0.1, -2.95), (1.4, 0.7, -2.1), sofa)
    x += cube((-2.2, 0, -2.9), (1.4, 0.1, -2.15), diffuse("0.1, 0.08, 0.06"))
    # painting on the left wall (texture upright: to_uv scale (1, -1))
    x += rect((-2.99, 1.55, -0.8), "+x", 0.6, 0.45,
              f'<bsdf type="diffuse">{bitmap("reflectance", "painting.png", (1, -1))}</bsdf>', "painting")
    # floor lamp, rough aluminium, and a rough-copper bowl on the table
    x += cube((-2.55, 0, -2.55), (-2.35, 0.03, -2.35), roughconductor("Al", 0.2), "floor lamp: base, pole, shade")
    x += cube((-2.47, 0.03, -2.47), (-2.43, 1.5, -2.43), roughconductor("Al", 0.2))
    x += f'    <shape type="sphere"><point name="center" value="-2.45, 1.6, -2.45"/><float name="radius" value="0.16"/>{roughconductor("Al", 0.08)}</shape>\n'
    x += f'    <shape type="sphere"><point name="center" value="0.8, {top + 0.0:g}, -1.1"/><float name="radius" value="0.1"/>{roughconductor("Cu", 0.15)}</shape>\n'
    write_scene(d, x)
    return tri_rug + tri_glass


# ============================================================================= pool

def pool():
    d = "pool"
    write_ldr(out(d, "pool_tiles.png"), to_u8(tiles(256, 256, 8, 8, [0.35, 0.62, 0.78], [0.85, 0.88, 0.9], 201)))
    n = 512
    stone = value_noise(n, n, 6, 202, 5)
    deck = tiles(n, n, 4, 4, [0.72, 0.66, 0.56], [0.4, 0.38, 0.35], 203, stagger=True, jitter=0.08)
    deck = deck * (0.85 + 0.3 * stone)[..., None]
    write_ldr(out(d, "deck_stone.jpg"), to_u8(np.clip(deck, 0, 1)), quality=88)
    # lane stripe on the pool floor: dark tiles in a band
    el, az = np.radians(55), np.radians(-30)
    sun = (np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az))
    env = sky(512, 256, sun, 5.0, (160.0, 150.0, 130.0), zenith=np.array([0.2, 0.38, 0.85]),
              horizon=np.array([0.8, 0.85, 0.95]), ground=np.array([0.25, 0.23, 0.2]), glow=1.0)
    write_float(out(d, "sky.hdr"), env)

    # water: height field of a few travelling waves, 330 x 170 cells (112 200 triangles)
    rng = np.random.default_rng(204)
    waves = [(rng.uniform(0, 2 * np.pi), rng.uniform(1.5, 5.0), rng.uniform(0, 2 * np.pi), rng.uniform(0.004, 0.012))
             for _ in range(9)]

    def water(X, Z):
        y = np.full_like(X, -0.12)
        for theta, k, ph, amp in waves:
            y += amp * np.sin(k * (np.cos(theta) * X + np.sin(theta) * Z) + ph)
        return y
    V, N, UV, F = height_field(-2.0, 2.0, -4.0, 4.0, 170, 330, water)
    tri = ser(out(d, "water.serialized"), "water", V, F, N)

    # a rough stainless ladder rail pair (lathe tubes bent by hand: straight tubes here)
    x = header("Mitsuba 3 oracle scene (make-realistic.py). An outdoor pool: a dielectric water surface "
               "(eta 1.33, a height field of %d triangles with vertex normals) over a tiled basin (PNG "
               "tiles, repeat), a stone deck (JPEG); lit by an RGBE (.hdr) sky whose sun (5 degrees) "
               "throws caustics on the basin floor, seen through the water. Shadow rays are blocked by "
               "the water, so the caustics are found only by BSDF sampling in PT." % tri,
               (0.6, 2.3, 5.6), (-0.1, -0.9, -0.6), 60)
    x += '    <emitter type="envmap"><string name="filename" value="sky.hdr"/></emitter>\n\n'
    x += f'    <bsdf type="diffuse" id="tiles">{bitmap("reflectance", "pool_tiles.png", (4, 4))}</bsdf>\n'
    x += f'    <bsdf type="diffuse" id="tiles_wall">{bitmap("reflectance", "pool_tiles.png", (8, 1.2))}</bsdf>\n'
    x += f'    <bsdf type="diffuse" id="deck">{bitmap("reflectance", "deck_stone.jpg", (3, 3))}</bsdf>\n\n'
    # basin x in [-2, 2], z in [-4, 4], y in [-1.4, 0]
    x += rect((0, -1.4, 0), "+y", 2, 4, '<ref id="tiles"/>', "basin floor")
    x += rect((0, -0.7, -4), "+z", 2, 0.7, '<ref id="tiles_wall"/>', "basin walls")
    x += rect((0, -0.7, 4), "-z", 2, 0.7, '<ref id="tiles_wall"/>')
    x += rect((-2, -0.7, 0), "+x", 4, 0.7, '<ref id="tiles_wall"/>')
    x += rect((2, -0.7, 0), "-x", 4, 0.7, '<ref id="tiles_wall"/>')
    # a dark lane stripe along the floor
    x += rect((0, -1.399, 0), "+y", 0.12, 3.4, diffuse("0.05, 0.08, 0.18"), "lane stripe")
    # deck y = 0 around the basin, out to x in [-8, 8], z in [-10, 8]
    x += rect((-5, 0, -1), "+y", 3, 9, '<ref id="deck"/>', "deck")
    x += rect((5, 0, -1), "+y", 3, 9, '<ref id="deck"/>')
    x += rect((0, 0, -7), "+y", 2, 3, '<ref id="deck"/>')
    x += rect((0, 0, 6), "+y", 2, 2, '<ref id="deck"/>')
    x += mesh("water.serialized", WATER, "water surface (open sheet, normals up)")
    # ladder: two rough steel rails and rungs in the water
    for rx in (-1.1, -0.6):
        x += cube((rx - 0.02, -1.0, -3.95), (rx + 0.02, 0.9, -3.91), roughconductor("Cr", 0.12))
    for ry in (-0.9, -0.55, -0.2):
        x += cube((-1.1, ry - 0.015, -3.95), (-0.6, ry + 0.015, -3.91), roughconductor("Cr", 0.12))
    # a white wall behind the pool and a beach ball
    x += rect((0, 1.5, -10), "+z", 8, 1.5, roughplastic(0.3, "0.85, 0.82, 0.76"), "garden wall")
    x += f'    <shape type="sphere"><point name="center" value="2.8, 0.3, 1.2"/><float name="radius" value="0.3"/>{roughplastic(0.1, "0.8, 0.15, 0.1")}</shape>\n'
    write_scene(d, x)
    return tri


# ============================================================================= kitchen

def kitchen():
    d = "kitchen"
    # subway tiles (JPEG), marble-ish counter (PNG), wood cabinets (JPEG)
    write_ldr(out(d, "backsplash.jpg"), to_u8(tiles(256, 256, 8, 4, [0.86, 0.86, 0.82], [0.45, 0.45, 0.44], 301,
                                                    stagger=True, jitter=0.05)), quality=90)
    n = 512
    veins = value_noise(n, n, 4, 302, 6)
    marble = 0.5 + 0.5 * np.sin(12 * veins + np.linspace(0, 8, n)[None, :])
    counter = np.array([0.72, 0.7, 0.68]) * (0.75 + 0.25 * marble ** 6)[..., None] + 0.1 * (1 - marble[..., None] ** 0.2)
    write_ldr(out(d, "counter.png"), to_u8(np.clip(counter, 0, 1)))
    wood = planks(512, 303)[:, :, [0, 1, 2]] * 0.9
    write_ldr(out(d, "cabinet_wood.jpg"), to_u8(np.clip(wood, 0, 1)), quality=88)

    top = 0.9
    # glasses: 5 tumblers / wine-glass-like beakers, 256 segments; two pots and a kettle (lathe)
    parts = []
    rng = np.random.default_rng(304)
    for k, gx in enumerate((-0.55, -0.38, 0.55)):
        r, h = rng.uniform(0.035, 0.045), rng.uniform(0.1, 0.16)
        V, N, F = revolve(glass_profile(r, h, 0.003, 0.01, n=100, belly=rng.uniform(-0.1, 0.2)), 192)
        parts.append((V + [gx, top, -0.25 + 0.08 * (k % 2)], N, F))
    V, N, F = merge(parts)
    tri_glass = ser(out(d, "glasses.serialized"), "glasses", V, F, N)
    pot = revolve(glass_profile(0.13, 0.16, 0.004, 0.006, n=80), 160)
    pan = revolve(glass_profile(0.1, 0.11, 0.004, 0.006, n=80), 160)
    V, N, F = merge([(pot[0] + [-0.05, top, -0.4], pot[1], pot[2]), (pan[0] + [0.3, top, -0.33], pan[1], pan[2])])
    tri_pots = ser(out(d, "pots.serialized"), "pots", V, F, N)
    kettle_prof = chaikin(np.array([(0, 0), (0.09, 0), (0.11, 0.06), (0.1, 0.14), (0.05, 0.19), (0.02, 0.2),
                                    (0.02, 0.23), (0, 0.23)]), 3)
    kettle = revolve(resample(kettle_prof, 80), 160)
    tri_kettle = ser(out(d, "kettle.serialized"), "kettle", kettle[0] + [0.85, top, -0.4], kettle[2], kettle[1])

    x = header("Mitsuba 3 oracle scene (make-realistic.py). A kitchen counter under a wall cabinet lit by "
               "ten small under-cabinet area lights and three small spherical bulbs; rough copper and "
               "aluminium pots and a rough chrome kettle (glossy interreflection), five hollow glasses "
               "(%d triangles) casting caustics on a textured rough-plastic counter; JPEG subway tiles, "
               "wooden cabinet doors." % tri_glass,
               (0.05, 1.32, 0.95), (-0.05, 0.95, -0.4), 72)
    x += '    <bsdf type="diffuse" id="paint"><rgb name="reflectance" value="0.7, 0.68, 0.62"/></bsdf>\n'
    x += f'    <bsdf type="diffuse" id="wood">{bitmap("reflectance", "cabinet_wood.jpg", (1, 1))}</bsdf>\n'
    x += ('    <bsdf type="diffuse" id="lamp_back"><rgb name="reflectance" value="0"/></bsdf>\n\n')
    # room x in [-2, 2], z in [-0.7, 3], y in [0, 2.5]
    x += rect((0, 0, 1.15), "+y", 2, 1.85, diffuse("0.35, 0.3, 0.26"), "floor")
    x += rect((0, 2.5, 1.15), "-y", 2, 1.85, '<ref id="paint"/>', "ceiling")
    x += rect((-2, 1.25, 1.15), "+x", 1.85, 1.25, '<ref id="paint"/>', "side walls")
    x += rect((2, 1.25, 1.15), "-x", 1.85, 1.25, '<ref id="paint"/>')
    x += rect((0, 1.25, 3), "-z", 2, 1.25, '<ref id="paint"/>', "wall behind the camera")
    x += rect((0, 0.45, -0.7), "+z", 2, 0.45, '<ref id="paint"/>', "back wall below the counter")
    x += rect((0, 1.2, -0.7), "+z", 2, 0.3, roughplastic(0.2, tex="backsplash.jpg", uv_scale=(4, -1)),
              "backsplash: subway tiles, roughplastic")
    x += rect((0, 2.45, -0.7), "+z", 2, 0.05, '<ref id="paint"/>')
    # counter: cabinet body below, textured top
    x += cube((-2, 0.05, -0.7), (2, top - 0.04, -0.05), '<ref id="wood"/>', "base cabinets")
    x += cube((-2, top - 0.04, -0.7), (2, top, 0.0),
              roughplastic(0.08, tex="counter.png", uv_scale=(2, 1)), "counter top, marble-like, glossy")
    # wall cabinet y in [1.5, 2.4], z in [-0.7, -0.35]
    x += cube((-2, 1.5, -0.7), (2, 2.4, -0.35), '<ref id="wood"/>', "wall cabinet")
    # ten under-cabinet lights facing down
    for k in range(10):
        lx = -1.8 + 0.4 * k
        x += (f'    <shape type="rectangle"><transform name="to_world"><scale x="0.06" y="0.025" z="1"/>'
              f'{ROT["-y"]}<translate x="{lx:g}" y="1.499" z="-0.5"/></transform>'
              f'<ref id="lamp_back"/><emitter type="area"><rgb name="radiance" value="60, 52, 40"/></emitter></shape>\n')
    # three bulbs on a ceiling rail
    for k, bx in enumerate((-1.0, 0.0, 1.0)):
        x += (f'    <shape type="sphere"><point name="center" value="{bx:g}, 2.2, 0.9"/><float name="radius" value="0.03"/>'
              f'<emitter type="area"><rgb name="radiance" value="90, 80, 65"/></emitter></shape>\n')
    x += cube((-1.3, 2.3, 0.88), (1.3, 2.5, 0.92), roughconductor("Al", 0.3), "bulb rail")
    x += mesh("glasses.serialized", GLASS, "five hollow glasses (walls 3 mm)")
    x += mesh("pots.serialized", roughconductor("Cu", 0.12), "copper pot and pan (rough)")
    x += mesh("kettle.serialized", roughconductor("Cr", 0.05), "chrome kettle")
    x += cube((-1.75, top, -0.6), (-1.25, top + 0.03, -0.3), roughplastic(0.3, "0.6, 0.42, 0.25"), "cutting board")
    x += f'    <shape type="sphere"><point name="center" value="-1.45, {top + 0.03 + 0.05:g}, -0.45"/><float name="radius" value="0.05"/>{roughplastic(0.15, "0.75, 0.55, 0.05")}</shape>\n'
    write_scene(d, x)
    return tri_glass + tri_pots + tri_kettle


if __name__ == "__main__":
    for f in (living_room, pool, kitchen):
        print(f.__name__, f(), "triangles")
