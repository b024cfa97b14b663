#!/usr/bin/env python3
"""Generate every asset (textures, environment maps, meshes, spectra) of the scenes added on
branch `new-scenes`. Deterministic: re-running it rewrites byte-identical files (fixed seeds).

    /work/venv/bin/python scenes/make-assets.py            # from the repository root

Writers: Mitsuba's `mi.Bitmap` for PNG (8/16 bit), JPEG, OpenEXR and Radiance RGBE; plain
numpy/struct for what Mitsuba reads but cannot write (BMP, TGA), and in scene_meshes.py for
PLY/OBJ meshes and the `serialized` mesh container (format as in
docs/mitsuba-scene-language.md section 5).

Conventions the pictures rely on (Mitsuba 3.9.1): texture v = 0 is the *top* image row; envmap
u = 0 looks along -z, u = 1/4 along +x, v = 0 is +y (rows corner-aligned: v = row/(H-1)).
"""
import os
import struct

import numpy as np
import mitsuba as mi

mi.set_variant("scalar_rgb")

ROOT = os.path.dirname(os.path.abspath(__file__))


def out(*parts):
    p = os.path.join(ROOT, *parts)
    os.makedirs(os.path.dirname(p), exist_ok=True)
    return p


# ----------------------------------------------------------------------------- image helpers

def to_u8(a):
    """[0,1] float (already in the file's encoding) -> uint8."""
    return np.clip(np.round(np.asarray(a) * 255.0), 0, 255).astype(np.uint8)


def to_u16(a):
    return np.clip(np.round(np.asarray(a) * 65535.0), 0, 65535).astype(np.uint16)


def write_ldr(path, a, quality=-1):
    """8- or 16-bit PNG / JPEG through mi.Bitmap (marked sRGB; Mitsuba decodes them as sRGB)."""
    fmt = mi.Bitmap.PixelFormat.Y if a.ndim == 2 else mi.Bitmap.PixelFormat.RGB
    b = mi.Bitmap(np.ascontiguousarray(a), fmt)
    b.set_srgb_gamma(True)
    b.write(path, quality=quality)


def write_float(path, a):
    """Linear float32 RGB: OpenEXR (.exr) or Radiance RGBE (.hdr)."""
    b = mi.Bitmap(np.ascontiguousarray(a.astype(np.float32)), mi.Bitmap.PixelFormat.RGB)
    b.write(path)


def write_bmp(path, rgb):
    """24-bit uncompressed Windows BMP (BITMAPINFOHEADER, rows bottom-up, BGR, 4-byte padding)."""
    h, w, _ = rgb.shape
    row = w * 3
    pad = (4 - row % 4) % 4
    data = b"".join(rgb[y, :, ::-1].tobytes() + b"\0" * pad for y in range(h - 1, -1, -1))
    header = struct.pack("<2sIHHI", b"BM", 14 + 40 + len(data), 0, 0, 14 + 40)
    info = struct.pack("<IiiHHIIiiII", 40, w, h, 1, 24, 0, len(data), 2835, 2835, 0, 0)
    with open(path, "wb") as f:
        f.write(header + info + data)


def write_tga(path, rgb):
    """Uncompressed true-colour TGA 2.0 (type 2), 24 bit BGR, top-left origin (descriptor 0x20)."""
    h, w, _ = rgb.shape
    header = struct.pack("<BBBHHBHHHHBB", 0, 0, 2, 0, 0, 0, 0, 0, w, h, 24, 0x20)
    with open(path, "wb") as f:
        # TGA 2.0 footer: Mitsuba detects TGA files only by this signature (not by extension)
        footer = struct.pack("<II", 0, 0) + b"TRUEVISION-XFILE.\0"
        f.write(header + np.ascontiguousarray(rgb[:, :, ::-1]).tobytes() + footer)


def value_noise(h, w, cells, seed, octaves=4):
    """Smooth periodic noise in [0,1] (bilinear value noise, octaves halve in amplitude)."""
    rng = np.random.default_rng(seed)
    acc = np.zeros((h, w))
    amp, tot = 1.0, 0.0
    for o in range(octaves):
        c = cells * 2 ** o
        g = rng.random((c, c))
        y = (np.arange(h) + 0.5) / h * c
        x = (np.arange(w) + 0.5) / w * c
        y0 = np.floor(y).astype(int)
        x0 = np.floor(x).astype(int)
        fy = (y - y0)[:, None]
        fx = (x - x0)[None, :]
        fy = fy * fy * (3 - 2 * fy)
        fx = fx * fx * (3 - 2 * fx)
        a = g[y0 % c][:, x0 % c]
        b = g[y0 % c][:, (x0 + 1) % c]
        cc = g[(y0 + 1) % c][:, x0 % c]
        d = g[(y0 + 1) % c][:, (x0 + 1) % c]
        acc += amp * ((a * (1 - fx) + b * fx) * (1 - fy) + (cc * (1 - fx) + d * fx) * fy)
        tot += amp
        amp *= 0.5
    return acc / tot


def latlong_dirs(w, h):
    """World directions of Mitsuba's envmap texels: u = (i+1/2)/W, v = j/(H-1)."""
    u = (np.arange(w) + 0.5) / w
    v = np.arange(h) / (h - 1)
    U, V = np.meshgrid(u, v)
    s = np.sin(np.pi * V)
    return np.stack([np.sin(2 * np.pi * U) * s, np.cos(np.pi * V), -np.cos(2 * np.pi * U) * s], -1)


def sky(w, h, sun_dir, sun_radius_deg, sun_rgb, zenith, horizon, ground, glow=0.0):
    d = latlong_dirs(w, h)
    y = d[..., 1]
    t = np.clip(y, 0, 1)[..., None] ** 0.6
    img = np.where(y[..., None] >= 0, horizon * (1 - t) + zenith * t, ground)
    sd = np.asarray(sun_dir, float)
    sd /= np.linalg.norm(sd)
    ang = np.degrees(np.arccos(np.clip(d @ sd, -1, 1)))
    core = np.clip((sun_radius_deg + 0.7 - ang) / 1.4, 0, 1)  # ~1.4 degree soft edge
    img = img + core[..., None] * np.asarray(sun_rgb)
    if glow:
        img = img + glow * np.exp(-ang / 12.0)[..., None] * np.asarray(sun_rgb) / max(sun_rgb)
    return img.astype(np.float32)


# mesh writers and generated meshes live beside this file (make-realistic.py uses them through this module)
from scene_meshes import (  # noqa: F401
    write_obj,
    write_ply,
    serialized_block,
    write_serialized,
    grid_faces,
    icosphere,
    vertex_normals,
    lathe,
    box,
)


# ============================================================================= scenes

def textured_room():
    d = "textured-room"
    rng = np.random.default_rng(11)
    # floor: 2x2 terracotta / cream tiles with grout, 128x128 8-bit RGB PNG (repeated by to_uv)
    n = 128
    y, x = np.mgrid[0:n, 0:n]
    tile = ((x // 64) + (y // 64)) % 2
    grout = ((x % 64) < 3) | ((y % 64) < 3)
    noise = value_noise(n, n, 8, 1)
    c0 = np.array([0.78, 0.42, 0.28])
    c1 = np.array([0.86, 0.80, 0.66])
    img = np.where(tile[..., None] == 0, c0, c1) * (0.85 + 0.3 * noise)[..., None]
    img = np.where(grout[..., None], np.array([0.35, 0.33, 0.3]), img)
    write_ldr(out(d, "floor_tiles.png"), to_u8(img))
    # wall: bricks, 256x128 JPEG
    h, w = 128, 256
    y, x = np.mgrid[0:h, 0:w]
    row = y // 16
    xs = x + (row % 2) * 16
    col = xs // 32
    mortar = ((y % 16) < 2) | ((xs % 32) < 2)
    tint = rng.uniform(0.75, 1.1, size=(8, 9))[row, col % 9]
    noise = value_noise(h, w, 16, 2)
    brick = np.array([0.62, 0.28, 0.2]) * (tint * (0.85 + 0.3 * noise))[..., None]
    img = np.where(mortar[..., None], np.array([0.72, 0.7, 0.66]), brick)
    write_ldr(out(d, "wall_bricks.jpg"), to_u8(img), quality=90)
    # sky: Radiance RGBE, 256x128, sun 30 degrees up along the map's +z (u = 1/2)
    sun = (0.0, np.sin(np.radians(30)), np.cos(np.radians(30)))
    env = sky(256, 128, sun, 3.0, (1500.0, 1400.0, 1250.0),
              zenith=np.array([0.25, 0.42, 0.85]), horizon=np.array([0.95, 0.95, 1.0]),
              ground=np.array([0.28, 0.25, 0.2]), glow=2.0)
    write_float(out(d, "sky.hdr"), env)


CORNELL_GREEN = (
    "400:0.092, 404:0.096, 408:0.098, 412:0.097, 416:0.098, 420:0.095, 424:0.095, 428:0.097, 432:0.095, "
    "436:0.094, 440:0.097, 444:0.098, 448:0.096, 452:0.101, 456:0.103, 460:0.104, 464:0.107, 468:0.109, "
    "472:0.112, 476:0.115, 480:0.125, 484:0.14, 488:0.16, 492:0.187, 496:0.229, 500:0.285, 504:0.343, "
    "508:0.39, 512:0.435, 516:0.464, 520:0.472, 524:0.476, 528:0.481, 532:0.462, 536:0.447, 540:0.441, "
    "544:0.426, 548:0.406, 552:0.373, 556:0.347, 560:0.337, 564:0.314, 568:0.285, 572:0.277, 576:0.266, "
    "580:0.25, 584:0.23, 588:0.207, 592:0.186, 596:0.171, 600:0.16, 604:0.148, 608:0.141, 612:0.136, "
    "616:0.13, 620:0.126, 624:0.123, 628:0.121, 632:0.122, 636:0.119, 640:0.114, 644:0.115, 648:0.117, "
    "652:0.117, 656:0.118, 660:0.12, 664:0.122, 668:0.128, 672:0.132, 676:0.139, 680:0.144, 684:0.146, "
    "688:0.15, 692:0.152, 696:0.157, 700:0.159")


def spectral_cornell():
    d = "spectral-cornell"
    lines = ["# Cornell box green wall, measured diffuse reflectance (classic Cornell box data)",
             "# wavelength [nm]   reflectance"]
    for tok in CORNELL_GREEN.split(","):
        lam, v = tok.strip().split(":")
        lines.append(f"{lam} {v}")
    with open(out(d, "green.spd"), "w") as f:
        f.write("\n".join(lines) + "\n")


def spectral_emitters():
    d = "spectral-emitters"
    # warm (incandescent-like) emission spectrum for the spot's intensity, 380-780 nm every 20 nm
    lam = np.arange(380, 781, 20)
    v = 40.0 * (lam / 780.0) ** 5 / (np.exp(1.6 * (lam / 560.0) - 1.6) + 0.0) ** 0.5
    lines = ["# warm spot light intensity [W/sr per unit spectral weight], smooth ramp",
             "# wavelength [nm]   value"]
    lines += [f"{l:d} {x:.4f}" for l, x in zip(lam, v)]
    with open(out(d, "warm.spd"), "w") as f:
        f.write("\n".join(lines) + "\n")


def included_scene():
    d = "included-scene"
    # vase (OBJ, smooth normals from the file), in parts/ -- referenced from parts/sub/ by the bare
    # name "vase.obj", found through the scene's <path value="parts"/>
    t = np.linspace(0, 1, 25)
    r = 0.16 + 0.11 * np.sin(np.pi * (0.15 + 0.85 * t)) ** 2 - 0.05 * t + 0.035 * np.exp(-((t - 0.93) / 0.05) ** 2)
    prof = np.column_stack([r, 0.9 * t])
    prof = np.vstack([[0.001, 0.0], prof])          # closed bottom
    V, F = lathe(prof, 48)
    N = vertex_normals(V, F)
    write_obj(out(d, "parts", "vase.obj"), [("vase", "glaze", V, N, None, F)], "vase, lathe of 26 rings x 48")
    # pedestal (binary PLY, flat octagonal prism)
    k = 8
    a = np.arange(k) * 2 * np.pi / k + np.pi / k
    ring = np.column_stack([0.42 * np.cos(a), np.zeros(k), 0.42 * np.sin(a)])
    Vb, Vt = ring.copy(), ring + [0, 0.35, 0]
    V = np.vstack([Vb, Vt, [[0, 0, 0], [0, 0.35, 0]]])
    F = []
    for i in range(k):
        j = (i + 1) % k
        F += [(i, j, k + j), (i, k + j, k + i)]          # sides
        F += [(2 * k + 1, k + j, k + i)]                # top
        F += [(2 * k, i, j)]                            # bottom
    V, F = np.array(V), np.array(F)
    # orient every face outward (centroid test)
    c = V.mean(0)
    for i, f in enumerate(F):
        p = V[f]
        nrm = np.cross(p[1] - p[0], p[2] - p[0])
        if np.dot(nrm, p.mean(0) - c) < 0:
            F[i] = f[[0, 2, 1]]
    write_ply(out(d, "parts", "pedestal.ply"), V, F, comment="octagonal pedestal")
    # wood texture for the floor, referenced as "sub/wood.png" (relative to parts/)
    h, w = 128, 128
    y, x = np.mgrid[0:h, 0:w]
    n1 = value_noise(h, w, 4, 21)
    rings = 0.5 + 0.5 * np.sin((x / w * 10 + 3 * n1) * 2 * np.pi)
    plank = (y // 32) % 2
    base = np.array([0.55, 0.36, 0.2]) * (0.8 + 0.25 * rings)[..., None]
    base *= np.where(plank[..., None] == 1, 0.9, 1.05)
    base = np.where(((y % 32) < 1)[..., None], 0.25, base)
    write_ldr(out(d, "parts", "sub", "wood.png"), to_u8(base))


def legacy_v06():
    d = "legacy-v06"
    n = 64
    y, x = np.mgrid[0:n, 0:n]
    # parquet: 4x4 blocks of 3 strips, alternating direction
    bx, by = x // 16, y // 16
    horiz = (bx + by) % 2 == 0
    strip = np.where(horiz, (y % 16) // 5, (x % 16) // 5)
    noise = value_noise(n, n, 8, 31)
    shade = 0.8 + 0.12 * ((strip * 7 + bx * 3 + by * 5) % 4) / 3 + 0.15 * noise
    img = np.array([0.7, 0.48, 0.28]) * shade[..., None]
    gap = np.where(horiz, (y % 16) % 5 == 4, (x % 16) % 5 == 4) | (x % 16 == 15) | (y % 16 == 15)
    img = np.where(gap[..., None], np.array([0.3, 0.2, 0.12]), img)
    write_ldr(out(d, "parquet.png"), to_u8(img))


def serialized_uv():
    d = "serialized-uv"
    # mesh 0: torus, float32 positions/normals/uvs; u in [0, 2] so `mirror` wrapping shows
    nu, nv, R, r = 48, 24, 0.6, 0.25
    i, j = np.meshgrid(np.arange(nu + 1), np.arange(nv + 1))
    phi = 2 * np.pi * i / nu
    th = 2 * np.pi * j / nv
    cx, cz = np.cos(phi), -np.sin(phi)
    V0 = np.stack([(R + r * np.cos(th)) * cx, r * np.sin(th), (R + r * np.cos(th)) * cz], -1).reshape(-1, 3)
    N0 = np.stack([np.cos(th) * cx, np.sin(th), np.cos(th) * cz], -1).reshape(-1, 3)
    UV0 = np.stack([2.0 * i / nu, j / nv], -1).reshape(-1, 2)
    F0 = grid_faces(nu, nv)
    # check orientation: outward normals
    p = V0[F0]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    if np.mean(np.sum(fn * N0[F0[:, 0]], 1)) < 0:
        F0 = F0[:, [0, 2, 1]]
    # mesh 1: gently rolling ground patch, float64 positions + uvs (no normals: Mitsuba computes them)
    n = 24
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1))
    X = -2 + 4.0 * i / n
    Z = -2 + 4.0 * j / n
    Y = 0.06 * np.sin(1.7 * X + 0.5) * np.cos(1.3 * Z) - 0.06
    V1 = np.stack([X, Y, Z], -1).reshape(-1, 3)
    UV1 = np.stack([-0.25 + 1.5 * i / n, -0.25 + 1.5 * j / n], -1).reshape(-1, 2)   # [-0.25, 1.25]: clamp
    F1 = grid_faces(n, n)
    p = V1[F1]
    fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    if np.mean(fn[:, 1]) < 0:
        F1 = F1[:, [0, 2, 1]]
    write_serialized(out(d, "meshes.serialized"), [
        serialized_block("torus", V0, F0, N=N0, UV=UV0, double=False),
        serialized_block("ground", V1, F1, UV=UV1, double=True),
    ])
    # OpenEXR (linear float) marble, 128x128
    h = w = 128
    y, x = np.mgrid[0:h, 0:w]
    nz = value_noise(h, w, 4, 41, octaves=5)
    vein = np.abs(np.sin((x / w * 3 + y / h * 1.5 + 4 * nz) * np.pi)) ** 0.35
    img = np.array([0.72, 0.70, 0.66]) * vein[..., None] + np.array([0.08, 0.12, 0.1]) * (1 - vein)[..., None]
    img[:, :, 0] += 0.06 * (x / w)                  # slight left-right asymmetry (mirror is visible)
    write_float(out(d, "marble.exr"), img)
    # 16-bit PNG, 32x32 pixel-art tiles (nearest filtering keeps the texels crisp)
    n = 32
    y, x = np.mgrid[0:n, 0:n]
    c = ((x // 4) + (y // 4)) % 2
    img = np.where(c[..., None] == 0, np.array([0.20, 0.45, 0.75]), np.array([0.85, 0.82, 0.55]))
    img = np.where(((x // 8 == 1) & (y // 8 == 2))[..., None], np.array([0.9, 0.25, 0.15]), img)
    img = np.where((x == y)[..., None], np.array([0.1, 0.1, 0.1]), img)   # a diagonal: shows orientation
    write_ldr(out(d, "tiles16.png"), to_u16(img))


def checker_conductor():
    d = "checker-conductor"
    # roughness map, single channel, raw values: alpha = value/255 in [0.04, 0.45]
    n = 128
    y, x = np.mgrid[0:n, 0:n]
    rr = np.hypot(x - n / 2 + 0.5, y - n / 2 + 0.5) / (n / 2)
    a = 0.04 + 0.41 * (0.5 + 0.5 * np.cos(rr * 3 * np.pi)) * np.clip(1.2 - rr, 0, 1)
    write_ldr(out(d, "roughness.png"), to_u8(a))
    # crate (BMP, 64x64): planks with a frame
    n = 64
    y, x = np.mgrid[0:n, 0:n]
    nz = value_noise(n, n, 4, 51)
    wood = np.array([0.62, 0.45, 0.25]) * (0.8 + 0.3 * nz)[..., None]
    wood = np.where(((y % 16) < 1)[..., None], np.array([0.3, 0.2, 0.1]), wood)
    frame = (x < 6) | (x >= 58) | (y < 6) | (y >= 58) | (np.abs(x - y) < 4)
    img = np.where(frame[..., None], np.array([0.45, 0.3, 0.15]), wood)
    write_bmp(out(d, "crate.bmp"), to_u8(img))
    # stripes (TGA, 128x64): diagonal blue/white stripes with a red band near the top rows
    h, w = 64, 128
    y, x = np.mgrid[0:h, 0:w]
    s = ((x + y) // 8) % 2
    img = np.where(s[..., None] == 0, np.array([0.15, 0.3, 0.7]), np.array([0.92, 0.92, 0.88]))
    img = np.where((y < 8)[..., None], np.array([0.8, 0.15, 0.1]), img)
    write_tga(out(d, "stripes.tga"), to_u8(img))
    # 8-bit sRGB PNG environment map 256x128 (LDR: brightness comes from the envmap `scale`)
    env = sky(256, 128, (0.5, 0.55, -0.6), 6.0, (1.0, 0.9, 0.7),
              zenith=np.array([0.18, 0.3, 0.6]), horizon=np.array([0.7, 0.75, 0.8]),
              ground=np.array([0.22, 0.2, 0.17]), glow=0.25)
    env = np.clip(env, 0, 1) ** (1 / 2.2)           # encode roughly as sRGB for the 8-bit file
    write_ldr(out(d, "sky.png"), to_u8(env))


def masked_leaves():
    d = "masked-leaves"
    # a twig with five leaves, single channel 8-bit PNG (opacity; 4x4 supersampled edges)
    n, ss = 256, 4
    yy, xx = np.mgrid[0:n * ss, 0:n * ss]
    X = (xx + 0.5) / (n * ss)
    Y = (yy + 0.5) / (n * ss)
    m = np.zeros_like(X, dtype=bool)
    # twig along the diagonal, leaves alternating +-50 degrees from it
    m |= (np.abs(X - Y) < 0.010) & (X > 0.04) & (X < 0.93)
    for k, t0 in enumerate(np.linspace(0.12, 0.86, 7)):
        side = 1 if k % 2 == 0 else -1
        ang = np.radians(45 + side * 50)
        L = 0.30 - 0.08 * t0
        px, py = t0, t0                               # attachment point on the twig
        dx, dy = np.cos(ang), np.sin(ang)
        lx = (X - px) * dx + (Y - py) * dy            # along the leaf
        ly = -(X - px) * dy + (Y - py) * dx           # across
        s = (lx - 0.03) / L                           # blade from s=0 (base) to s=1 (tip)
        width = 0.20 * L * np.sin(np.pi * np.clip(s, 0, 1) ** 0.8)
        blade = (s > 0) & (s < 1) & (np.abs(ly) < width * (1 + 0.05 * np.sin(s * 70)))
        midrib = (np.abs(ly) < 0.0035) & (s > 0.05) & (s < 0.9)
        m |= blade & ~midrib
        m |= (np.abs(ly) < 0.005) & (lx > 0) & (s <= 0.02)   # petiole
    op = m.reshape(n, ss, n, ss).mean((1, 3))
    write_ldr(out(d, "leaf_mask.png"), to_u8(op))


def mesh_colors():
    d = "mesh-colors"
    # blob: icosphere (1280 triangles) with radial bumps, float vertex normals and colours r g b
    V, F = icosphere(3)
    bump = 1 + 0.12 * np.sin(3 * V[:, 0] + 1) * np.sin(4 * V[:, 1]) + 0.08 * np.cos(5 * V[:, 2])
    Vb = V * bump[:, None]
    N = vertex_normals(Vb, F)
    h = (np.arctan2(V[:, 2], V[:, 0]) / (2 * np.pi)) % 1.0
    col = np.stack([0.5 + 0.45 * np.cos(2 * np.pi * (h + k / 3)) for k in range(3)], 1)
    col = col * (0.55 + 0.45 * (V[:, 1:2] + 1) / 2)
    write_ply(out(d, "blob.ply"), Vb, F,
              vprops=[("nx", N[:, 0]), ("ny", N[:, 1]), ("nz", N[:, 2]),
                      ("r", col[:, 0]), ("g", col[:, 1]), ("b", col[:, 2])],
              comment="bumpy icosphere with float vertex colours")
    # faceted gem: icosphere subdiv 1 (80 faces), float face colours
    V, F = icosphere(1)
    V = V * np.array([1.0, 1.3, 1.0])
    rng = np.random.default_rng(61)
    palette = np.array([[0.9, 0.2, 0.15], [0.95, 0.75, 0.1], [0.15, 0.55, 0.85], [0.2, 0.7, 0.3], [0.85, 0.85, 0.8]])
    fc = palette[rng.integers(0, len(palette), len(F))]
    write_ply(out(d, "facets.ply"), V, F,
              fprops=[("r", fc[:, 0]), ("g", fc[:, 1]), ("b", fc[:, 2])],
              comment="icosphere with float face colours")
    # table: OBJ with one group per part (top, four legs); Mitsuba merges them into one mesh
    groups = []
    Vt, Nt, Ft = box((-0.9, 0.7, -0.5), (0.9, 0.78, 0.5))
    groups.append(("top", "wood", Vt, Nt, None, Ft))
    for k, (sx, sz) in enumerate([(-1, -1), (1, -1), (1, 1), (-1, 1)]):
        Vl, Nl, Fl = box((sx * 0.8 - 0.05, 0.0, sz * 0.4 - 0.05), (sx * 0.8 + 0.05, 0.7, sz * 0.4 + 0.05))
        groups.append((f"leg{k + 1}", "wood", Vl, Nl, None, Fl))
    write_obj(out(d, "table.obj"), groups, "table: top + 4 legs, one group each, flat normals")


def lanczos_crop():
    d = "lanczos-crop"
    # planet lat-long map for a `sphere` (u = atan2(y, x)/2pi, v = acos(z)/pi), 256x128 PNG
    h, w = 128, 256
    y, x = np.mgrid[0:h, 0:w]
    lat = 90 - 180 * (y + 0.5) / h
    nz = value_noise(h, w, 4, 71, octaves=5)
    land = nz > 0.55
    img = np.where(land[..., None], np.array([0.25, 0.5, 0.18]) * (0.7 + 0.6 * (nz - 0.55))[..., None],
                   np.array([0.06, 0.18, 0.45]))
    img = np.where((land & (nz > 0.68))[..., None], np.array([0.55, 0.45, 0.3]), img)
    img = np.where((np.abs(lat) > 70)[..., None], np.array([0.92, 0.94, 0.96]), img)
    grid = ((x % 32) == 0) | ((y % 32) == 0)
    img = np.where(grid[..., None], np.array([0.9, 0.85, 0.2]), img)
    img = np.where(((x < 16) & (np.abs(lat) < 20))[..., None], np.array([0.9, 0.1, 0.1]), img)  # u = 0 marker
    write_ldr(out(d, "planet.png"), to_u8(img))


def envmap_glossy():
    d = "envmap-glossy"
    # OpenEXR lat-long, 256x128, a 6-degree sun (50x) 35 degrees up, plus two soft "softbox" panels
    sun = (0.0, np.sin(np.radians(35)), -np.cos(np.radians(35)))    # along the map's -z (u = 0)
    env = sky(256, 128, sun, 6.0, (50.0, 46.0, 40.0),
              zenith=np.array([0.2, 0.35, 0.75]), horizon=np.array([0.85, 0.88, 0.92]),
              ground=np.array([0.2, 0.18, 0.16]), glow=1.5)
    dirs = latlong_dirs(256, 128)
    for c, col in (((0.8, 0.25, 0.55), (4.0, 4.0, 4.2)), ((-0.9, 0.35, 0.25), (2.0, 2.6, 3.2))):
        c = np.array(c) / np.linalg.norm(c)
        ang = np.degrees(np.arccos(np.clip(dirs @ c, -1, 1)))
        env += (np.clip((12 - ang) / 2, 0, 1))[..., None] * np.array(col, np.float32)
    write_float(out(d, "studio.exr"), env)


def textured_emitters():
    d = "textured-emitters"
    # "stained glass" window: linear float EXR, 64x48 cells of saturated colour up to 3, with
    # dark leading between them; radiance of a rectangle light (texture v = 0 at the top)
    h, w = 48, 64
    y, x = np.mgrid[0:h, 0:w]
    rng = np.random.default_rng(23)
    palette = np.array([[3.0, 0.5, 0.3], [0.4, 2.4, 0.6], [0.45, 0.7, 3.0], [2.5, 2.1, 0.4], [2.0, 0.4, 2.3]])
    cells = palette[rng.integers(0, len(palette), (h // 8, w // 8))]
    img = cells[y // 8, x // 8]
    lead = ((x % 8) == 0) | ((y % 8) == 0)
    img = np.where(lead[..., None], np.array([0.02, 0.02, 0.02]), img)
    write_float(out(d, "window.exr"), img.astype(np.float32))


def spot_texture():
    d = "spot-texture"
    # projector slide: 8-bit sRGB PNG, 64x64, four quadrants (yellow, blue / green, red) with
    # diagonal stripes at half brightness, so the projection's orientation and flips show
    h = w = 64
    y, x = np.mgrid[0:h, 0:w]
    quad = np.array([[[0.95, 0.85, 0.1], [0.15, 0.3, 0.95]], [[0.1, 0.8, 0.2], [0.95, 0.15, 0.1]]])
    img = quad[y // 32, x // 32]
    stripe = ((x + y) // 6) % 2 == 1
    img = np.where(stripe[..., None], img * 0.5, img)
    write_ldr(out(d, "slide.png"), to_u8(img))


if __name__ == "__main__":
    textured_room()
    spectral_cornell()
    spectral_emitters()
    included_scene()
    legacy_v06()
    serialized_uv()
    checker_conductor()
    masked_leaves()
    mesh_colors()
    lanczos_crop()
    envmap_glossy()
    textured_emitters()
    spot_texture()
    print("assets written under", ROOT)
