#!/usr/bin/env python3
"""Write scenes/coverage.json: for each scene listed in NEW_SCENES, the Mitsuba 3 plugins,
parameters, scene-language structures and asset formats it uses, as flat tokens.

    python3 scenes/make-coverage.py        # from the repository root (plain Python 3, no Mitsuba)

Tokens (all derived mechanically from the XML and the asset files):
  <tag>/<type>                          a plugin, e.g. "texture/bitmap", "rfilter/lanczos"
  <tag>/<type>:<name>                   a property given explicitly, e.g. "emitter/spot:cutoff_angle"
  <tag>/<type>:<name>=<value>           strings and booleans always; numbers for rfilter, sampler,
                                        film, serialized shape_index, spot, envmap and mask
  <tag>/<type>:<name>[rgb|float|integer|spectrum-list|spectrum-value|spectrum-file|<transform ops>]
  <tag>/<type>:<name><-<tag>/<type>     a nested object, e.g. "bsdf/roughconductor:alpha<-texture/bitmap"
  rfilter/default-gaussian              a film without <rfilter>
  structure/...                         include (root=scene|<tag>, name, nested), path, alias, ref
                                        (forward, named, nested), default, parameter ($name),
                                        version=..., upgrade-v1:<old>-><new>
  asset/...                             file formats, e.g. "asset/png:16bit:rgb", "asset/serialized:v4"
Property names are reported after Mitsuba's upgrade of version < 2.0 files (camelCase ->
snake_case, diffuse_reflectance -> reflectance on diffuse, uoffset/.. -> to_uv); the upgrade itself
is reported as structure/upgrade-v1:<old>-><new>.
"""
import json
import os
import re
import struct
import xml.etree.ElementTree as ET
import zlib

ROOT = os.path.dirname(os.path.abspath(__file__))
NEW_SCENES = ["textured-room", "spectral-cornell", "spectral-emitters", "included-scene", "legacy-v06",
              "spot-directional", "serialized-uv", "checker-conductor", "masked-leaves", "mesh-colors",
              "lanczos-crop", "envmap-glossy", "textured-emitters", "direct-samples",
              "area-ref", "conductor-names",
              "spot-texture"]
OBJECT_TAGS = {"scene", "bsdf", "shape", "emitter", "texture", "sensor", "film", "rfilter", "sampler",
               "integrator", "medium", "phase", "volume"}
PROP_TAGS = {"boolean", "integer", "float", "string", "point", "vector", "rgb", "spectrum", "transform"}
NUMERIC_VALUE_OF = ("rfilter/", "sampler/", "film/", "shape/serialized", "emitter/spot", "emitter/envmap",
                    "bsdf/mask")


def camel_to_snake(name):
    """Mitsuba's camel_to_underscore_case (parser.cpp)."""
    out, i = "", 0
    while i < len(name):
        c = name[i]
        if i > 0 and name[i - 1].islower() and c.isupper():
            out += "_" + c.lower()
            while i + 1 < len(name) and name[i + 1].isupper():
                i += 1
                out += name[i].lower()
        else:
            out += c
        i += 1
    return out


def version_lt2(v):
    return int(v.split(".")[0]) < 2


def child_name(ch, parent, toks):
    """The name a child object/ref gets in its parent, after the version < 2.0 upgrade."""
    name = ch.get("name")
    if not name or not version_lt2(parent.get("_version", "3.0.0")):
        return name or "_"
    new = camel_to_snake(name)
    if new != name:
        toks.add(f"structure/upgrade-v1:{name}->{new}")
    if parent.get("type") == "diffuse" and new == "diffuse_reflectance":
        toks.add(f"structure/upgrade-v1:{new}->reflectance")
        new = "reflectance"
    return new


class Flattener:
    def __init__(self, main):
        self.main = main
        self.scene_dir = os.path.dirname(main)
        self.search = [self.scene_dir]
        self.defaults = {}
        self.tokens = set()

    def subst(self, text):
        if "$" not in text:
            return text
        self.tokens.add("structure/parameter")
        for k in sorted(self.defaults, key=len, reverse=True):
            text = text.replace("$" + k, self.defaults[k])
        return text

    def load(self, path, depth=0):
        root = ET.parse(path).getroot()
        version = root.get("version")
        self.tokens.add(f"structure/version={version}" if depth == 0 else f"structure/include:version={version}")
        return self.walk(root, os.path.dirname(path), version, depth)

    def walk(self, el, cur_dir, version, depth):
        """Returns a copy of el with includes spliced, attributes substituted, version attached."""
        new = ET.Element(el.tag, {k: self.subst(v) for k, v in el.attrib.items()})
        new.set("_version", version)
        for ch in el:
            if ch.tag == "default":
                self.tokens.add("structure/default")
                n, v = ch.get("name"), ch.get("value")
                if n in self.defaults:
                    self.tokens.add("structure/default:repeated-name-first-wins")
                else:
                    self.defaults[n] = v
                continue
            if ch.tag == "path":
                self.tokens.add("structure/path")
                p = os.path.join(cur_dir, ch.get("value"))
                self.search.insert(0, p)
                continue
            if ch.tag == "include":
                self.tokens.add("structure/include")
                if depth >= 1:
                    self.tokens.add("structure/include:nested")
                fn = self.subst(ch.get("filename"))
                path = os.path.join(cur_dir, fn)
                inc = self.load(path, depth + 1)
                self.tokens.add(f"structure/include:root={inc.tag}")
                if inc.tag == "scene":
                    new.extend(list(inc))
                else:
                    if ch.get("name"):
                        self.tokens.add("structure/include:name")
                        inc.set("name", ch.get("name"))
                    new.append(inc)
                continue
            new.append(self.walk(ch, cur_dir, version, depth))
        return new

    def resolve(self, fn):
        for d in self.search:
            p = os.path.join(d, fn)
            if os.path.exists(p):
                return p
        return None


def asset_tokens(path):
    ext = path.rsplit(".", 1)[-1].lower()
    data = open(path, "rb").read()
    if ext == "png":
        depth, ctype = data[24], data[25]
        ch = {0: "y", 2: "rgb", 4: "ya", 6: "rgba"}.get(ctype, f"type{ctype}")
        return [f"asset/png:{depth}bit:{ch}"]
    if ext in ("jpg", "jpeg"):
        return ["asset/jpeg"]
    if ext == "exr":
        return ["asset/openexr"]
    if ext == "hdr":
        return ["asset/rgbe-hdr"]
    if ext == "bmp":
        bpp = struct.unpack_from("<H", data, 28)[0]
        return [f"asset/bmp:{bpp}bit"]
    if ext == "tga":
        return [f"asset/tga:type{data[2]}:{data[16]}bit" + (":v2-footer" if data.endswith(b"TRUEVISION-XFILE.\0") else "")]
    if ext == "spd":
        return ["asset/spd"]
    if ext == "obj":
        text = data.decode()
        groups = len(re.findall(r"^g ", text, re.M))
        toks = ["asset/obj"]
        if groups > 1:
            toks.append(f"asset/obj:groups={groups}")
        if re.search(r"^vn ", text, re.M):
            toks.append("asset/obj:vn")
        if re.search(r"^vt ", text, re.M):
            toks.append("asset/obj:vt")
        return toks
    if ext == "ply":
        head = data[:data.index(b"end_header")].decode()
        fmt = re.search(r"^format (\S+)", head, re.M).group(1)
        toks = [f"asset/ply:{fmt}"]
        elem = None
        for line in head.splitlines():
            w = line.split()
            if w and w[0] == "element":
                elem = w[1]
            elif w and w[0] == "property" and w[1] != "list" and w[2] not in ("x", "y", "z"):
                toks.append(f"asset/ply:{elem}:{w[2]}:{w[1]}")
        return toks
    if ext == "serialized":
        version = struct.unpack_from("<H", data, 2)[0]
        count = struct.unpack_from("<I", data, len(data) - 4)[0]
        offs = struct.unpack_from("<%dQ" % count, data, len(data) - 4 - 8 * count)
        toks = [f"asset/serialized:v{version}", f"asset/serialized:meshes={count}"]
        for o in offs:
            payload = zlib.decompressobj().decompress(data[o + 4:])
            flags = struct.unpack_from("<I", payload)[0]
            desc = ["float64" if flags & 0x2000 else "float32"]
            desc += [n for bit, n in ((1, "normals"), (2, "uvs"), (8, "colors")) if flags & bit]
            toks.append("asset/serialized:mesh:" + "+".join(desc))
        return toks
    return [f"asset/{ext}"]


def scene_tokens(name):
    main = os.path.join(ROOT, name, "scene.xml")
    fl = Flattener(main)
    root = fl.load(main)
    toks = fl.tokens

    # document order of ids (after splicing includes) for forward-reference detection
    order = {}
    ids = {}
    referenced = set()
    for k, el in enumerate(root.iter()):
        order[id(el)] = k
        if el.get("id") and el.tag in OBJECT_TAGS:
            ids[el.get("id")] = el
    for el in root.iter():
        if el.tag == "alias":
            ids[el.get("as")] = ids[el.get("id")]
            toks.add("structure/alias")
        if el.tag == "ref":
            referenced.add(el.get("id"))

    def label(el):
        return f"{el.tag}/{el.get('type')}"

    def visit(el, parent, inside_ids):
        parent_label = label(parent) if parent is not None and parent.tag != "scene" else None
        lab = label(el) if el.tag != "scene" else "scene"
        old = version_lt2(el.get("_version", "3.0.0"))
        if el.tag not in ("scene",):
            toks.add(lab)
            if parent_label:
                toks.add(f"{parent_label}:{child_name(el, parent, toks)}<-{lab}")
        if el.tag == "film" and el.find("rfilter") is None:
            toks.add("rfilter/default-gaussian")
        my_ids = inside_ids + ([el.get("id")] if el.get("id") else [])
        for ch in el:
            if ch.tag in OBJECT_TAGS:
                visit(ch, el, my_ids)
            elif ch.tag == "ref":
                toks.add("structure/ref")
                tgt = ids[ch.get("id")]
                if order[id(tgt)] > order[id(ch)]:
                    toks.add("structure/ref:forward")
                if ch.get("name"):
                    toks.add("structure/ref:named")
                if any(i in referenced for i in my_ids):
                    toks.add("structure/ref:nested")
                if el.tag != "scene":
                    toks.add(f"{lab}:{child_name(ch, el, toks)}<-ref:{label(tgt)}")
            elif ch.tag in PROP_TAGS:
                pname = ch.get("name")
                if old:
                    new = camel_to_snake(pname)
                    if new != pname:
                        toks.add(f"structure/upgrade-v1:{pname}->{new}")
                    if el.get("type") == "diffuse" and new == "diffuse_reflectance":
                        toks.add("structure/upgrade-v1:diffuse_reflectance->reflectance")
                        new = "reflectance"
                    if new in ("uoffset", "voffset", "uscale", "vscale"):
                        toks.add(f"structure/upgrade-v1:{pname}->to_uv")
                        toks.add(f"{lab}:to_uv[upgrade-v1]")
                        continue
                    pname = new
                toks.add(f"{lab}:{pname}")
                val = ch.get("value")
                if ch.tag in ("string", "boolean"):
                    toks.add(f"{lab}:{pname}={val}")
                    if pname == "filename":
                        path = fl.resolve(val)
                        if path is None:
                            raise SystemExit(f"{name}: cannot resolve {val}")
                        at = asset_tokens(path)
                        toks.update(at)
                        toks.add(f"{lab}:file<-{at[0]}")
                elif ch.tag in ("integer", "float"):
                    toks.add(f"{lab}:{pname}[{ch.tag}]")
                    if lab.startswith(NUMERIC_VALUE_OF):
                        toks.add(f"{lab}:{pname}={val}")
                elif ch.tag == "rgb":
                    toks.add(f"{lab}:{pname}[rgb]")
                elif ch.tag == "spectrum":
                    if ch.get("filename"):
                        kind = "spectrum-file"
                        toks.update(asset_tokens(os.path.join(os.path.dirname(main), ch.get("filename"))))
                    elif ":" in val:
                        kind = "spectrum-list"
                    else:
                        kind = "spectrum-value"
                    toks.add(f"{lab}:{pname}[{kind}]")
                elif ch.tag == "transform":
                    ops = "+".join(sorted({c.tag for c in ch}))
                    toks.add(f"{lab}:{pname}[{ops}]")
                elif ch.tag in ("point", "vector"):
                    toks.add(f"{lab}:{pname}[{ch.tag}]")
    visit(root, None, [])
    toks.discard("scene/None")
    return sorted(toks)


# what the scene set must exercise (the brief for branch new-scenes), checked on every run
REQUIRED = [
    # 1 textured-room
    "emitter/envmap:file<-asset/rgbe-hdr", "emitter/envmap:scale[float]", "emitter/envmap:to_world[rotate]",
    "texture/bitmap:file<-asset/png:8bit:rgb", "texture/bitmap:wrap_mode=repeat", "texture/bitmap:to_uv[scale]",
    "texture/bitmap:file<-asset/jpeg", "bsdf/roughplastic:diffuse_reflectance<-texture/bitmap",
    "bsdf/diffuse:reflectance<-texture/bitmap",
    # 2 spectral-cornell
    "bsdf/diffuse:reflectance[spectrum-list]", "emitter/area:radiance[spectrum-list]",
    "bsdf/diffuse:reflectance[spectrum-value]", "bsdf/diffuse:reflectance[spectrum-file]", "asset/spd",
    "rfilter/default-gaussian",
    # 3 included-scene
    "structure/include:root=scene", "structure/include:root=shape", "structure/include:nested",
    "structure/path", "structure/alias", "structure/ref:forward", "structure/ref:nested",
    "structure/default", "structure/parameter",
    # 4 legacy-v06
    "structure/version=0.6.0", "structure/upgrade-v1:toWorld->to_world", "structure/upgrade-v1:maxDepth->max_depth",
    "structure/upgrade-v1:intIOR->int_ior", "structure/upgrade-v1:extIOR->ext_ior",
    "structure/upgrade-v1:fovAxis->fov_axis", "structure/upgrade-v1:sampleCount->sample_count",
    "structure/upgrade-v1:diffuse_reflectance->reflectance", "structure/upgrade-v1:uoffset->to_uv",
    "structure/upgrade-v1:uscale->to_uv", "structure/upgrade-v1:vscale->to_uv",
    # 5 spot-directional
    "emitter/spot:cutoff_angle[float]", "emitter/spot:beam_width[float]", "emitter/spot:to_world[lookat]",
    "emitter/directional:irradiance[rgb]", "emitter/directional:direction[vector]", "rfilter/tent:radius[float]",
    # 6 serialized-uv
    "shape/serialized:shape_index=0", "shape/serialized:shape_index=1", "asset/serialized:meshes=2",
    "asset/serialized:mesh:float32+normals+uvs", "asset/serialized:mesh:float64+uvs",
    "texture/bitmap:file<-asset/openexr", "texture/bitmap:file<-asset/png:16bit:rgb",
    "texture/bitmap:filter_type=nearest", "texture/bitmap:wrap_mode=mirror", "texture/bitmap:wrap_mode=clamp",
    # 7 checker-conductor
    "bsdf/roughconductor:specular_reflectance<-texture/checkerboard", "texture/checkerboard:to_uv[scale]",
    "bsdf/roughconductor:alpha<-texture/bitmap", "texture/bitmap:raw=true", "texture/bitmap:file<-asset/png:8bit:y",
    "texture/bitmap:file<-asset/bmp:24bit", "texture/bitmap:file<-asset/tga:type2:24bit:v2-footer",
    "rfilter/catmullrom",
    # 8 masked-leaves
    "bsdf/mask:opacity<-texture/bitmap", "bsdf/mask:_<-bsdf/twosided", "bsdf/twosided:_<-bsdf/diffuse",
    # 9 mesh-colors
    "texture/mesh_attribute:name=vertex_color", "texture/mesh_attribute:name=face_color",
    "asset/ply:vertex:r:float", "asset/ply:face:r:float", "asset/obj:groups=5", "rfilter/mitchell",
    # 10 lanczos-crop
    "rfilter/lanczos", "film/hdrfilm:crop_offset_x[integer]", "film/hdrfilm:crop_offset_y[integer]",
    "film/hdrfilm:crop_width[integer]", "film/hdrfilm:crop_height[integer]", "shape/sphere:to_world[rotate+scale+translate]",
    "shape/disk", "texture/checkerboard",
    # 11 envmap-glossy
    "emitter/envmap:file<-asset/openexr", "bsdf/roughconductor:alpha_u[float]", "bsdf/roughconductor:alpha_v[float]",
    "bsdf/dielectric", "bsdf/roughplastic", "rfilter/gaussian:stddev[float]",
    # 13 textured-emitters
    "emitter/area:radiance<-texture/bitmap", "emitter/area:radiance<-texture/checkerboard",
    # 12 samplers and integrators
    "sampler/stratified:sample_count[integer]", "sampler/stratified:seed[integer]",
    "sampler/multijitter:sample_count[integer]", "sampler/multijitter:seed[integer]",
    "sampler/orthogonal:sample_count[integer]", "sampler/orthogonal:seed[integer]",
    "sampler/ldsampler:sample_count[integer]", "sampler/ldsampler:seed[integer]",
    "integrator/direct", "integrator/volpath", "integrator/moment:_<-integrator/path", "integrator/aov:image<-integrator/path",
    # shapes and emitters
    "shape/rectangle", "shape/cube", "shape/sphere", "shape/disk", "shape/obj", "shape/ply",
    "emitter/envmap:file<-asset/png:8bit:rgb", "emitter/point", "emitter/area",
]
FORBIDDEN = ["spectrum/blackbody", "bsdf/principled", "bsdf/normalmap", "bsdf/bumpmap", "bsdf/blendbsdf",
             "shape/instance", "shape/shapegroup", "shape/cylinder", "sensor/thinlens", "sensor/orthographic",
             "medium/", "phase/", "integrator/ptracer", "bsdf/polarizer", "bsdf/retarder",
             "bsdf/dielectric:int_ior<-", "bsdf/dielectric:ext_ior<-"]


def main():
    scenes = {n: scene_tokens(n) for n in NEW_SCENES}
    index = {}
    for n, toks in scenes.items():
        for t in toks:
            index.setdefault(t, []).append(n)
    missing = [t for t in REQUIRED if t not in index]
    forbidden = [t for t in index if t.startswith(tuple(FORBIDDEN))]
    if missing or forbidden:
        raise SystemExit(f"missing: {missing}\nforbidden: {forbidden}")
    doc = {
        "generated_by": "scenes/make-coverage.py",
        "mitsuba": "3.9.1",
        "note": "tokens per scene; 'required' maps each token the scene set must exercise to the scenes "
                "using it; 'index' maps every token to the scenes using it",
        "scenes": scenes,
        "required": {t: index[t] for t in REQUIRED},
        "forbidden_prefixes": FORBIDDEN,
        "index": dict(sorted(index.items())),
    }
    with open(os.path.join(ROOT, "coverage.json"), "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")
    print(f"{len(scenes)} scenes, {len(index)} distinct tokens")


if __name__ == "__main__":
    main()
