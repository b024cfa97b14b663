"""Scene bundles: the scene XML and every file it reaches, as `tessera submit` ships them.

The files are found as Tessera's loader finds them (common/src/bundle.rs): included XML files
and spectrum files while the scene is read, through a search list that starts with the scene's
folder, gets each `<path>` in front, and the including file's folder in front for the time of an
`<include>`; then every plugin `filename`, through the final search list. `$name` parameters
are substituted from the caller's defines over the file's `<default>`s. The bundle is rooted at
the deepest folder holding all the files, so `../textures` ships unchanged.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Set, Tuple, Union

#: Most nested `<include>`s, as the loader allows.
MAX_INCLUDE_DEPTH = 16


class BundleError(Exception):
    """The scene or a file it references cannot be read."""


#: Tags of plugin objects (besides `<scene>` and `<spectrum type=..>`), as the loader has them.
OBJECT_TAGS = {"bsdf", "emitter", "film", "integrator", "medium", "phase", "rfilter", "sampler", "sensor",
               "shape", "texture", "volume"}


@dataclass
class _Node:
    """An object of the scene: its `filename` properties and its child objects, a `<ref>` to
    an object as its id."""

    filenames: List[str] = field(default_factory=list)
    children: List[Union["_Node", str]] = field(default_factory=list)

    def collect(self, ids: Dict[str, "_Node"], out: List[str], seen: Set[int]) -> None:
        # the loader's order: an object's own properties, then its children, a referenced
        # object where it is referenced (once)
        if id(self) in seen:
            return
        seen.add(id(self))
        out += self.filenames
        for child in self.children:
            target = ids.get(child) if isinstance(child, str) else child
            if target is not None:
                target.collect(ids, out, seen)


@dataclass
class _Reader:
    params: Dict[str, str]
    dirs: List[Path]
    files: List[Path] = field(default_factory=list)
    ids: Dict[str, _Node] = field(default_factory=dict)
    aliases: Dict[str, str] = field(default_factory=dict)

    def substitute(self, text: str) -> str:
        for name, value in self.params.items():
            text = text.replace("$" + name, value)
        return text

    def find(self, name: str) -> Optional[Path]:
        path = Path(name)
        if path.is_absolute():
            return path if path.exists() else None
        for folder in self.dirs:
            if (folder / path).exists():
                return folder / path
        return None

    def resolve(self, name: str) -> Path:
        found = self.find(name)
        if found is not None:
            return found
        return self.dirs[-1] / name if not Path(name).is_absolute() else Path(name)

    def record(self, path: Path) -> None:
        if path not in self.files:
            self.files.append(path)

    def read(self, path: Path, depth: int) -> Tuple[str, _Node]:
        """The root's tag and object tree of the XML file `path`."""
        try:
            root = ET.parse(path).getroot()
        except (OSError, ET.ParseError) as e:
            raise BundleError(f"{path}: {e}") from e
        node = _Node()
        self.walk(root, node, path, depth, is_root=True)
        return root.tag, node

    def walk(self, element: ET.Element, node: _Node, file: Path, depth: int, is_root: bool) -> None:
        for child in element:
            attrs = {k: self.substitute(v) for k, v in child.attrib.items()}
            tag = child.tag
            if tag in OBJECT_TAGS or (tag == "spectrum" and "type" in attrs):
                object_node = _Node()
                if "id" in attrs:
                    self.ids[attrs["id"]] = object_node
                self.walk(child, object_node, file, depth, is_root=False)
                node.children.append(object_node)
            elif tag == "ref" and "id" in attrs:
                node.children.append(attrs["id"])
            elif tag == "alias" and "id" in attrs and "as" in attrs:
                self.aliases[attrs["as"]] = attrs["id"]
            elif tag == "default" and "name" in attrs and "value" in attrs:
                self.params.setdefault(attrs["name"], attrs["value"])
            elif tag == "path" and is_root and "value" in attrs:
                self.add_path(attrs["value"], file)
            elif tag == "include" and "filename" in attrs:
                self.include(attrs["filename"], node, file, depth)
            elif tag == "spectrum" and "filename" in attrs:
                found = self.find(attrs["filename"])
                if found is None:
                    raise BundleError(f"{file}: spectrum file \"{attrs['filename']}\" not found")
                self.record(found)
            elif attrs.get("name") == "filename" and "value" in attrs:
                node.filenames.append(attrs["value"])

    def add_path(self, value: str, file: Path) -> None:
        p = Path(value)
        if p.is_absolute():
            folder = p
        else:
            local = file.parent / p
            folder = local if local.exists() else (self.find(value) or local)
        self.dirs.insert(0, folder)

    def include(self, name: str, parent: _Node, file: Path, depth: int) -> None:
        if depth + 1 >= MAX_INCLUDE_DEPTH:
            raise BundleError(f"{file}: <include> of \"{name}\" is nested too deep")
        saved = list(self.dirs)
        self.dirs.insert(0, file.parent)
        found = self.find(name)
        if found is None:
            raise BundleError(f"{file}: included file \"{name}\" not found")
        self.record(found)
        tag, node = self.read(found, depth + 1)
        self.dirs = saved
        # an included <scene>'s objects join the including object; another root is one object
        if tag == "scene":
            parent.children += node.children
        else:
            parent.children.append(node)


def referenced_files(scene: Path, defines: Optional[Mapping[str, str]] = None) -> List[Path]:
    """The files `scene` reaches besides itself, in the order the loader meets them."""
    reader = _Reader(params=dict(defines or {}), dirs=[scene.parent])
    _, root = reader.read(scene, 0)
    ids = dict(reader.ids)
    for alias, target in reader.aliases.items():
        if target in ids:
            ids[alias] = ids[target]
    names: List[str] = []
    root.collect(ids, names, set())
    for name in names:
        reader.record(reader.resolve(name))
    return reader.files


def find_scene(path: Path) -> Path:
    """`path` if it is a file; for a folder, its `scene.xml` or its only `.xml` file."""
    if path.is_file():
        return path
    if not path.is_dir():
        raise BundleError(f"{path}: no such file or folder")
    if (path / "scene.xml").is_file():
        return path / "scene.xml"
    xml = sorted(p for p in path.iterdir() if p.suffix == ".xml" and p.is_file())
    if len(xml) != 1:
        raise BundleError(f"{path}: no scene.xml, and {len(xml)} .xml files where one would name the scene")
    return xml[0]


def pack(scene: Path, defines_per_frame: Optional[Sequence[Mapping[str, str]]] = None) -> Tuple[str, List[Tuple[str, Path]]]:
    """The scene's path in the bundle and every file's (bundle path, local path), the scene
    first; one set of files per frame's defines, joined."""
    scene = Path(os.path.abspath(scene))
    files: List[Path] = [scene]
    for defines in defines_per_frame or [{}]:
        for f in referenced_files(scene, defines):
            absolute = Path(os.path.normpath(os.path.abspath(f)))
            if absolute not in files:
                files.append(absolute)
    missing = [f for f in files if not f.is_file()]
    if missing:
        raise BundleError(f"{scene}: referenced file {missing[0]} not found")
    root = Path(os.path.commonpath([str(f.parent) for f in files]))
    entries = [(f.relative_to(root).as_posix(), f) for f in files]
    return entries[0][0], entries
