//! The data folder's free space. Storage failures stop the coordinator (the fail-stop rule of
//! docs/decisions/0017), so a full disk must never reach a commit:
//!
//! * below a reserve (`tessera serve --min-free-space`) the service takes no new work: a
//!   submission is refused with 507 and no tile is leased, while results already rendered are
//!   still accepted (a job leases no further than about 512 MiB past its merge frontier);
//! * a ballast file of [`BALLAST_BYTES`] is kept in the folder and removed when the disk is
//!   nearly full before a delete or a cancel, so that those commits, which give space back,
//!   find room even when something else filled the disk; it is made again once space is back.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Size of the ballast file: room for the commits of deletes and cancels.
pub const BALLAST_BYTES: u64 = 16 << 20;
const BALLAST: &str = "space-reserve.ballast";

/// Free bytes for an unprivileged process on the file system holding `dir`.
pub fn free_bytes(dir: &Path) -> std::io::Result<u64> {
    use std::os::unix::ffi::OsStrExt;
    let path = std::ffi::CString::new(dir.as_os_str().as_bytes()).map_err(std::io::Error::other)?;
    let mut stat: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: `path` is a NUL-terminated string and `stat` a valid out-parameter
    if unsafe { libc::statvfs(path.as_ptr(), &mut stat) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(stat.f_bavail as u64 * stat.f_frsize as u64)
}

/// The reserve of one data folder.
#[derive(Debug)]
pub struct Disk {
    dir: PathBuf,
    reserve: u64,
    /// Free space was below the reserve when last looked at (to log each change once).
    low: std::sync::atomic::AtomicBool,
}

/// What the data folder's disk has, for `GET /api/v1/server` and the dashboard.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Space {
    /// Free bytes.
    pub free_bytes: u64,
    /// The reserve.
    pub reserve_bytes: u64,
    /// Free space is below the reserve: no new work is taken.
    pub low: bool,
}

impl Disk {
    /// The reserve of `reserve` bytes on `dir`'s disk (0: none, and no ballast).
    pub fn open(dir: &Path, reserve: u64) -> Disk {
        let disk = Disk { dir: dir.to_path_buf(), reserve, low: Default::default() };
        disk.restore_ballast();
        disk
    }

    /// The disk's free space, if it can be read.
    pub fn space(&self) -> Option<Space> {
        let free_bytes = free_bytes(&self.dir).ok()?;
        Some(Space { free_bytes, reserve_bytes: self.reserve, low: free_bytes < self.reserve })
    }

    /// Why new work cannot be taken now, if free space is below the reserve.
    pub fn refusal(&self) -> Option<String> {
        let space = self.space()?;
        if self.low.swap(space.low, std::sync::atomic::Ordering::Relaxed) != space.low {
            match space.low {
                true => {
                    tracing::error!(free_mib = space.free_bytes >> 20, "disk below its reserve: no new work is taken")
                }
                false => tracing::info!(free_mib = space.free_bytes >> 20, "disk back above its reserve"),
            }
        }
        let space = Some(space).filter(|s| s.low)?;
        Some(format!(
            "the coordinator's disk has {} MiB free, below the {} MiB it keeps in reserve (tessera serve --min-free-space): delete finished jobs or free space, then retry",
            space.free_bytes >> 20,
            space.reserve_bytes >> 20
        ))
    }

    /// Gives the ballast's space back when the disk is nearly full, before a commit that frees
    /// space (a delete, a cancel).
    pub fn make_room(&self) {
        let nearly_full = free_bytes(&self.dir).is_ok_and(|f| f < 2 * BALLAST_BYTES);
        let path = self.dir.join(BALLAST);
        if self.reserve > 0 && nearly_full && path.exists() {
            match std::fs::remove_file(&path) {
                Ok(()) => tracing::warn!("disk nearly full: the ballast file was removed to make room"),
                Err(e) => tracing::error!(error = %e, "cannot remove the ballast file"),
            }
        }
    }

    /// Makes the ballast file again when it is missing and the disk has room above the reserve.
    pub fn restore_ballast(&self) {
        let path = self.dir.join(BALLAST);
        if self.reserve == 0 || path.exists() || !free_bytes(&self.dir).is_ok_and(|f| f > self.reserve + BALLAST_BYTES)
        {
            return;
        }
        // written, not sparse: the blocks must really be held
        let write = || -> std::io::Result<()> {
            let tmp = path.with_extension("tmp");
            let mut file = std::fs::File::create(&tmp)?;
            let zeros = vec![0u8; 1 << 20];
            for _ in 0..BALLAST_BYTES >> 20 {
                file.write_all(&zeros)?;
            }
            file.sync_all()?;
            std::fs::rename(&tmp, &path)
        };
        if let Err(e) = write() {
            tracing::warn!(error = %e, "cannot make the ballast file");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reserve_refuses_work_and_the_ballast_comes_and_goes() {
        let dir = tempfile::tempdir().unwrap();
        let free = free_bytes(dir.path()).unwrap();
        assert!(free > 0);
        let disk = Disk::open(dir.path(), 1 << 20);
        assert!(dir.path().join(BALLAST).metadata().is_ok_and(|m| m.len() == BALLAST_BYTES), "ballast made");
        assert_eq!(disk.refusal(), None);
        let full = Disk::open(dir.path(), u64::MAX / 2);
        let why = full.refusal().unwrap();
        assert!(why.contains("--min-free-space") && why.contains("MiB free"), "{why}");
        assert!(full.space().unwrap().low);
        let none = Disk::open(dir.path(), 0);
        assert_eq!(none.refusal(), None, "no reserve: never refused");
    }
}
