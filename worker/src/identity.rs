//! The identity a worker keeps in its cache folder: an id and a secret, so that a restarted
//! worker registers as the same worker and its failures and blocklists follow it. Several
//! workers may share one cache folder: each holds an exclusive lock on one identity slot for
//! as long as it runs, and takes the first slot no live process holds.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, Write};
use std::path::Path;

/// Identity slots per cache folder (as many workers may share it).
const SLOTS: usize = 256;

/// A kept identity; the lock on its file lasts as long as this value.
#[derive(Debug)]
pub struct Identity {
    /// The worker id.
    pub id: String,
    /// Proves the id is this worker's.
    pub secret: String,
    _lock: File,
}

/// Why no identity could be kept.
#[derive(Debug, thiserror::Error)]
pub enum IdentityError {
    /// The folder or a slot file cannot be used.
    #[error("worker identity in {path}: {source}")]
    Io {
        /// The file or folder.
        path: String,
        /// What failed.
        source: std::io::Error,
    },
    /// Every slot is held by a running worker.
    #[error("all {SLOTS} worker identities in {0} are held by running workers")]
    AllHeld(String),
}

impl Identity {
    /// Takes the first identity slot in `dir` no running worker holds, creating its id and
    /// secret when the slot is new.
    pub fn keep(dir: &Path) -> Result<Identity, IdentityError> {
        let io = |path: &Path| {
            let path = path.display().to_string();
            move |source| IdentityError::Io { path, source }
        };
        let dir = dir.join("identity");
        std::fs::create_dir_all(&dir).map_err(io(&dir))?;
        for slot in 0..SLOTS {
            let path = dir.join(format!("worker-{slot}"));
            let mut file = OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(io(&path))?;
            match file.try_lock() {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => continue,
                Err(std::fs::TryLockError::Error(e)) => return Err(io(&path)(e)),
            }
            let mut text = String::new();
            file.read_to_string(&mut text).map_err(io(&path))?;
            if let Some((id, secret)) = parse(&text) {
                return Ok(Identity { id, secret, _lock: file });
            }
            // new (or unreadable) slot: a fresh identity, written before it is used
            let (id, secret) = (
                uuid::Uuid::new_v4().to_string(),
                format!("{}{}", uuid::Uuid::new_v4().simple(), uuid::Uuid::new_v4().simple()),
            );
            file.set_len(0).map_err(io(&path))?;
            file.rewind().map_err(io(&path))?;
            file.write_all(format!("{id}\n{secret}\n").as_bytes()).map_err(io(&path))?;
            file.sync_all().map_err(io(&path))?;
            return Ok(Identity { id, secret, _lock: file });
        }
        Err(IdentityError::AllHeld(dir.display().to_string()))
    }
}

fn parse(text: &str) -> Option<(String, String)> {
    let mut lines = text.lines();
    let (id, secret) = (lines.next()?.trim(), lines.next()?.trim());
    let ok = !id.is_empty() && id.len() <= 64 && secret.len() >= 16;
    ok.then(|| (id.to_string(), secret.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_identity_is_kept_across_restarts_and_not_shared_while_held() {
        let dir = tempfile::tempdir().unwrap();
        let first = Identity::keep(dir.path()).unwrap();
        let second = Identity::keep(dir.path()).unwrap();
        assert_ne!(first.id, second.id, "two running workers never share an identity");
        let (id, secret) = (first.id.clone(), first.secret.clone());
        drop(first);
        let restarted = Identity::keep(dir.path()).unwrap();
        assert_eq!((restarted.id, restarted.secret), (id, secret), "a restart keeps its identity");
        assert!(second.secret.len() >= 32);
    }
}
