//! Where a scene's relative filenames are looked for: Mitsuba's `FileResolver`, an ordered
//! list of folders in which the first folder holding the file wins.
//!
//! The list starts as the main scene's folder; each top-level `<path value>` of the main scene
//! is put in front of it. Every plugin `filename` (meshes, images, …) is resolved against the
//! list as it stands when parsing ends, so a relative filename written inside an `<include>`d
//! file is looked up from the *main* scene, not from the included file's folder, exactly as
//! Mitsuba resolves it at instantiation. Unlike Mitsuba, the current working directory is never
//! searched: a scene must load the same way wherever a worker runs it.
//!
//! ```
//! use std::path::Path;
//! use tessera_common::scene::FileResolver;
//! let mut resolver = FileResolver::new(Path::new("scenes/cornell-box"));
//! resolver.prepend(Path::new("scenes/cornell-box/meshes").to_path_buf());
//! // nothing exists under these names: the fallback is the scene's own folder
//! assert_eq!(resolver.resolve(Path::new("none.obj")), Path::new("scenes/cornell-box/none.obj"));
//! ```

use std::path::{Path, PathBuf};

/// An ordered list of folders searched for relative filenames.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileResolver {
    /// Searched first to last; the last is the main scene's folder.
    dirs: Vec<PathBuf>,
}

impl FileResolver {
    /// A resolver searching only `scene_dir`.
    pub fn new(scene_dir: &Path) -> Self {
        FileResolver { dirs: vec![scene_dir.to_path_buf()] }
    }

    /// Searches `dir` before every folder already in the list.
    pub fn prepend(&mut self, dir: PathBuf) {
        self.dirs.insert(0, dir);
    }

    /// The folders in search order.
    pub fn dirs(&self) -> &[PathBuf] {
        &self.dirs
    }

    /// The first existing `dir/path` in search order; an absolute `path` if it exists.
    pub fn find(&self, path: &Path) -> Option<PathBuf> {
        if path.is_absolute() {
            return path.exists().then(|| path.to_path_buf());
        }
        self.dirs.iter().map(|dir| dir.join(path)).find(|candidate| candidate.exists())
    }

    /// [`Self::find`], or else `path` in the main scene's folder, so that the error about the
    /// missing file names a sensible place.
    pub fn resolve(&self, path: &Path) -> PathBuf {
        self.find(path).unwrap_or_else(|| match self.dirs.last() {
            Some(dir) if !path.is_absolute() => dir.join(path),
            _ => path.to_path_buf(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolver_prefers_prepended_folders() {
        let root = tempfile::tempdir().unwrap();
        let (a, b) = (root.path().join("a"), root.path().join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        std::fs::write(root.path().join("m.obj"), "").unwrap();
        std::fs::write(b.join("m.obj"), "").unwrap();
        std::fs::write(a.join("only-a.obj"), "").unwrap();
        let mut r = FileResolver::new(root.path());
        assert_eq!(r.resolve(Path::new("m.obj")), root.path().join("m.obj"));
        r.prepend(a.clone());
        r.prepend(b.clone());
        assert_eq!(r.dirs(), &[b.clone(), a.clone(), root.path().to_path_buf()]);
        assert_eq!(r.find(Path::new("m.obj")), Some(b.join("m.obj")));
        assert_eq!(r.find(Path::new("only-a.obj")), Some(a.join("only-a.obj")));
        assert_eq!(r.find(Path::new("missing.obj")), None);
        assert_eq!(r.resolve(Path::new("missing.obj")), root.path().join("missing.obj"));
        let absolute = a.join("only-a.obj");
        assert_eq!(r.find(&absolute), Some(absolute.clone()));
    }
}
