#!/usr/bin/env python3
"""Compares the pixels of two OpenEXR files bit for bit, every channel, ignoring the header's
attributes (render time, scene path). Used by deploy/test.sh, which must run with nothing but
Python's standard library: it reads the single-part scanline files Tessera writes, uncompressed
or ZIP/ZIPS-compressed (what `exr`'s SMALL_LOSSLESS produces), and refuses anything else.

    exr-equal.py A.exr B.exr     exit 0 if identical, 1 if they differ, 2 if unreadable
"""
import itertools
import struct
import sys
import zlib

MAGIC = 20000630
COMPRESSION = {0: "none", 1: "rle", 2: "zips", 3: "zip", 4: "piz", 5: "pxr24", 6: "b44", 7: "b44a", 8: "dwaa", 9: "dwab"}
LINES_PER_BLOCK = {"none": 1, "zips": 1, "zip": 16}
BYTES_PER_SAMPLE = {0: 4, 1: 2, 2: 4}  # uint, half, float


class ExrError(Exception):
    pass


def read_header(data, path):
    magic, version = struct.unpack_from("<ii", data, 0)
    if magic != MAGIC:
        raise ExrError(f"{path}: not an OpenEXR file")
    if version & 0x1A00:  # tiled (0x200), deep (0x800), multi-part (0x1000)
        raise ExrError(f"{path}: only single-part scanline files are supported (flags {version:#x})")
    pos, attrs = 8, {}
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        name, kind = data[pos:name_end].decode(), data[name_end + 1 : type_end].decode()
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = data[type_end + 5 : type_end + 5 + size]
        attrs[name] = (kind, value)
        pos = type_end + 5 + size
    return attrs, pos + 1


def parse_channels(raw):
    channels, pos = [], 0
    while raw[pos] != 0:
        end = raw.index(b"\0", pos)
        name = raw[pos:end].decode()
        pixel_type, _linear, xs, ys = struct.unpack_from("<iB3xii", raw, end + 1)
        if (xs, ys) != (1, 1):
            raise ExrError(f"channel {name} is subsampled")
        channels.append((name, pixel_type))
        pos = end + 1 + 16
    return channels


def undo_zip(block, expected):
    raw = zlib.decompress(block)
    if len(raw) != expected:
        raise ExrError(f"a block holds {len(raw)} bytes instead of {expected}")
    # OpenEXR's ZIP: a byte-delta predictor, then the two halves interleaved
    t = bytes(itertools.accumulate(raw, lambda a, b: (a + b - 128) & 0xFF))
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2], out[1::2] = t[:half], t[half:]
    return bytes(out)


def read_exr(path):
    """Returns (width, height, {channel: [bytes of each scanline]}, {attribute: text})."""
    with open(path, "rb") as f:
        data = f.read()
    attrs, pos = read_header(data, path)
    xmin, ymin, xmax, ymax = struct.unpack("<iiii", attrs["dataWindow"][1])
    width, height = xmax - xmin + 1, ymax - ymin + 1
    channels = parse_channels(attrs["channels"][1])
    compression = COMPRESSION.get(attrs["compression"][1][0], "unknown")
    if compression not in LINES_PER_BLOCK:
        raise ExrError(f"{path}: {compression} compression is not supported")
    lines = LINES_PER_BLOCK[compression]
    chunks = (height + lines - 1) // lines
    offsets = struct.unpack_from(f"<{chunks}Q", data, pos)
    planes = {name: [None] * height for name, _ in channels}
    for offset in offsets:
        y, size = struct.unpack_from("<ii", data, offset)
        block = data[offset + 8 : offset + 8 + size]
        rows = min(lines, ymax - y + 1)
        expected = rows * width * sum(BYTES_PER_SAMPLE[t] for _, t in channels)
        # a block that would not shrink is stored as it is
        pixels = block if size == expected or compression == "none" else undo_zip(block, expected)
        p = 0
        for row in range(rows):
            for name, pixel_type in channels:
                n = width * BYTES_PER_SAMPLE[pixel_type]
                planes[name][y - ymin + row] = pixels[p : p + n]
                p += n
    if any(row is None for rows in planes.values() for row in rows):
        raise ExrError(f"{path}: some scanlines are missing")
    text = {}
    for name, (kind, value) in attrs.items():
        if name.startswith("tessera/"):
            if kind == "string":
                text[name] = value.decode(errors="replace")
            elif kind == "float":
                text[name] = repr(struct.unpack("<f", value)[0])
            elif kind == "int":
                text[name] = str(struct.unpack("<i", value)[0])
    return width, height, {name: b"".join(rows) for name, rows in planes.items()}, text


def main():
    if len(sys.argv) != 3:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    a_path, b_path = sys.argv[1:]
    try:
        (aw, ah, a, a_attrs), (bw, bh, b, b_attrs) = read_exr(a_path), read_exr(b_path)
    except (OSError, ExrError, KeyError, struct.error, zlib.error) as e:
        print(f"exr-equal: cannot read: {e}", file=sys.stderr)
        return 2
    for key in ("tessera/integrator", "tessera/spp", "tessera/seed"):
        print(f"  {key}: {a_attrs.get(key, '-')} | {b_attrs.get(key, '-')}")
    if (aw, ah) != (bw, bh):
        print(f"exr-equal: sizes differ: {aw}x{ah} and {bw}x{bh}")
        return 1
    if sorted(a) != sorted(b):
        print(f"exr-equal: channels differ: {sorted(a)} and {sorted(b)}")
        return 1
    pixels, differing = aw * ah, {}
    for name in sorted(a):
        x, y = a[name], b[name]
        step = len(x) // pixels
        n = sum(1 for i in range(0, len(x), step) if x[i : i + step] != y[i : i + step]) if x != y else 0
        if n:
            differing[name] = n
    if differing:
        print(f"exr-equal: {a_path} and {b_path} differ: " + ", ".join(f"{k}: {v} of {pixels} pixels" for k, v in differing.items()))
        return 1
    print(f"exr-equal: identical, {aw}x{ah} pixels, channels {', '.join(sorted(a))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
