//! The blob directory: content-addressed blobs (scene bundles, merge masks, result EXRs and
//! PNGs, named by [`tessera_proto::blob_digest`]) and checkpoints of merged films. Every file is
//! written to a temporary name and renamed into place, so a crash never leaves a half-written
//! blob under a real name. Accepted tile results live in the database
//! (docs/decisions/0009-results-in-the-database.md); [`BlobStore::get_result`] reads the result
//! files a data directory may still hold from before that.

use std::io::Write;
use std::path::{Path, PathBuf};
use tessera_common::film::Film;

/// Blob storage under one directory.
#[derive(Clone, Debug)]
pub struct BlobStore {
    root: PathBuf,
}

impl BlobStore {
    /// Opens (creating) the blob directory.
    pub fn open(root: &Path) -> std::io::Result<Self> {
        for sub in ["cas", "results", "checkpoints", "tmp"] {
            std::fs::create_dir_all(root.join(sub))?;
        }
        Ok(BlobStore { root: root.to_path_buf() })
    }

    fn write_atomic(&self, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
        self.write_atomic_with(path, |w| w.write_all(bytes))
    }

    /// [`BlobStore::write_atomic`] with the bytes produced by `write` (no copy in memory).
    fn write_atomic_with(
        &self,
        path: &Path,
        write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
    ) -> std::io::Result<()> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir)?;
        }
        let tmp = self.root.join("tmp").join(uuid::Uuid::new_v4().to_string());
        let mut f = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&tmp)?);
        write(&mut f)?;
        f.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        std::fs::rename(&tmp, path)
    }

    /// Stores `bytes` content-addressed; returns the digest.
    pub fn put(&self, bytes: &[u8]) -> std::io::Result<String> {
        let digest = tessera_proto::blob_digest(bytes);
        let path = self.cas_path(&digest).expect("invariant: blob_digest gives a valid digest");
        if !path.exists() {
            self.write_atomic(&path, bytes)?;
        }
        Ok(digest)
    }

    /// Where blob `digest` lives; `None` if `digest` is not a SHA-256 hex string.
    pub fn cas_path(&self, digest: &str) -> Option<PathBuf> {
        tessera_proto::is_blob_digest(digest).then(|| self.root.join("cas").join(&digest[..2]).join(digest))
    }

    /// A content-addressed blob; `Ok(None)` when there is no such blob.
    pub fn get(&self, digest: &str) -> std::io::Result<Option<Vec<u8>>> {
        let Some(path) = self.cas_path(digest) else { return Ok(None) };
        match std::fs::read(path) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    fn result_path(&self, job: &str, tile: usize, epoch: u64) -> PathBuf {
        self.root.join("results").join(job).join(format!("{tile}-{epoch}.bin"))
    }

    /// An accepted tile result's payload stored as a file (non-finite count, then
    /// the payload).
    pub fn get_result(&self, job: &str, tile: usize, epoch: u64) -> std::io::Result<Vec<u8>> {
        std::fs::read(self.result_path(job, tile, epoch))
    }

    /// Writes a checkpoint of `film` holding `tiles[..merged]`, followed by `trailer` (an EMIS
    /// state, or nothing); returns its file name.
    pub fn put_checkpoint(&self, job: &str, merged: usize, film: &Film, trailer: &[u8]) -> std::io::Result<String> {
        let name = format!("{job}.{merged}.film");
        // streamed in the payload layout (`tessera_proto::encode_tile_payload`): a 4K film is
        // 230 MB, which is not worth copying in memory first
        self.write_atomic_with(&self.root.join("checkpoints").join(&name), |w| {
            w.write_all(&film.width.to_le_bytes())?;
            w.write_all(&film.height.to_le_bytes())?;
            w.write_all(&film.non_finite.to_le_bytes())?;
            for s in &film.sum {
                for c in s {
                    w.write_all(&c.to_le_bytes())?;
                }
            }
            for c in &film.count {
                w.write_all(&c.to_le_bytes())?;
            }
            w.write_all(trailer)
        })?;
        Ok(name)
    }

    /// Reads a checkpoint written by [`BlobStore::put_checkpoint`]: the film and the trailer.
    pub fn get_checkpoint(&self, name: &str) -> std::io::Result<(Film, Vec<u8>)> {
        let bytes = std::fs::read(self.root.join("checkpoints").join(name))?;
        let bad = || std::io::Error::new(std::io::ErrorKind::InvalidData, format!("checkpoint {name} is corrupt"));
        if bytes.len() < 16 {
            return Err(bad());
        }
        let width = u32::from_le_bytes(bytes[0..4].try_into().map_err(|_| bad())?);
        let height = u32::from_le_bytes(bytes[4..8].try_into().map_err(|_| bad())?);
        let non_finite = u64::from_le_bytes(bytes[8..16].try_into().map_err(|_| bad())?);
        let film_bytes = (width as usize * height as usize)
            .checked_mul(tessera_proto::RESULT_BYTES_PER_PIXEL)
            .and_then(|n| n.checked_add(16))
            .filter(|&n| n <= bytes.len())
            .ok_or_else(bad)?;
        let (sum, count) = tessera_proto::decode_tile_payload(&bytes[16..film_bytes], width as usize * height as usize)
            .ok_or_else(bad)?;
        Ok((Film { width, height, sum, count, non_finite }, bytes[film_bytes..].to_vec()))
    }

    /// Deletes a superseded checkpoint.
    pub fn remove_checkpoint(&self, name: &str) {
        let _ = std::fs::remove_file(self.root.join("checkpoints").join(name));
    }

    /// A fresh path for temporary files (e.g. an EXR written by a library before hashing).
    pub fn temp_path(&self, suffix: &str) -> PathBuf {
        self.root.join("tmp").join(format!("{}{suffix}", uuid::Uuid::new_v4()))
    }

    /// Stores the file at `path` content-addressed, moving it into place; returns the digest.
    pub fn put_file(&self, path: &Path) -> std::io::Result<String> {
        let digest = tessera_proto::blob_digest(&std::fs::read(path)?);
        let target = self.cas_path(&digest).expect("invariant: blob_digest gives a valid digest");
        if target.exists() {
            std::fs::remove_file(path)?;
        } else {
            std::fs::File::open(path)?.sync_all()?;
            if let Some(dir) = target.parent() {
                std::fs::create_dir_all(dir)?;
            }
            std::fs::rename(path, &target)?;
        }
        Ok(digest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blobs_are_content_addressed_and_checkpoints_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let blobs = BlobStore::open(dir.path()).unwrap();
        let d = blobs.put(b"hello").unwrap();
        assert_eq!(d, "2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824");
        assert_eq!(blobs.get(&d).unwrap().unwrap(), b"hello");
        assert!(blobs.get("../../etc/passwd").unwrap().is_none());
        let mut film = Film::new(2, 1);
        film.sum[1] = [0.5, 1.5, -0.0];
        film.count[1] = 3;
        film.non_finite = 2;
        let name = blobs.put_checkpoint("job", 1, &film, &[]).unwrap();
        assert_eq!(blobs.get_checkpoint(&name).unwrap(), (film.clone(), Vec::new()));
        let name = blobs.put_checkpoint("job", 2, &film, b"emis").unwrap();
        assert_eq!(blobs.get_checkpoint(&name).unwrap(), (film, b"emis".to_vec()));
    }
}
