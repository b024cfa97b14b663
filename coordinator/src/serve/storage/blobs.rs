//! The blob directory: content-addressed blobs (scene bundles, merge masks, result EXRs and
//! PNGs, named by [`tessera_proto::blob_digest`]) and checkpoints of merged films. Every file is
//! written to a temporary name, synced, renamed into place and its folder synced, so a crash
//! never leaves a half-written blob under a real name nor loses a rename that was reported
//! done; a blob is checked against its digest whenever it is read. Accepted tile results live in
//! the database (docs/decisions/0009-results-in-the-database.md), except large ones, which are
//! files under `results/<job>/` ([`BlobStore::put_result`], the same record): SQLite copies each
//! byte twice (its log, then the checkpoint of the log), a file once.
//!
//! Files go when the database stops naming them: a deleted job's files after the commit that
//! deletes its rows, and at start-up whatever a crash left between such a commit and the
//! removal (or between writing a file and committing its name): [`BlobStore::sweep`].

use std::collections::HashSet;
use std::io::Write;
use std::path::{Path, PathBuf};
use tessera_common::FORMAT_VERSION;
use tessera_common::film::Film;

/// The first word of a film checkpoint ("TSCK").
pub const CHECKPOINT_MAGIC: u32 = u32::from_le_bytes(*b"TSCK");

/// The fixed part of a checkpoint: its film's size and channels.
struct CheckpointHeader {
    flags: u32,
    width: u32,
    height: u32,
    /// Where the non-finite count is; the channels follow it.
    at: usize,
}

impl CheckpointHeader {
    /// From the checkpoint's first 20 bytes.
    fn parse(name: &str, bytes: &[u8]) -> std::io::Result<CheckpointHeader> {
        let word = |at: usize| -> std::io::Result<u32> {
            Ok(u32::from_le_bytes(
                bytes
                    .get(at..at + 4)
                    .ok_or_else(|| corrupt_checkpoint(name, "too short"))?
                    .try_into()
                    .expect("invariant: 4 bytes"),
            ))
        };
        if word(0)? != CHECKPOINT_MAGIC {
            return Err(corrupt_checkpoint(name, "not a checkpoint"));
        }
        if word(4)? != FORMAT_VERSION {
            let why = format!(
                "format version {}, written by another Tessera version (this one reads {FORMAT_VERSION})",
                word(4)?
            );
            return Err(corrupt_checkpoint(name, &why));
        }
        Ok(CheckpointHeader { flags: word(8)?, width: word(12)?, height: word(16)?, at: 20 })
    }

    fn weights(&self) -> bool {
        self.flags & 1 != 0
    }

    fn splats(&self) -> bool {
        self.flags & 2 != 0
    }

    /// Where the film ends and the trailer starts (`None` if that overflows).
    fn trailer(&self) -> Option<usize> {
        let per_pixel = 28 + if self.weights() { 8 } else { 0 } + if self.splats() { 24 } else { 0 };
        (self.width as usize * self.height as usize).checked_mul(per_pixel)?.checked_add(self.at + 8)
    }
}

fn corrupt_checkpoint(name: &str, why: &str) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidData, format!("checkpoint {name} is corrupt: {why}"))
}

/// Accepted results of at least this many bytes are stored as files instead of rows.
pub const RESULT_FILE_BYTES: usize = 1 << 20;

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
        std::fs::rename(&tmp, path)?;
        sync_parent(path)
    }

    /// Stores `bytes` content-addressed; returns the digest.
    pub fn put(&self, bytes: &[u8]) -> std::io::Result<String> {
        let digest = tessera_proto::blob_digest(bytes);
        self.put_digested(&digest, bytes)?;
        Ok(digest)
    }

    /// Stores `bytes` under `digest`, which the caller computed with
    /// [`tessera_proto::blob_digest`] (a bundle's digest is needed before it is stored).
    pub fn put_digested(&self, digest: &str, bytes: &[u8]) -> std::io::Result<()> {
        let path = self.cas_path(digest).ok_or_else(|| std::io::Error::other(format!("invalid digest {digest}")))?;
        debug_assert_eq!(tessera_proto::blob_digest(bytes), digest, "invariant: the digest is the bytes'");
        if !path.exists() {
            self.write_atomic(&path, bytes)?;
        }
        Ok(())
    }

    /// Deletes a content-addressed blob (nothing if it is not there).
    pub fn remove(&self, digest: &str) -> std::io::Result<()> {
        match self.cas_path(digest).map(std::fs::remove_file) {
            Some(Err(e)) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    /// Deletes every result file of a job.
    pub fn remove_results(&self, job: &str) -> std::io::Result<()> {
        remove_all(&self.root.join("results").join(job))
    }

    /// Stores an accepted result too large for a database row as a file (the non-finite
    /// count, then the payload), synced before this returns.
    pub fn put_result(
        &self,
        job: &str,
        tile: usize,
        epoch: u64,
        non_finite: u64,
        payload: &[u8],
    ) -> std::io::Result<()> {
        self.write_atomic_with(&self.result_path(job, tile, epoch), |w| {
            w.write_all(&non_finite.to_le_bytes())?;
            w.write_all(payload)
        })
    }

    /// Deletes one result file (a result stored, then not accepted).
    pub fn remove_result(&self, job: &str, tile: usize, epoch: u64) -> std::io::Result<()> {
        match std::fs::remove_file(self.result_path(job, tile, epoch)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    /// Deletes the result files of a job's tiles before `upto` (a committed checkpoint holds
    /// them); returns how many went.
    pub fn remove_results_below(&self, job: &str, upto: usize) -> std::io::Result<usize> {
        let entries = match std::fs::read_dir(self.root.join("results").join(job)) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
            Err(e) => return Err(e),
        };
        let mut removed = 0;
        for entry in entries {
            let entry = entry?;
            let name = entry.file_name().to_string_lossy().into_owned();
            let tile = name.split_once('-').and_then(|(t, _)| t.parse::<usize>().ok());
            if tile.is_some_and(|t| t < upto) {
                std::fs::remove_file(entry.path())?;
                removed += 1;
            }
        }
        Ok(removed)
    }

    /// Deletes every file that `live` does not name: content-addressed blobs, checkpoints,
    /// old result folders of jobs that are gone, and every temporary file (run at start-up,
    /// before anything writes). Returns how many entries went.
    pub fn sweep(&self, live: &Live) -> std::io::Result<usize> {
        let mut removed = 0;
        for shard in std::fs::read_dir(self.root.join("cas"))? {
            let shard = shard?.path();
            if !shard.is_dir() {
                continue;
            }
            for blob in std::fs::read_dir(&shard)? {
                let blob = blob?;
                if !live.blobs.contains(&*blob.file_name().to_string_lossy()) {
                    remove_all(&blob.path())?;
                    removed += 1;
                }
            }
        }
        for (sub, keep) in [("checkpoints", &live.checkpoints), ("results", &live.jobs), ("tmp", &HashSet::new())] {
            for entry in std::fs::read_dir(self.root.join(sub))? {
                let entry = entry?;
                if !keep.contains(&*entry.file_name().to_string_lossy()) {
                    remove_all(&entry.path())?;
                    removed += 1;
                }
            }
        }
        Ok(removed)
    }

    /// Where blob `digest` lives; `None` if `digest` is not a SHA-256 hex string.
    pub fn cas_path(&self, digest: &str) -> Option<PathBuf> {
        tessera_proto::is_blob_digest(digest).then(|| self.root.join("cas").join(&digest[..2]).join(digest))
    }

    /// A content-addressed blob opened for reading (`Ok(None)` when there is no such blob); the
    /// reader checks the bytes against the digest (see `grpc::stream_blob`).
    pub fn open_blob(&self, digest: &str) -> std::io::Result<Option<std::fs::File>> {
        let Some(path) = self.cas_path(digest) else { return Ok(None) };
        match std::fs::File::open(path) {
            Ok(f) => Ok(Some(f)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// A content-addressed blob; `Ok(None)` when there is no such blob, an error when the bytes
    /// on disk no longer match their digest.
    pub fn get(&self, digest: &str) -> std::io::Result<Option<Vec<u8>>> {
        let Some(path) = self.cas_path(digest) else { return Ok(None) };
        match std::fs::read(path) {
            Ok(b) if tessera_proto::blob_digest(&b) == digest => Ok(Some(b)),
            Ok(_) => Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!("blob {digest} is corrupt on disk (its bytes no longer match the digest)"),
            )),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    fn result_path(&self, job: &str, tile: usize, epoch: u64) -> PathBuf {
        self.root.join("results").join(job).join(format!("{tile}-{epoch}.bin"))
    }

    /// An accepted tile result's payload stored as a file by [`BlobStore::put_result`]
    /// (non-finite count, then the payload).
    pub fn get_result(&self, job: &str, tile: usize, epoch: u64) -> std::io::Result<Vec<u8>> {
        std::fs::read(self.result_path(job, tile, epoch))
    }

    /// Writes a checkpoint of `film` holding `tiles[..merged]`, followed by `trailer` (an EMIS
    /// state, or nothing); returns its file name. The format: [`CHECKPOINT_MAGIC`], a version,
    /// flags (weights, splats), width, height, the non-finite count, then the film's channels
    /// in the payload order (`tessera_link::payload`), then the trailer.
    pub fn put_checkpoint(&self, job: &str, merged: usize, film: &Film, trailer: &[u8]) -> std::io::Result<String> {
        let name = format!("{job}.{merged}.film");
        // streamed: a 4K film is 230 MB or more, not worth copying in memory first
        self.write_atomic_with(&self.root.join("checkpoints").join(&name), |w| {
            let flags = film.weight.is_some() as u32 | (film.splat.is_some() as u32) << 1;
            for word in [CHECKPOINT_MAGIC, FORMAT_VERSION, flags, film.width, film.height] {
                w.write_all(&word.to_le_bytes())?;
            }
            w.write_all(&film.non_finite.to_le_bytes())?;
            tessera_link::payload::write_channels(
                w,
                &film.sum,
                film.weight.as_deref(),
                film.splat.as_deref(),
                &film.count,
            )?;
            w.write_all(trailer)
        })?;
        Ok(name)
    }

    /// Reads a checkpoint written by [`BlobStore::put_checkpoint`]: the film and the trailer.
    pub fn get_checkpoint(&self, name: &str) -> std::io::Result<(Film, Vec<u8>)> {
        let bytes = std::fs::read(self.root.join("checkpoints").join(name))?;
        let h = CheckpointHeader::parse(name, &bytes)?;
        let bad = |why: &str| corrupt_checkpoint(name, why);
        let non_finite = u64::from_le_bytes(
            bytes.get(h.at..h.at + 8).ok_or_else(|| bad("too short"))?.try_into().expect("invariant: 8 bytes"),
        );
        let end = h.trailer().filter(|&n| n <= bytes.len()).ok_or_else(|| bad("too short for its size"))?;
        let pixels = h.width as usize * h.height as usize;
        let (sum, weight, splat, count) =
            tessera_link::payload::decode_channels(&bytes[h.at + 8..end], pixels, h.weights(), h.splats())
                .ok_or_else(|| bad("wrong size"))?;
        let (width, height) = (h.width, h.height);
        Ok((Film { width, height, sum, weight, splat, count, non_finite }, bytes[end..].to_vec()))
    }

    /// A checkpoint's file positioned at its trailer, the film left unread: a job that ended
    /// without outputs shows its EMIS decisions from the trailer's head.
    pub fn checkpoint_trailer(&self, name: &str) -> std::io::Result<std::fs::File> {
        use std::io::{Read, Seek};
        let mut file = std::fs::File::open(self.root.join("checkpoints").join(name))?;
        let mut head = Vec::with_capacity(24);
        (&mut file).take(24).read_to_end(&mut head)?;
        let end = CheckpointHeader::parse(name, &head)?.trailer();
        let end = end.filter(|&n| n as u64 <= file.metadata().map_or(0, |m| m.len()));
        file.seek(std::io::SeekFrom::Start(
            end.ok_or_else(|| corrupt_checkpoint(name, "too short for its size"))? as u64
        ))?;
        Ok(file)
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
        use sha2::Digest;
        let mut hash = sha2::Sha256::new();
        std::io::copy(&mut std::fs::File::open(path)?, &mut hash)?;
        let digest = hex::encode(hash.finalize());
        self.put_file_digested(path, &digest)?;
        Ok(digest)
    }

    /// Stores the file at `path`, whose digest the caller computed as it wrote the file, under
    /// that digest, moving it into place (or removing it when the blob is there already).
    pub fn put_file_digested(&self, path: &Path, digest: &str) -> std::io::Result<()> {
        let target = self.cas_path(digest).ok_or_else(|| std::io::Error::other(format!("invalid digest {digest}")))?;
        if target.exists() {
            std::fs::remove_file(path)?;
        } else {
            std::fs::File::open(path)?.sync_all()?;
            if let Some(dir) = target.parent() {
                std::fs::create_dir_all(dir)?;
            }
            std::fs::rename(path, &target)?;
            sync_parent(&target)?;
        }
        Ok(())
    }
}

/// What the database and the running jobs still name; [`BlobStore::sweep`] deletes the rest.
#[derive(Clone, Debug, Default)]
pub struct Live {
    /// Digests of content-addressed blobs (bundles, outputs, current merge masks).
    pub blobs: HashSet<String>,
    /// Checkpoint file names.
    pub checkpoints: HashSet<String>,
    /// Job ids (their old result folders stay).
    pub jobs: HashSet<String>,
}

/// Removes a file or a folder with its contents; nothing if it is not there.
pub fn remove_all(path: &Path) -> std::io::Result<()> {
    let removed = match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => std::fs::remove_dir_all(path),
        Ok(_) => std::fs::remove_file(path),
        Err(e) => Err(e),
    };
    match removed {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    }
}

/// Syncs the folder holding `path`, so that a rename into it survives a crash.
fn sync_parent(path: &Path) -> std::io::Result<()> {
    match path.parent() {
        Some(dir) => std::fs::File::open(dir)?.sync_all(),
        None => Ok(()),
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
        // a blob changed on disk is refused, not served
        std::fs::write(blobs.cas_path(&d).unwrap(), b"jello").unwrap();
        let err = blobs.get(&d).unwrap_err();
        assert!(err.to_string().contains("corrupt"), "{err}");
        let boxed = tessera_common::film::filter::Filter::BOX;
        let gaussian = tessera_common::film::filter::Filter::new(tessera_common::film::filter::FilterKind::DEFAULT);
        for (i, filter) in [boxed, gaussian].iter().enumerate() {
            let mut film = Film::for_filter(2, 1, filter);
            film.sum[1] = [0.5, 1.5, -0.0];
            film.count[1] = 3;
            film.non_finite = 2;
            if let Some(w) = &mut film.weight {
                w[1] = 0.75;
                film.splat = Some(vec![[1.0, 2.0, 3.0], [0.0; 3]]);
            }
            let name = blobs.put_checkpoint("job", 2 * i, &film, &[]).unwrap();
            assert_eq!(blobs.get_checkpoint(&name).unwrap(), (film.clone(), Vec::new()));
            let name = blobs.put_checkpoint("job", 2 * i + 1, &film, b"emis").unwrap();
            assert_eq!(blobs.get_checkpoint(&name).unwrap(), (film, b"emis".to_vec()));
        }
    }

    #[test]
    fn sweep_keeps_what_is_live_and_deletes_the_rest() {
        let dir = tempfile::tempdir().unwrap();
        let blobs = BlobStore::open(dir.path()).unwrap();
        let (kept, orphan) = (blobs.put(b"kept").unwrap(), blobs.put(b"orphan").unwrap());
        let film = Film::for_filter(1, 1, &tessera_common::film::filter::Filter::BOX);
        let (live_ck, old_ck) =
            (blobs.put_checkpoint("a", 2, &film, &[]).unwrap(), blobs.put_checkpoint("a", 1, &film, &[]).unwrap());
        for job in ["a", "gone"] {
            std::fs::create_dir_all(dir.path().join("results").join(job)).unwrap();
            std::fs::write(dir.path().join("results").join(job).join("0-0.bin"), b"r").unwrap();
        }
        std::fs::write(blobs.temp_path(".exr"), b"half-written").unwrap();
        let live = Live {
            blobs: [kept.clone()].into(),
            checkpoints: [live_ck.clone()].into(),
            jobs: ["a".to_string()].into(),
        };
        assert_eq!(blobs.sweep(&live).unwrap(), 4);
        assert_eq!(blobs.get(&kept).unwrap().as_deref(), Some(&b"kept"[..]));
        assert!(blobs.get(&orphan).unwrap().is_none());
        assert!(blobs.get_checkpoint(&live_ck).is_ok() && blobs.get_checkpoint(&old_ck).is_err());
        assert!(blobs.get_result("a", 0, 0).is_ok() && blobs.get_result("gone", 0, 0).is_err());
        assert_eq!(std::fs::read_dir(dir.path().join("tmp")).unwrap().count(), 0);
        assert_eq!(blobs.sweep(&live).unwrap(), 0, "nothing more to do");
        blobs.remove(&kept).unwrap();
        blobs.remove(&kept).unwrap();
        assert!(blobs.get(&kept).unwrap().is_none());
    }

    #[test]
    fn result_files_round_trip_and_go_once_a_checkpoint_holds_them() {
        let dir = tempfile::tempdir().unwrap();
        let blobs = BlobStore::open(dir.path()).unwrap();
        for (tile, epoch) in [(0, 0), (1, 2), (2, 0), (10, 1)] {
            blobs.put_result("a", tile, epoch, tile as u64 + 7, &vec![tile as u8; 3 << 20]).unwrap();
        }
        let read = blobs.get_result("a", 1, 2).unwrap();
        assert_eq!(read.len(), 8 + (3 << 20));
        assert_eq!((u64::from_le_bytes(read[..8].try_into().unwrap()), read[8]), (8, 1));
        assert!(blobs.get_result("a", 1, 1).is_err(), "another epoch is another result");
        // tile 10 is not below 2: "10-1.bin" must not read as tile 1
        assert_eq!(blobs.remove_results_below("a", 2).unwrap(), 2);
        assert!(blobs.get_result("a", 0, 0).is_err() && blobs.get_result("a", 2, 0).is_ok());
        assert!(blobs.get_result("a", 10, 1).is_ok());
        blobs.remove_result("a", 2, 0).unwrap();
        blobs.remove_result("a", 2, 0).unwrap();
        assert_eq!(blobs.remove_results_below("no-such-job", 5).unwrap(), 0);
        assert_eq!(std::fs::read_dir(dir.path().join("tmp")).unwrap().count(), 0);
    }

    #[test]
    fn checkpoints_round_trip_and_other_versions_and_corrupt_ones_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let blobs = BlobStore::open(dir.path()).unwrap();
        let mut film = Film::for_filter(
            2,
            1,
            &tessera_common::film::filter::Filter::new(tessera_common::film::filter::FilterKind::Box),
        );
        (film.sum[1], film.count[1], film.non_finite) = ([1.0, 2.0, 3.0], 7, 4);
        let name = blobs.put_checkpoint("job", 1, &film, b"tail").unwrap();
        let (back, trailer) = blobs.get_checkpoint(&name).unwrap();
        assert_eq!(
            (back.sum, back.count, back.non_finite, trailer),
            (film.sum.clone(), film.count.clone(), 4, b"tail".to_vec())
        );
        let path = dir.path().join("checkpoints").join(&name);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[4] = 9;
        std::fs::write(&path, &bytes).unwrap();
        let e = blobs.get_checkpoint(&name).unwrap_err().to_string();
        assert!(e.contains("format version 9") && e.contains("another Tessera version"), "{e}");
        // a file without the magic number (the box-only format of before checkpoints had one)
        std::fs::write(&path, &bytes[8..]).unwrap();
        assert!(blobs.get_checkpoint(&name).unwrap_err().to_string().contains("not a checkpoint"));
        std::fs::write(&path, &bytes[..20]).unwrap();
        assert!(blobs.get_checkpoint(&name).is_err());
    }
}
