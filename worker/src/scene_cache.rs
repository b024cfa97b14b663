//! Scene bundles cached on disk by digest (fetched once through `FetchBlob`, verified against
//! their SHA-256, unpacked into `<cache>/<digest>/`) and loaded scenes kept in memory for the
//! few most recent (bundle, defines) pairs; also the current EMIS merge mask (a blob too).

use crate::client::Client;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tessera_common::bundle::{Bundle, safe_relative_path};
use tessera_common::scene::{LoadOptions, Scene};
use tessera_common::texture::TextureLimits;
use tessera_proto::v1 as pb;
use tokio_stream::StreamExt;

/// Loaded scenes kept in memory.
const KEEP_LOADED: usize = 4;

/// A loaded scene's identity: bundle digest and sorted defines.
type SceneKey = (String, Vec<(String, String)>);

/// The cache.
pub struct SceneCache {
    dir: PathBuf,
    loaded: Vec<(SceneKey, Arc<Scene>)>,
    /// The current EMIS merge mask.
    pub masks: MaskCache,
    texture_limits: TextureLimits,
}

impl SceneCache {
    /// A cache under `dir`.
    pub fn new(dir: PathBuf, texture_budget_mib: Option<u64>) -> Self {
        let texture_limits =
            texture_budget_mib.map_or_else(TextureLimits::default, |mib| TextureLimits::total(mib << 20));
        SceneCache { dir, loaded: Vec::new(), masks: MaskCache::default(), texture_limits }
    }

    /// The scene of bundle `digest` loaded with `defines`, fetching and unpacking it if needed.
    pub async fn get(
        &mut self,
        client: &mut Client,
        digest: &str,
        defines: &HashMap<String, String>,
    ) -> anyhow::Result<Arc<Scene>> {
        let mut key_defines: Vec<_> = defines.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
        key_defines.sort();
        let key = (digest.to_string(), key_defines);
        if let Some((_, scene)) = self.loaded.iter().find(|(k, _)| *k == key) {
            return Ok(scene.clone());
        }
        let scene_file = self.unpack(client, digest).await?;
        // the scene may name only files of its own bundle, whatever the coordinator checked
        let options = LoadOptions {
            defines: defines.clone(),
            texture_limits: self.texture_limits,
            confine_to: Some(self.dir.join(digest)),
        };
        let scene = tokio::task::spawn_blocking(move || Scene::load_options(&scene_file, &options)).await??;
        let scene = Arc::new(scene);
        self.loaded.push((key, scene.clone()));
        if self.loaded.len() > KEEP_LOADED {
            self.loaded.remove(0);
        }
        Ok(scene)
    }

    /// Makes sure the bundle is unpacked; returns the scene file's path.
    async fn unpack(&self, client: &mut Client, digest: &str) -> anyhow::Result<PathBuf> {
        if !tessera_proto::is_blob_digest(digest) {
            anyhow::bail!("invalid bundle digest {digest:?}");
        }
        let dir = self.dir.join(digest);
        let marker = dir.join(".scene_path");
        if let Ok(p) = std::fs::read_to_string(&marker) {
            return Ok(dir.join(p));
        }
        let bytes = fetch_verified(client, digest).await?;
        let bundle = tessera_proto::bundle::decode(&bytes)?;
        let cache_dir = self.dir.clone();
        let digest = digest.to_string();
        tokio::task::spawn_blocking(move || write_bundle(&cache_dir, &digest, &bundle)).await?
    }
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
        anyhow::bail!("blob {digest} arrived corrupted (digest mismatch)");
    }
    Ok(bytes)
}

/// The most recent EMIS merge mask, kept in memory: every tile of a pass uses the same one.
#[derive(Default)]
pub struct MaskCache {
    last: Option<(String, Arc<Vec<f32>>)>,
}

impl MaskCache {
    /// The per-pixel merge probabilities of blob `digest` (`pixels` little-endian f32).
    pub async fn get(&mut self, client: &mut Client, digest: &str, pixels: usize) -> anyhow::Result<Arc<Vec<f32>>> {
        if let Some((d, mask)) = &self.last
            && d == digest
        {
            return Ok(mask.clone());
        }
        let bytes = fetch_verified(client, digest).await?;
        if bytes.len() != pixels * 4 {
            anyhow::bail!("merge mask {digest} has {} bytes, expected {} for {pixels} pixels", bytes.len(), pixels * 4);
        }
        let mask: Vec<f32> =
            bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("invariant: 4 bytes"))).collect();
        if mask.iter().any(|v| !(0.0..=1.0).contains(v)) {
            anyhow::bail!("merge mask {digest} has values outside [0, 1]");
        }
        let mask = Arc::new(mask);
        self.last = Some((digest.to_string(), mask.clone()));
        Ok(mask)
    }
}

fn write_bundle(cache: &Path, digest: &str, bundle: &Bundle) -> anyhow::Result<PathBuf> {
    let tmp = cache.join(format!(".{digest}.{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
    for (path, data) in &bundle.files {
        let rel = safe_relative_path(path).ok_or_else(|| anyhow::anyhow!("unsafe bundle path {path:?}"))?;
        let p = tmp.join(rel);
        std::fs::create_dir_all(p.parent().unwrap_or(&tmp))?;
        std::fs::write(&p, data)?;
    }
    safe_relative_path(&bundle.scene_path).ok_or_else(|| anyhow::anyhow!("unsafe scene path"))?;
    std::fs::write(tmp.join(".scene_path"), &bundle.scene_path)?;
    let dir = cache.join(digest);
    if std::fs::rename(&tmp, &dir).is_err() {
        // another worker process sharing the cache unpacked it first
        let _ = std::fs::remove_dir_all(&tmp);
    }
    Ok(dir.join(&bundle.scene_path))
}
