//! Scene bundles: which files a scene XML reaches (included XML files, spectrum files and every
//! plugin `filename`, resolved exactly as the loader resolves them), the bundle a client ships to
//! a render farm (the scene and everything it needs, with paths relative to the deepest folder
//! holding them all, so that a scene reaching `../textures` ships unchanged), and the path rules
//! for unpacking such a bundle safely on the other side.
//!
//! ```no_run
//! use std::path::Path;
//! let files = tessera_common::bundle::referenced_files(Path::new("scenes/caustic-glass/scene.xml"), &Default::default()).unwrap();
//! assert!(files.iter().any(|f| f.ends_with("gem.obj")));
//! ```

use crate::scene::resolver::normalize;
use crate::scene::xml::{Element, Value, parse};
use crate::scene::{FileResolver, SceneError};
use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

/// A scene and the files it needs, with `/`-separated paths relative to the bundle's root.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Bundle {
    /// The scene XML's path in `files`.
    pub scene_path: String,
    /// Path and bytes of every file, the scene first.
    pub files: Vec<(String, Vec<u8>)>,
}

/// Packing a bundle failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BundleError {
    /// The scene does not parse.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A file cannot be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A referenced file lies outside the scene's folder, so it has no path in the bundle.
    #[error("{file} is outside the scene's folder {folder}")]
    Outside {
        /// The file.
        file: PathBuf,
        /// The scene's folder.
        folder: PathBuf,
    },
}

/// Packs `scene` and every file it references ([`referenced_files`]) into a bundle rooted at
/// the deepest folder that holds the scene and all of them (the scene's own folder when nothing
/// lies outside it), so the scene's relative names work unchanged inside the bundle.
pub fn pack(scene: &Path, defines: &HashMap<String, String>) -> Result<Bundle, BundleError> {
    pack_many(&[(scene.to_path_buf(), defines.clone())], scene)
}

/// Packs several scenes (the frames of an animation: one file per frame, or one file with
/// per-frame `defines`) and every file each references into one bundle, each file once, rooted
/// as [`pack`] roots one scene. The bundle's scene path is `name`'s (a frame-numbered name
/// such as `shot.####.xml` need not exist).
pub fn pack_many(scenes: &[(PathBuf, HashMap<String, String>)], name: &Path) -> Result<Bundle, BundleError> {
    let read = |path: &Path| std::fs::read(path).map_err(|source| BundleError::Read { path: path.into(), source });
    let mut referenced: Vec<PathBuf> = Vec::new();
    for (scene, defines) in scenes {
        for file in std::iter::once(scene.clone()).chain(referenced_files(scene, defines)?) {
            if !referenced.contains(&file) {
                referenced.push(file);
            }
        }
    }
    let absolute = |p: &Path| std::path::absolute(p).map(|a| normalize(&a)).unwrap_or_else(|_| normalize(p));
    // `scene.xml`'s parent is the empty path, which is the current folder
    let parent_of = |p: &Path| {
        absolute(
            Some(p.parent().unwrap_or(Path::new(""))).filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new(".")),
        )
    };
    let mut folder = parent_of(name);
    for file in &referenced {
        let parent = parent_of(file);
        while !parent.starts_with(&folder) && folder.pop() {}
    }
    let folder = folder.as_path();
    let outside = |file: &Path| BundleError::Outside { file: file.into(), folder: folder.into() };
    let in_bundle = |file: &Path| {
        relative_to(&absolute(file), folder)
            .and_then(|r| r.to_str().map(|s| s.replace('\\', "/")))
            .filter(|r| safe_relative_path(r).is_some())
            .ok_or_else(|| outside(file))
    };
    let scene_path = in_bundle(name)?;
    let mut files: Vec<(String, Vec<u8>)> = Vec::new();
    for file in referenced {
        let relative = in_bundle(&file)?;
        if !files.iter().any(|(p, _)| *p == relative) {
            files.push((relative, read(&file)?));
        }
    }
    Ok(Bundle { scene_path, files })
}

/// `file` relative to `folder` if it lies inside: compared lexically first (so `sub/../x` is
/// `x`), then with both paths canonicalised (so symbolic links and absolute `<path>`s that
/// point back into the folder count as inside).
fn relative_to(file: &Path, folder: &Path) -> Option<PathBuf> {
    if let Ok(r) = normalize(file).strip_prefix(normalize(folder)) {
        return Some(r.to_path_buf());
    }
    let (file, folder) = (file.canonicalize().ok()?, folder.canonicalize().ok()?);
    file.strip_prefix(folder).ok().map(Path::to_path_buf)
}

/// The files `scene` reaches besides itself, in the order the loader meets them without
/// repeats: included XML files and spectrum files as the parser reads them, then every plugin
/// `filename`, resolved through the scene's `<path>` list the way the loader resolves it.
/// `$name` parameters are substituted with `defines` over the file's `<default>`s.
pub fn referenced_files(scene: &Path, defines: &HashMap<String, String>) -> Result<Vec<PathBuf>, SceneError> {
    let text =
        std::fs::read_to_string(scene).map_err(|e| SceneError::file(scene, format!("cannot read scene: {e}")))?;
    let tree = parse(&text, scene, defines)?;
    let mut out = tree.files.clone();
    for e in &tree.elements {
        collect(e, &tree.resolver, &mut out);
    }
    Ok(out)
}

fn collect(e: &Element, resolver: &FileResolver, out: &mut Vec<PathBuf>) {
    for p in &e.properties {
        if let (true, Value::String(s)) = (p.name == "filename", &p.value) {
            let path = resolver.resolve(Path::new(s));
            if !out.contains(&path) {
                out.push(path);
            }
        }
    }
    for c in &e.children {
        collect(c, resolver, out);
    }
}

/// `path` (relative, `/`-separated, as stored in a bundle) as a path that stays inside the
/// folder it is joined to: `None` for absolute paths, `..`, or empty paths.
pub fn safe_relative_path(path: &str) -> Option<PathBuf> {
    let p = Path::new(path);
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            Component::Normal(s) => out.push(s),
            Component::CurDir => {}
            _ => return None,
        }
    }
    (!out.as_os_str().is_empty()).then_some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn referenced_files_lists_meshes_relative_to_the_scene() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/caustic-glass/scene.xml");
        let files = referenced_files(&dir, &HashMap::new()).unwrap();
        assert_eq!(files.len(), 1, "{files:?}");
        assert!(files[0].ends_with("gem.obj") && files[0].exists());
        let box_scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.xml");
        assert!(referenced_files(&box_scene, &HashMap::new()).unwrap().is_empty());
    }

    #[test]
    fn pack_holds_the_scene_and_its_meshes() {
        let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/caustic-glass/scene.xml");
        let bundle = pack(&scene, &HashMap::new()).unwrap();
        assert_eq!(bundle.scene_path, "scene.xml");
        let paths: Vec<&str> = bundle.files.iter().map(|(p, _)| p.as_str()).collect();
        assert_eq!(paths[0], "scene.xml");
        assert!(paths[1..].iter().all(|p| p.ends_with(".obj")), "{paths:?}");
        assert_eq!(bundle.files[0].1, std::fs::read(&scene).unwrap());
    }

    /// A scene reaching into a sibling folder ships from their common folder, names unchanged.
    #[test]
    fn pack_roots_the_bundle_where_every_file_fits() {
        let tmp = tempfile::tempdir().unwrap();
        let (scene_dir, shared) = (tmp.path().join("project/scene"), tmp.path().join("project/meshes"));
        std::fs::create_dir_all(&scene_dir).unwrap();
        std::fs::create_dir_all(&shared).unwrap();
        std::fs::write(shared.join("m.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let xml = r#"<scene version="3.0.0"><shape type="obj"><string name="filename" value="../meshes/m.obj"/></shape></scene>"#;
        std::fs::write(scene_dir.join("scene.xml"), xml).unwrap();
        let bundle = pack(&scene_dir.join("scene.xml"), &HashMap::new()).unwrap();
        assert_eq!(bundle.scene_path, "scene/scene.xml");
        let paths: Vec<&str> = bundle.files.iter().map(|(p, _)| p.as_str()).collect();
        assert_eq!(paths, ["scene/scene.xml", "meshes/m.obj"]);
    }

    #[test]
    fn safe_relative_path_refuses_escapes() {
        assert_eq!(safe_relative_path("meshes/a.obj"), Some(PathBuf::from("meshes/a.obj")));
        assert_eq!(safe_relative_path("./a.obj"), Some(PathBuf::from("a.obj")));
        assert_eq!(safe_relative_path("../a.obj"), None);
        assert_eq!(safe_relative_path("/etc/passwd"), None);
        assert_eq!(safe_relative_path(""), None);
    }
}
