//! Scene bundles cached on disk by digest (fetched once through `FetchBlob`, verified against
//! their SHA-256, unpacked into `<cache>/<digest>/`) and loaded scenes kept in memory for the
//! few most recent (bundle, defines) pairs; also the current EMIS merge mask (a blob too).
//!
//! The folder is kept under a size limit (`--cache-limit`): each use of a bundle touches its
//! `.scene_path` marker, and after a new bundle is unpacked the least recently used others are
//! deleted until the rest fit ([`evict`]). The bundle being loaded is never deleted; other
//! bundles are not needed once their scene is loaded, since a scene is read into memory whole.
//! The marker's time is the recency, so worker processes sharing a folder share one LRU order.

use crate::client::Client;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::SystemTime;
use tessera_common::bundle::{Bundle, safe_relative_path};
use tessera_common::scene::{LoadOptions, Scene, SceneLimits};
use tessera_common::settings::WorkLimits;
use tessera_common::texture::TextureLimits;
use tessera_proto::v1 as pb;
use tokio_stream::StreamExt;

/// Loaded scenes kept in memory.
const KEEP_LOADED: usize = 4;

/// `--cache-limit` unless given: MiB of unpacked bundles kept on disk.
pub const DEFAULT_CACHE_LIMIT_MIB: u64 = 4096;

/// The file in a bundle's folder naming its scene file; it is written last, so a folder with
/// it is complete, and its modification time is the bundle's last use.
const MARKER: &str = ".scene_path";

/// A loaded scene's identity: `DIGEST/SCENE_PATH` and the sorted defines.
type SceneKey = (String, Vec<(String, String)>);

/// The cache.
pub struct SceneCache {
    dir: PathBuf,
    /// Bytes of unpacked bundles kept on disk.
    limit_bytes: u64,
    loaded: Vec<(SceneKey, Arc<Scene>)>,
    /// The current EMIS merge mask.
    pub masks: MaskCache,
    limits: SceneLimits,
    /// What a tile of a job may ask of this worker, checked once its scene is loaded.
    pub work_limits: WorkLimits,
}

impl SceneCache {
    /// A cache under `dir` holding at most `limit_bytes` of unpacked bundles (besides the one
    /// in use); trims what an earlier run left over the limit.
    pub fn new(dir: PathBuf, texture_budget_mib: Option<u64>, max_triangles: u64, limit_bytes: u64) -> Self {
        let textures = texture_budget_mib.map_or_else(TextureLimits::default, |mib| TextureLimits::total(mib << 20));
        let limits = SceneLimits { textures, max_triangles };
        if let Err(e) = evict(&dir, limit_bytes, &HashSet::new()) {
            tracing::warn!(error = %e, "cannot trim the scene cache");
        }
        match remove_leftovers(&dir, LEFTOVER_AGE) {
            Ok(0) => {}
            Ok(n) => tracing::info!(folders = n, "removed unfinished unpackings of killed workers"),
            Err(e) => tracing::warn!(error = %e, "cannot remove unfinished unpackings"),
        }
        SceneCache {
            dir,
            limit_bytes,
            loaded: Vec::new(),
            masks: MaskCache::default(),
            limits,
            work_limits: WorkLimits::default(),
        }
    }

    /// The scene `scene_path` of bundle `digest` (empty: the bundle's own) loaded with
    /// `defines`, fetching and unpacking the bundle if needed.
    pub async fn get(
        &mut self,
        client: &mut Client,
        digest: &str,
        scene_path: &str,
        defines: &HashMap<String, String>,
    ) -> anyhow::Result<Arc<Scene>> {
        let mut key_defines: Vec<_> = defines.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
        key_defines.sort();
        let key = (format!("{digest}/{scene_path}"), key_defines);
        if let Some((_, scene)) = self.loaded.iter().find(|(k, _)| *k == key) {
            touch(&self.dir, digest);
            return Ok(scene.clone());
        }
        let own_scene = self.unpack_retrying(client, digest).await?;
        let scene_file = match scene_path {
            "" => own_scene,
            path => self.dir.join(digest).join(
                tessera_common::bundle::safe_relative_path(path)
                    .ok_or_else(|| anyhow::anyhow!("unsafe scene path {path:?}"))?,
            ),
        };
        touch(&self.dir, digest);
        // the scene may name only files of its own bundle, whatever the coordinator checked
        let options =
            LoadOptions { defines: defines.clone(), limits: self.limits, confine_to: Some(self.dir.join(digest)) };
        let scene = tokio::task::spawn_blocking(move || Scene::load_options(&scene_file, &options)).await??;
        let scene = Arc::new(scene);
        self.loaded.push((key, scene.clone()));
        if self.loaded.len() > KEEP_LOADED {
            self.loaded.remove(0);
        }
        Ok(scene)
    }

    /// [`SceneCache::unpack`], tried again after a pause when it failed in a way that may pass
    /// (the cache's disk, a blob corrupted in transit), so that a passing fault of this worker
    /// does not count as a failure of the tiles it holds.
    async fn unpack_retrying(&self, client: &mut Client, digest: &str) -> anyhow::Result<PathBuf> {
        let mut pauses = UNPACK_RETRY_PAUSES.iter();
        loop {
            match self.unpack(client, digest).await {
                Err(e) if may_pass(&e) => match pauses.next() {
                    Some(&pause) => {
                        tracing::warn!(bundle = digest, error = %format!("{e:#}"), retry_in_ms = pause.as_millis() as u64, "cannot unpack the bundle");
                        tokio::time::sleep(pause).await;
                    }
                    None => return Err(e),
                },
                other => return other,
            }
        }
    }

    /// Makes sure the bundle is unpacked; returns the scene file's path.
    async fn unpack(&self, client: &mut Client, digest: &str) -> anyhow::Result<PathBuf> {
        if !tessera_proto::is_blob_digest(digest) {
            anyhow::bail!("invalid bundle digest {digest:?}");
        }
        let dir = self.dir.join(digest);
        if let Ok(p) = std::fs::read_to_string(dir.join(MARKER)) {
            return Ok(dir.join(p));
        }
        let bytes = fetch_verified(client, digest).await?;
        let bundle = tessera_link::bundle::decode(&bytes)?;
        let (cache_dir, limit) = (self.dir.clone(), self.limit_bytes);
        let digest = digest.to_string();
        tokio::task::spawn_blocking(move || -> anyhow::Result<PathBuf> {
            let scene = write_bundle(&cache_dir, &digest, &bundle)?;
            match evict(&cache_dir, limit, &HashSet::from([digest.as_str()])) {
                Ok(gone) if !gone.is_empty() => tracing::info!(bundles = gone.len(), "scene cache trimmed"),
                Ok(_) => {}
                Err(e) => tracing::warn!(error = %e, "cannot trim the scene cache"),
            }
            Ok(scene)
        })
        .await?
    }
}

/// Pauses before unpacking a bundle again after a fault that may pass.
const UNPACK_RETRY_PAUSES: [std::time::Duration; 2] =
    [std::time::Duration::from_millis(500), std::time::Duration::from_secs(2)];

/// A fetched blob whose bytes do not match its digest.
#[derive(Debug, thiserror::Error)]
#[error("blob {0} arrived corrupted (digest mismatch)")]
struct Corrupted(String);

/// Whether an unpacking failure may pass when tried again: a local I/O error or a corrupted
/// transfer, not a bad bundle nor a refusal by the coordinator.
fn may_pass(e: &anyhow::Error) -> bool {
    e.chain().any(|c| c.is::<std::io::Error>() || c.is::<Corrupted>())
}

/// A blob fetched by digest and checked against it.
async fn fetch_verified(client: &mut Client, digest: &str) -> anyhow::Result<Vec<u8>> {
    let mut stream = client
        .inner
        .fetch_blob(client.request(pb::FetchBlobRequest { digest: digest.to_string() }))
        .await?
        .into_inner();
    let mut bytes = Vec::new();
    while let Some(chunk) = stream.next().await {
        bytes.extend_from_slice(&chunk?.data);
    }
    if tessera_proto::blob_digest(&bytes) != digest {
        return Err(Corrupted(digest.to_string()).into());
    }
    Ok(bytes)
}

/// The most recent EMIS masks (merge probabilities, connection counts), kept in memory: every
/// tile of a pass uses the same ones.
#[derive(Default)]
pub struct MaskCache {
    recent: Vec<(String, Arc<Vec<f32>>)>,
}

/// Masks a pass may use at once: its merge mask and its connection mask.
const MASKS_KEPT: usize = 2;

impl MaskCache {
    /// The `what` mask of blob `digest`: `pixels` little-endian f32, each within `range`.
    pub async fn get(
        &mut self,
        client: &mut Client,
        digest: &str,
        pixels: usize,
        what: &str,
        range: std::ops::RangeInclusive<f32>,
    ) -> anyhow::Result<Arc<Vec<f32>>> {
        if let Some((_, mask)) = self.recent.iter().find(|(d, _)| d == digest) {
            return Ok(mask.clone());
        }
        let bytes = fetch_verified(client, digest).await?;
        let mask =
            tessera_link::mask::decode(&bytes, pixels).map_err(|e| anyhow::anyhow!("{what} {digest} has {e}"))?;
        if mask.iter().any(|v| !range.contains(v)) {
            anyhow::bail!("{what} {digest} has values outside [{}, {}]", range.start(), range.end());
        }
        let mask = Arc::new(mask);
        if self.recent.len() >= MASKS_KEPT {
            self.recent.remove(0);
        }
        self.recent.push((digest.to_string(), mask.clone()));
        Ok(mask)
    }
}

/// Unpacks `bundle` into `<cache>/<digest>/`; returns its scene file. Files are written into a
/// folder of a unique name and renamed into place, so that workers sharing the cache (even ones
/// with equal process ids, as in containers) never see each other's half-written folders: the
/// loser of a race drops its copy and uses the winner's.
fn write_bundle(cache: &Path, digest: &str, bundle: &Bundle) -> anyhow::Result<PathBuf> {
    let scene_rel = safe_relative_path(&bundle.scene_path)
        .ok_or_else(|| anyhow::anyhow!("unsafe scene path {:?}", bundle.scene_path))?;
    let tmp = tempfile::Builder::new().prefix(&format!(".{digest}.")).tempdir_in(cache)?;
    for (path, data) in &bundle.files {
        let rel = safe_relative_path(path).ok_or_else(|| anyhow::anyhow!("unsafe bundle path {path:?}"))?;
        let p = tmp.path().join(rel);
        std::fs::create_dir_all(p.parent().unwrap_or(tmp.path()))?;
        std::fs::write(&p, data)?;
    }
    std::fs::write(tmp.path().join(MARKER), &bundle.scene_path)?;
    let dir = cache.join(digest);
    if let Err(e) = std::fs::rename(tmp.path(), &dir) {
        // renaming onto a complete folder fails: another worker unpacked it first
        if !dir.join(MARKER).exists() {
            return Err(anyhow::Error::new(e).context(format!("cannot move the unpacked bundle to {}", dir.display())));
        }
    }
    Ok(dir.join(scene_rel))
}

/// An unpacked bundle in the cache folder.
#[derive(Clone, Debug, PartialEq)]
pub struct CachedBundle {
    /// Its digest (the folder's name).
    pub digest: String,
    /// Bytes of its files.
    pub bytes: u64,
    /// Its last use.
    pub last_used: SystemTime,
}

/// The bundles to delete so that the others fit in `limit_bytes`: least recently used first,
/// never one `in_use` (which may leave the cache over the limit).
pub fn plan_eviction(mut bundles: Vec<CachedBundle>, limit_bytes: u64, in_use: &HashSet<&str>) -> Vec<String> {
    let mut total: u64 = bundles.iter().map(|b| b.bytes).sum();
    bundles.sort_by(|a, b| (a.last_used, &a.digest).cmp(&(b.last_used, &b.digest)));
    let mut gone = Vec::new();
    for b in bundles {
        if total <= limit_bytes {
            break;
        }
        if !in_use.contains(b.digest.as_str()) {
            total -= b.bytes;
            gone.push(b.digest);
        }
    }
    gone
}

/// Deletes least recently used bundles under `dir` until the rest fit in `limit_bytes`,
/// keeping those `in_use`; returns the deleted digests.
pub fn evict(dir: &Path, limit_bytes: u64, in_use: &HashSet<&str>) -> std::io::Result<Vec<String>> {
    let gone = plan_eviction(scan(dir)?, limit_bytes, in_use);
    for digest in &gone {
        // renamed away first: a folder with its marker is always complete for another process
        let doomed = dir.join(format!(".evict.{digest}.{}", uuid::Uuid::new_v4().simple()));
        match std::fs::rename(dir.join(digest), &doomed) {
            Ok(()) => std::fs::remove_dir_all(&doomed)?,
            // another worker sharing the folder evicted it at the same time
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    Ok(gone)
}

/// Unpacking and evicting folders older than this were left by killed workers.
const LEFTOVER_AGE: std::time::Duration = std::time::Duration::from_secs(3600);

/// Deletes the unpacking and evicting folders under `dir` (named with a leading dot) older
/// than `age`, which a killed worker left behind; returns how many.
fn remove_leftovers(dir: &Path, age: std::time::Duration) -> std::io::Result<usize> {
    let mut removed = 0;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let meta = entry.metadata()?;
        let old = meta.modified()?.elapsed().is_ok_and(|a| a >= age);
        if name.starts_with('.') && meta.is_dir() && old {
            std::fs::remove_dir_all(entry.path())?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// The unpacked bundles under `dir`: folders named by a digest holding a marker.
fn scan(dir: &Path) -> std::io::Result<Vec<CachedBundle>> {
    let mut bundles = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let digest = entry.file_name().to_string_lossy().into_owned();
        let Ok(marker) = std::fs::metadata(entry.path().join(MARKER)) else { continue };
        if tessera_proto::is_blob_digest(&digest) {
            let last_used = marker.modified()?;
            bundles.push(CachedBundle { bytes: folder_bytes(&entry.path())?, digest, last_used });
        }
    }
    Ok(bundles)
}

fn folder_bytes(dir: &Path) -> std::io::Result<u64> {
    let mut total = 0;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let meta = entry.metadata()?;
        total += if meta.is_dir() { folder_bytes(&entry.path())? } else { meta.len() };
    }
    Ok(total)
}

/// Marks bundle `digest` as just used (best effort: a failure only makes it look older).
fn touch(dir: &Path, digest: &str) {
    let marked = std::fs::File::options()
        .write(true)
        .open(dir.join(digest).join(MARKER))
        .and_then(|f| f.set_modified(SystemTime::now()));
    if let Err(e) = marked {
        tracing::debug!(bundle = digest, error = %e, "cannot mark a cached bundle as used");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn digest(i: u8) -> String {
        tessera_proto::blob_digest(&[i])
    }

    fn bundle(i: u8, bytes: u64, age_s: u64) -> CachedBundle {
        CachedBundle { digest: digest(i), bytes, last_used: SystemTime::UNIX_EPOCH + Duration::from_secs(1000 - age_s) }
    }

    #[test]
    fn plan_eviction_drops_least_recently_used_first_and_never_one_in_use() {
        let bundles = vec![bundle(0, 40, 10), bundle(1, 30, 300), bundle(2, 20, 200), bundle(3, 10, 100)];
        // 100 bytes, limit 60: the two oldest go (1 then 2)
        assert_eq!(plan_eviction(bundles.clone(), 60, &HashSet::new()), vec![digest(1), digest(2)]);
        assert!(plan_eviction(bundles.clone(), 100, &HashSet::new()).is_empty());
        // the oldest is in use: it stays, and the next ones go instead
        let in_use = HashSet::from([digest(1)]);
        let in_use: HashSet<&str> = in_use.iter().map(String::as_str).collect();
        assert_eq!(plan_eviction(bundles.clone(), 60, &in_use), vec![digest(2), digest(3), digest(0)]);
        // a limit of 0 keeps only what is in use
        assert_eq!(plan_eviction(bundles, 0, &in_use).len(), 3);
    }

    #[test]
    fn evict_deletes_the_least_recently_used_bundle_folders() {
        let dir = tempfile::tempdir().unwrap();
        let now = SystemTime::now();
        for (i, age_s) in [(0u8, 30u64), (1, 10), (2, 20)] {
            let b = dir.path().join(digest(i));
            std::fs::create_dir_all(b.join("meshes")).unwrap();
            std::fs::write(b.join("meshes").join("m.obj"), vec![0u8; 1000]).unwrap();
            std::fs::write(b.join(MARKER), "scene.xml").unwrap();
            let marker = std::fs::File::options().write(true).open(b.join(MARKER)).unwrap();
            marker.set_modified(now - Duration::from_secs(age_s)).unwrap();
        }
        // an unfinished unpacking (no marker) is not a bundle
        std::fs::create_dir_all(dir.path().join(format!(".{}.7", digest(9)))).unwrap();
        let bytes = scan(dir.path()).unwrap().iter().map(|b| b.bytes).sum::<u64>();
        assert_eq!(bytes, 3 * (1000 + "scene.xml".len() as u64));
        // room for two: the oldest (0) goes
        assert_eq!(evict(dir.path(), 2100, &HashSet::new()).unwrap(), vec![digest(0)]);
        assert!(!dir.path().join(digest(0)).exists() && dir.path().join(digest(1)).exists());
        // using 2 makes 1 the least recently used
        touch(dir.path(), &digest(2));
        assert_eq!(evict(dir.path(), 1100, &HashSet::new()).unwrap(), vec![digest(1)]);
        // in use, it stays even over the limit
        assert!(evict(dir.path(), 0, &HashSet::from([digest(2).as_str()])).unwrap().is_empty());
        assert!(dir.path().join(digest(2)).join(MARKER).exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2, "no evicted leftovers");
        // the unfinished unpacking is a killed worker's leftover once old enough
        assert_eq!(remove_leftovers(dir.path(), Duration::from_secs(3600)).unwrap(), 0);
        assert_eq!(remove_leftovers(dir.path(), Duration::ZERO).unwrap(), 1);
        assert!(dir.path().join(digest(2)).join(MARKER).exists());
    }

    /// Workers sharing a cache folder unpack the same bundle at once: each gets the complete
    /// scene. Threads of one process stand in for containers, whose workers all have pid 1.
    #[test]
    fn concurrent_unpacking_of_one_bundle_always_gives_a_complete_folder() {
        let files: Vec<(String, Vec<u8>)> = std::iter::once(("scene.xml".to_string(), b"<scene/>".to_vec()))
            .chain((0..40).map(|i| (format!("meshes/m{i}.obj"), vec![i as u8; 4096])))
            .collect();
        let bundle = Bundle { scene_path: "scene.xml".into(), files };
        for round in 0..20u8 {
            let dir = tempfile::tempdir().unwrap();
            let d = digest(round);
            let barrier = std::sync::Barrier::new(6);
            std::thread::scope(|s| {
                let runs: Vec<_> = (0..6)
                    .map(|_| {
                        s.spawn(|| {
                            barrier.wait();
                            write_bundle(dir.path(), &d, &bundle)
                        })
                    })
                    .collect();
                for run in runs {
                    let scene = run.join().unwrap().expect("every worker gets the bundle");
                    assert_eq!(std::fs::read(&scene).unwrap(), b"<scene/>");
                    assert_eq!(std::fs::read(dir.path().join(&d).join("meshes/m39.obj")).unwrap(), vec![39u8; 4096]);
                }
            });
            let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
            assert_eq!(left, vec![std::ffi::OsString::from(&d)], "only the bundle's folder is left");
        }
    }
}
