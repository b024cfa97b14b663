//! Scene bundles written to disk as they arrive: a submission's files go piece by piece into a
//! staging folder (the bundle unpacked), and the bundle's blob is then encoded from those files
//! while it is hashed, so no copy of the bundle is ever whole in memory. A staging folder that
//! is never finished is removed when its upload is dropped, or by the start-up sweep.
//!
//! A bundle holds at most [`MAX_BUNDLE_FILES`] files with paths of at most
//! [`MAX_PATH_BYTES`]: each file costs a folder entry and a multipart part, and 100 000
//! one-byte parts once took 20 s and left as many files behind.

use super::{JobService, ServiceError};
use crate::serve::storage::blobs::remove_all;
use std::collections::HashSet;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use tessera_common::bundle::safe_relative_path;

/// The most files a bundle may hold (a scene, its includes, meshes and textures).
pub const MAX_BUNDLE_FILES: usize = 10_000;
/// The longest path a bundle's file may have.
pub const MAX_PATH_BYTES: usize = 1024;

/// A bundle being received: [`JobService::begin_upload`], then [`BundleUpload::start_file`]
/// and [`BundleUpload::write`] for each file, then [`JobService::submit_upload`].
#[derive(Debug)]
pub struct BundleUpload {
    /// The staging folder, under the scenes folder (swept at start-up if left behind).
    dir: PathBuf,
    /// Path and length of every file so far, in arrival order.
    files: Vec<(String, u64)>,
    /// The paths of `files`, to find a repeat at once.
    paths: HashSet<String>,
    current: Option<BufWriter<File>>,
    total: u64,
    limit: u64,
}

impl JobService {
    /// A new upload, refused past `limit` bytes of file data in all.
    pub fn begin_upload(&self, limit: u64) -> Result<BundleUpload, ServiceError> {
        self.check_space()?;
        let dir = self.scenes_dir.join(format!("staging-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir)?;
        Ok(BundleUpload { dir, files: Vec::new(), paths: HashSet::new(), current: None, total: 0, limit })
    }
}

impl BundleUpload {
    /// Starts the next file of the bundle at `path` (relative, `/`-separated, as in a bundle).
    pub fn start_file(&mut self, path: &str) -> Result<(), ServiceError> {
        let invalid = ServiceError::InvalidArgument;
        self.close_current()?;
        if self.files.len() >= MAX_BUNDLE_FILES {
            return Err(invalid(format!("a bundle holds at most {MAX_BUNDLE_FILES} files")));
        }
        if path.len() > MAX_PATH_BYTES {
            return Err(invalid(format!("bundle file paths are at most {MAX_PATH_BYTES} bytes long")));
        }
        let relative = safe_relative_path(path)
            .ok_or_else(|| invalid(format!("bundle file path \"{path}\" must be relative without \"..\"")))?;
        if !self.paths.insert(path.to_string()) {
            return Err(invalid(format!("bundle has the file \"{path}\" twice")));
        }
        let target = self.dir.join(&relative);
        let clash = || invalid(format!("bundle file \"{path}\" clashes with another file's folder or name"));
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent).map_err(|_| clash())?;
        }
        let file = std::fs::OpenOptions::new().write(true).create_new(true).open(&target).map_err(|_| clash())?;
        self.current = Some(BufWriter::with_capacity(64 << 10, file));
        self.files.push((path.to_string(), 0));
        Ok(())
    }

    /// Appends `data` to the current file.
    pub fn write(&mut self, data: &[u8]) -> Result<(), ServiceError> {
        let (Some(file), Some((path, len))) = (self.current.as_mut(), self.files.last_mut()) else {
            return Err(ServiceError::InvalidArgument("bundle data before any file's path".into()));
        };
        self.total += data.len() as u64;
        if self.total > self.limit {
            return Err(ServiceError::TooLarge(format!(
                "the bundle exceeds this coordinator's limit of {} bytes (tessera serve --max-upload-mb), at file \"{path}\"",
                self.limit
            )));
        }
        file.write_all(data)?;
        *len += data.len() as u64;
        Ok(())
    }

    /// Bytes of file data received so far.
    pub fn total(&self) -> u64 {
        self.total
    }

    fn close_current(&mut self) -> Result<(), ServiceError> {
        if let Some(file) = self.current.take() {
            file.into_inner().map_err(|e| e.into_error())?;
        }
        Ok(())
    }

    /// Closes the last file and writes the bundle's blob to `blob_path` (the encoding of
    /// [`tessera_link::bundle::encode`], hashed on the way); returns its digest.
    pub(super) fn finish(&mut self, scene_path: &str, blob_path: &Path) -> Result<String, ServiceError> {
        let invalid = ServiceError::InvalidArgument;
        self.close_current()?;
        if safe_relative_path(scene_path).is_none() {
            return Err(invalid(format!("bundle scene path \"{scene_path}\" is not a relative path")));
        }
        if !self.paths.contains(scene_path) {
            return Err(invalid(format!("bundle has no file \"{scene_path}\" (the scene)")));
        }
        let mut out = HashingWriter {
            inner: BufWriter::with_capacity(1 << 20, File::create(blob_path)?),
            hash: Default::default(),
        };
        let open =
            |i: usize| File::open(self.dir.join(safe_relative_path(&self.files[i].0).expect("invariant: checked")));
        tessera_link::bundle::encode_to(scene_path, &self.files, open, &mut out)?;
        out.inner.into_inner().map_err(|e| e.into_error())?.sync_all()?;
        use sha2::Digest;
        Ok(hex::encode(out.hash.finalize()))
    }

    /// Moves the unpacked files to `dir` unless something is there already (the same bundle,
    /// unpacked by an earlier submission); the staging folder is gone either way.
    pub(super) fn unpack_to(&mut self, dir: &Path) -> Result<(), ServiceError> {
        if !dir.exists() && std::fs::rename(&self.dir, dir).is_ok() {
            return Ok(());
        }
        remove_all(&self.dir)?;
        Ok(())
    }
}

impl Drop for BundleUpload {
    fn drop(&mut self) {
        self.current = None;
        if let Err(e) = remove_all(&self.dir) {
            tracing::warn!(dir = %self.dir.display(), error = %e, "cannot remove a staging folder; the start-up sweep will");
        }
    }
}

/// Hashes what it writes ([`tessera_proto::blob_digest`] of the whole).
struct HashingWriter<W> {
    inner: W,
    hash: sha2::Sha256,
}

impl<W: Write> Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        use sha2::Digest;
        let n = self.inner.write(buf)?;
        self.hash.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::job::service::Bundle;
    use crate::serve::job::service_tests::{CFG, cornell};
    use tessera_common::settings::RenderSettings;

    fn staged(dir: &Path) -> usize {
        std::fs::read_dir(dir.join("scenes")).map_or(0, |d| {
            d.filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().starts_with("staging-")).count()
        })
    }

    /// Bad bundles are refused naming the file, and leave no staging folder behind; a good
    /// one streamed in pieces is stored under the digest of its message encoding.
    #[test]
    fn uploads_refuse_bad_bundles_and_store_good_ones_under_their_digest() {
        let dir = tempfile::tempdir().unwrap();
        let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
        let refused = |f: &dyn Fn(&mut BundleUpload) -> Result<(), ServiceError>| {
            let mut upload = svc.begin_upload(16).unwrap();
            let e = f(&mut upload).unwrap_err();
            drop(upload);
            assert_eq!(staged(dir.path()), 0, "a refused upload left its staging folder");
            e.to_string()
        };
        assert!(refused(&|u| u.write(b"x")).contains("before any file"));
        assert!(refused(&|u| u.start_file("../x")).contains("\"../x\" must be relative"));
        assert!(refused(&|u| u.start_file("/etc/passwd")).contains("must be relative"));
        let twice = refused(&|u| u.start_file("a").and_then(|()| u.start_file("a")));
        assert!(twice.contains("\"a\" twice"), "{twice}");
        let clash = refused(&|u| u.start_file("a").and_then(|()| u.start_file("a/b")));
        assert!(clash.contains("clashes"), "{clash}");
        let big = refused(&|u| u.start_file("a").and_then(|()| u.write(&[0; 10])).and_then(|()| u.write(&[0; 7])));
        assert!(big.contains("limit of 16 bytes") && big.contains("\"a\""), "{big}");

        let (bundle, _) = cornell();
        let mut upload = svc.begin_upload(u64::MAX).unwrap();
        upload.start_file("empty.txt").unwrap();
        upload.start_file("scene.xml").unwrap();
        for piece in bundle.files[0].1.chunks(100) {
            upload.write(piece).unwrap();
        }
        let settings = RenderSettings { spp: Some(1), ..Default::default() };
        let view = svc.submit_upload(upload, "scene.xml", settings.clone(), 0, None, 1_000).unwrap();
        let expected = Bundle {
            scene_path: "scene.xml".into(),
            files: vec![("empty.txt".into(), vec![]), bundle.files[0].clone()],
        };
        let digest = tessera_proto::blob_digest(&tessera_link::bundle::encode(&expected));
        assert_eq!(svc.blobs.get(&digest).unwrap(), Some(tessera_link::bundle::encode(&expected)), "{view:?}");
        assert!(svc.scenes_dir.join(&digest).join("empty.txt").exists());
        let missing = svc.begin_upload(u64::MAX).unwrap();
        let e = svc.submit_upload(missing, "scene.xml", settings, 0, None, 1_000).unwrap_err();
        assert!(e.to_string().contains("no file \"scene.xml\""), "{e}");
        assert_eq!(staged(dir.path()), 0);
    }
}
