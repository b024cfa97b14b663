//! The one error type of scene loading: every message names the file, and the line and column
//! where the fault is (line 0 when it concerns a whole file).
//!
//! A farm job's scene is loaded from a folder on the coordinator or a worker; its errors must
//! name the user's files, never that folder ([`SceneError::within`]).

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// A place in a scene or mesh file. The file's path is shared: a parsed scene holds one
/// location per node, and each owning a copy of a long path cost kilobytes a node.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    /// The file.
    pub file: Arc<Path>,
    /// 1-based line, 0 when unknown.
    pub line: u32,
    /// 1-based column, 0 when unknown.
    pub column: u32,
}

impl Location {
    /// A location in `file` at `line:column`.
    pub fn new(file: &Path, line: u32, column: u32) -> Self {
        Location { file: Arc::from(file), line, column }
    }

    /// A location in `file` at `line:column`, sharing the path.
    pub fn shared(file: &Arc<Path>, line: u32, column: u32) -> Self {
        Location { file: file.clone(), line, column }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (self.line, self.column) {
            (0, _) => write!(f, "{}", self.file.display()),
            (l, 0) => write!(f, "{}:{}", self.file.display(), l),
            (l, c) => write!(f, "{}:{}:{}", self.file.display(), l, c),
        }
    }
}

/// Why a scene could not be loaded.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[error("{location}: {message}")]
#[non_exhaustive]
pub struct SceneError {
    /// Where the fault is.
    pub location: Location,
    /// What is wrong, lowercase, naming the element or field.
    pub message: String,
}

impl SceneError {
    /// An error at `location`.
    pub fn at(location: &Location, message: impl Into<String>) -> Self {
        SceneError { location: location.clone(), message: message.into() }
    }

    /// An error about a whole file.
    pub fn file(file: &Path, message: impl Into<String>) -> Self {
        SceneError { location: Location::new(file, 0, 0), message: message.into() }
    }

    /// The error as the owner of the folder `root` (a job's bundle) should read it: its file
    /// named relative to `root`, and `root` removed from the message wherever a path in it
    /// shows it (the bundle itself reads `.`). Messages quote the names the scene wrote, but a
    /// name such as `.` or `a/..` resolves to the folder itself, and the operating system's
    /// messages may repeat a path.
    pub fn within(mut self, root: &Path) -> Self {
        let clean = super::resolver::normalize(root);
        for r in [root, clean.as_path()] {
            if let Ok(rel) = self.location.file.strip_prefix(r) {
                let rel = if rel.as_os_str().is_empty() { Path::new(".") } else { rel };
                self.location.file = Arc::from(rel);
                break;
            }
        }
        for r in [root.to_path_buf(), clean] {
            let text = r.display().to_string();
            if !text.is_empty() && text != "." {
                self.message = self.message.replace(&format!("{text}/"), "").replace(&text, ".");
            }
        }
        self
    }

    /// The file named by this error's location.
    pub fn path(&self) -> PathBuf {
        self.location.file.to_path_buf()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn within_names_files_inside_the_root_and_hides_the_root() {
        let root = Path::new("/srv/data/scenes/abc");
        let e = SceneError::file(&root.join("sub/scene.xml"), "cannot read /srv/data/scenes/abc/tex/x.png: no");
        let e = e.within(root);
        assert_eq!(e.to_string(), "sub/scene.xml: cannot read tex/x.png: no");
        let e = SceneError::file(Path::new("/srv/data/scenes/abc/./"), "/srv/data/scenes/abc is a directory");
        assert_eq!(e.within(root).to_string(), ".: . is a directory");
        let relative = Path::new("tessera-data/scenes/abc");
        let e = SceneError::file(&relative.join("./m.ply"), "x").within(relative);
        assert_eq!(e.to_string(), "m.ply: x");
    }
}
