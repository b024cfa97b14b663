//! The mesh files of a scene while it is built: each file is read once, and each distinct
//! content (file bytes, format and mesh index) parsed once, however many shapes name it.
//! Every shape still holds its own copy in world space, so the scene's triangles are counted
//! against [`SceneLimits::max_triangles`](super::SceneLimits) before a copy is made: twenty
//! shapes naming one 1.4 MB mesh used to load it twenty times, and a few hundred bytes of XML
//! could ask for any number of copies.

use super::error::{Location, SceneError};
use super::load::{obj::load_obj_bytes, ply::load_ply_bytes, serialized::load_serialized_bytes};
use super::shape::Mesh;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// What identifies a parsed mesh: the file's SHA-256, its format and the mesh's index in it.
type Key = ([u8; 32], &'static str, u32);

/// Meshes read so far, and the triangles the scene's shapes hold.
pub(super) struct MeshFiles {
    /// Each file's digest, and its bytes while more of its meshes may be asked for (a
    /// `serialized` file holds several).
    files: HashMap<PathBuf, ([u8; 32], Option<Arc<Vec<u8>>>)>,
    meshes: HashMap<Key, Arc<Mesh>>,
    triangles: u64,
    max_triangles: u64,
}

impl MeshFiles {
    pub(super) fn new(max_triangles: u64) -> Self {
        MeshFiles { files: HashMap::new(), meshes: HashMap::new(), triangles: 0, max_triangles }
    }

    /// The mesh `index` of the `format` (`obj`, `ply`, `serialized`) file at `path`, as
    /// parsed (object space, as stored).
    pub(super) fn load(&mut self, path: &Path, format: &str, index: u32) -> Result<Arc<Mesh>, SceneError> {
        let format: &'static str = match format {
            "obj" => "obj",
            "ply" => "ply",
            _ => "serialized",
        };
        let (digest, bytes) = self.read(path, format == "serialized")?;
        let key = (digest, format, index);
        if let Some(mesh) = self.meshes.get(&key) {
            return Ok(mesh.clone());
        }
        let bytes = match bytes {
            Some(b) => b,
            // read before under another format: rare enough to read again
            None => Arc::new(std::fs::read(path).map_err(|e| cannot_read(path, e))?),
        };
        let mesh = Arc::new(match format {
            "obj" => load_obj_bytes(path, &bytes)?,
            "ply" => load_ply_bytes(path, &bytes)?,
            _ => load_serialized_bytes(path, &bytes, index)?,
        });
        self.meshes.insert(key, mesh.clone());
        Ok(mesh)
    }

    /// The digest of the file at `path`, reading it the first time (bytes then returned, and
    /// kept when `keep`).
    fn read(&mut self, path: &Path, keep: bool) -> Result<([u8; 32], Option<Arc<Vec<u8>>>), SceneError> {
        let key = super::resolver::normalize(path);
        if let Some((digest, bytes)) = self.files.get(&key) {
            return Ok((*digest, bytes.clone()));
        }
        let bytes = Arc::new(std::fs::read(path).map_err(|e| cannot_read(path, e))?);
        let digest: [u8; 32] = Sha256::digest(bytes.as_slice()).into();
        self.files.insert(key, (digest, keep.then(|| bytes.clone())));
        Ok((digest, Some(bytes)))
    }

    /// Counts `triangles` more for the shape at `at`; fails past the scene's limit.
    pub(super) fn count(&mut self, triangles: usize, at: &Location) -> Result<(), SceneError> {
        self.triangles = self.triangles.saturating_add(triangles as u64);
        if self.triangles > self.max_triangles {
            return Err(SceneError::at(
                at,
                format!(
                    "the scene's shapes hold more than {} triangles, the limit this scene is loaded with",
                    self.max_triangles
                ),
            ));
        }
        Ok(())
    }
}

fn cannot_read(path: &Path, e: std::io::Error) -> SceneError {
    SceneError::file(path, format!("cannot read mesh: {e}"))
}
