//! Scene bundles: which files a scene XML references, so that a client can ship the scene
//! with everything it needs to a render farm, and the path rules for unpacking such a bundle
//! safely on the other side.
//!
//! ```no_run
//! use std::path::Path;
//! let files = tessera_common::bundle::referenced_files(Path::new("scenes/caustic-glass/scene.xml"), &Default::default()).unwrap();
//! assert!(files.iter().any(|f| f.ends_with("gem.obj")));
//! ```

use crate::scene::SceneError;
use crate::scene::xml::{Element, Value, parse};
use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

/// The files `scene` references (mesh `filename`s), resolved against the scene's folder the
/// way the loader resolves them, in document order without repeats. `$name` parameters are
/// substituted with `defines` over the file's `<default>`s.
pub fn referenced_files(scene: &Path, defines: &HashMap<String, String>) -> Result<Vec<PathBuf>, SceneError> {
    let text =
        std::fs::read_to_string(scene).map_err(|e| SceneError::file(scene, format!("cannot read scene: {e}")))?;
    let tree = parse(&text, scene, defines)?;
    let dir = scene.parent().unwrap_or(Path::new(""));
    let mut out = Vec::new();
    for e in &tree.elements {
        collect(e, dir, &mut out);
    }
    Ok(out)
}

fn collect(e: &Element, dir: &Path, out: &mut Vec<PathBuf>) {
    for p in &e.properties {
        if let (true, Value::String(s)) = (p.name == "filename", &p.value) {
            let path = dir.join(s);
            if !out.contains(&path) {
                out.push(path);
            }
        }
    }
    for c in &e.children {
        collect(c, dir, out);
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
    fn safe_relative_path_refuses_escapes() {
        assert_eq!(safe_relative_path("meshes/a.obj"), Some(PathBuf::from("meshes/a.obj")));
        assert_eq!(safe_relative_path("./a.obj"), Some(PathBuf::from("a.obj")));
        assert_eq!(safe_relative_path("../a.obj"), None);
        assert_eq!(safe_relative_path("/etc/passwd"), None);
        assert_eq!(safe_relative_path(""), None);
    }
}
