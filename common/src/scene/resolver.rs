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
//! A farm job's resolver is *confined* to the job's bundle: absolute names, names that lead out
//! of the bundle through `..`, symbolic links and anything but regular files and folders are
//! refused with the reason ([`FileResolver::refusal`]), and never found
//! (`docs/decisions/0015-limits-on-hostile-input.md`).
//!
//! ```
//! use std::path::Path;
//! use tessera_common::scene::FileResolver;
//! let mut resolver = FileResolver::new(Path::new("scenes/cornell-box"));
//! resolver.prepend(Path::new("scenes/cornell-box/meshes").to_path_buf());
//! // nothing exists under these names: the fallback is the scene's own folder
//! assert_eq!(resolver.resolve(Path::new("none.obj")), Path::new("scenes/cornell-box/none.obj"));
//! ```

use std::path::{Component, Path, PathBuf};

/// An ordered list of folders searched for relative filenames.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileResolver {
    /// Searched first to last; the last is the main scene's folder.
    dirs: Vec<PathBuf>,
    /// The folder every file must lie in (a job's bundle), if confined.
    root: Option<PathBuf>,
}

impl FileResolver {
    /// A resolver searching only `scene_dir`.
    pub fn new(scene_dir: &Path) -> Self {
        FileResolver { dirs: vec![scene_dir.to_path_buf()], root: None }
    }

    /// A resolver searching `scene_dir` that finds only files inside `root`.
    pub fn confined(scene_dir: &Path, root: &Path) -> Self {
        FileResolver { dirs: vec![scene_dir.to_path_buf()], root: Some(root.to_path_buf()) }
    }

    /// Why a confined resolver refuses the scene's file name `name` (a phrase to follow the
    /// quoted name), or `None` when it may be looked up. An unconfined resolver refuses nothing.
    pub fn refusal(&self, name: &Path) -> Option<String> {
        let root = self.root.as_ref()?;
        if name.is_absolute() {
            return Some("is an absolute path; a job's scene can only name files inside its bundle".into());
        }
        self.dirs.iter().find_map(|dir| inside(root, &dir.join(name)).err())
    }

    /// `<path>`'s folder `dir` (already joined to where it is looked for): the reason it is
    /// refused, as [`FileResolver::refusal`].
    pub fn refusal_of_folder(&self, dir: &Path) -> Option<String> {
        inside(self.root.as_ref()?, dir).err()
    }

    /// Whether the resolver is confined to a bundle.
    pub fn is_confined(&self) -> bool {
        self.root.is_some()
    }

    /// [`FileResolver::resolve`] after [`FileResolver::refusal`].
    pub fn resolve_checked(&self, name: &Path) -> Result<PathBuf, String> {
        match self.refusal(name) {
            Some(why) => Err(why),
            None => Ok(self.resolve(name)),
        }
    }

    /// Searches `dir` before every folder already in the list.
    pub fn prepend(&mut self, dir: PathBuf) {
        self.dirs.insert(0, dir);
    }

    /// The folders in search order.
    pub fn dirs(&self) -> &[PathBuf] {
        &self.dirs
    }

    /// The first existing `dir/path` in search order; an absolute `path` if it exists. A
    /// confined resolver finds only what it does not refuse.
    pub fn find(&self, path: &Path) -> Option<PathBuf> {
        if let Some(root) = &self.root {
            if path.is_absolute() {
                return None;
            }
            return self.dirs.iter().filter_map(|dir| inside(root, &dir.join(path)).ok()).find(|c| c.exists());
        }
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

/// `path` with `.` dropped and `name/..` pairs removed, without touching the file system.
pub(crate) fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir if matches!(out.components().next_back(), Some(Component::Normal(_))) => {
                out.pop();
            }
            other => out.push(other),
        }
    }
    out
}

/// `path` normalised, if it stays inside `root`, and then only if no part of it below `root` is
/// a symbolic link or something other than a file or folder.
fn inside(root: &Path, path: &Path) -> Result<PathBuf, String> {
    let (clean, mut at) = (normalize(path), normalize(root));
    let Ok(below) = clean.strip_prefix(&at) else { return Err("leads outside the job's bundle".into()) };
    let below = below.to_path_buf();
    for c in below.components() {
        at.push(c);
        let Ok(meta) = std::fs::symlink_metadata(&at) else { break };
        if meta.file_type().is_symlink() {
            return Err("is (or passes through) a symbolic link, which a job's bundle cannot hold".into());
        }
        if !meta.is_file() && !meta.is_dir() {
            return Err("is not a regular file".into());
        }
    }
    Ok(clean)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A confined resolver refuses every way out of its bundle and finds what is inside.
    #[test]
    fn confined_resolver_stays_inside_the_bundle() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().join("bundle");
        std::fs::create_dir_all(root.join("scene/meshes")).unwrap();
        std::fs::write(root.join("scene/meshes/m.obj"), "").unwrap();
        std::fs::write(root.join("shared.obj"), "").unwrap();
        std::fs::write(tmp.path().join("secret.obj"), "").unwrap();
        std::os::unix::fs::symlink(tmp.path().join("secret.obj"), root.join("scene/link.obj")).unwrap();
        let r = FileResolver::confined(&root.join("scene"), &root);
        assert_eq!(r.find(Path::new("meshes/m.obj")), Some(root.join("scene/meshes/m.obj")));
        assert_eq!(r.refusal(Path::new("../shared.obj")), None);
        assert_eq!(r.find(Path::new("../shared.obj")), Some(root.join("shared.obj")));
        assert_eq!(r.find(Path::new("meshes/./../meshes/m.obj")), Some(root.join("scene/meshes/m.obj")));
        for (name, why) in [
            ("/dev/zero", "absolute"),
            ("../../secret.obj", "outside"),
            ("meshes/../../../secret.obj", "outside"),
            ("link.obj", "symbolic link"),
        ] {
            let refusal = r.refusal(Path::new(name)).unwrap_or_else(|| panic!("{name} accepted"));
            assert!(refusal.contains(why), "{name}: {refusal}");
            assert_eq!(r.find(Path::new(name)), None, "{name}");
            assert!(r.resolve_checked(Path::new(name)).is_err(), "{name}");
        }
        let open = FileResolver::new(&root.join("scene"));
        assert_eq!(open.refusal(Path::new("/dev/zero")), None);
        assert_eq!(open.find(Path::new("../../secret.obj")), Some(root.join("scene/../../secret.obj")));
    }

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
