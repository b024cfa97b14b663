//! The one error type of scene loading: every message names the file, and the line and column
//! where the fault is (line 0 when it concerns a whole file).

use std::fmt;
use std::path::{Path, PathBuf};

/// A place in a scene or mesh file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Location {
    /// The file.
    pub file: PathBuf,
    /// 1-based line, 0 when unknown.
    pub line: u32,
    /// 1-based column, 0 when unknown.
    pub column: u32,
}

impl Location {
    /// A location in `file` at `line:column`.
    pub fn new(file: &Path, line: u32, column: u32) -> Self {
        Location { file: file.to_path_buf(), line, column }
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
}
