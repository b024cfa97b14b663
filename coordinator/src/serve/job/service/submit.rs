//! Submission: a scene bundle and settings are checked, the bundle is stored as a blob and
//! unpacked, the scene is loaded from it to refuse a bad one with its file, line and column,
//! and the job is queued.

use super::{Bundle, JobService, ServiceError};
use crate::serve::job::model::JobSpec;
use crate::serve::job::plan::TILE_SIZE;
use crate::serve::job::view::JobView;
use std::path::Path;
use tessera_common::scene::{LoadOptions, Scene};
use tessera_common::settings::RenderSettings;

impl JobService {
    /// Validates and stores a scene bundle and settings, and queues the job.
    #[tracing::instrument(skip_all, fields(scene = %bundle.scene_path))]
    pub fn submit(
        &self,
        bundle: Bundle,
        settings: RenderSettings,
        priority: i32,
        name: Option<String>,
        now_ms: u64,
    ) -> Result<JobView, ServiceError> {
        settings.validate().map_err(|e| ServiceError::InvalidArgument(e.to_string()))?;
        let encoded = tessera_proto::bundle::encode(&bundle);
        let digest = tessera_proto::blob_digest(&encoded);
        // pinned until the job is in the model, so that a delete of another job with this
        // bundle leaves it alone meanwhile
        let pin = self.pin_bundle(&digest);
        let spec = self.store_bundle(&bundle, &encoded, &digest, settings, priority, name);
        drop(encoded);
        let spec = match spec {
            Ok(spec) => spec,
            Err(e) => {
                // a refused scene leaves no files behind (unless a job or submission uses them)
                drop(pin);
                self.remove_unused_blobs(&self.lock(), [digest].into());
                return Err(e);
            }
        };
        let id = uuid::Uuid::new_v4().to_string();
        let mut inner = self.lock();
        let changes = inner.model.submit(&id, spec.clone(), now_ms)?;
        drop(pin);
        self.persist(&mut inner, &changes, &[])?;
        self.sync(&inner)?;
        tracing::info!(
            job_id = %id,
            name = %spec.name,
            integrator = %spec.settings.integrator,
            width = spec.width,
            height = spec.height,
            spp = spec.settings.spp,
            time_s = spec.settings.time_s,
            priority = spec.priority,
            "job submitted"
        );
        super::events::pass_planned(&inner.model, &id);
        self.work.notify_waiters();
        Ok(self.view(&inner, &id, now_ms))
    }

    /// Stores and loads the bundle (see [`JobService::unpack_and_load`]) and checks the scene
    /// against the settings and limits: the job's description.
    fn store_bundle(
        &self,
        bundle: &Bundle,
        encoded: &[u8],
        digest: &str,
        settings: RenderSettings,
        priority: i32,
        name: Option<String>,
    ) -> Result<JobSpec, ServiceError> {
        let scene = self.unpack_and_load(bundle, encoded, digest, &settings)?;
        let (w, h) = (scene.camera.width, scene.camera.height);
        if u64::from(w) * u64::from(h) > self.cfg.max_pixels {
            return Err(ServiceError::InvalidArgument(format!(
                "the film is {w}×{h} = {} pixels, over this coordinator's limit of {} (tessera serve --max-pixels)",
                u64::from(w) * u64::from(h),
                self.cfg.max_pixels
            )));
        }
        let integrator_settings = settings.resolved(&scene);
        integrator_settings.make_renderer(&scene).map_err(|e| ServiceError::InvalidArgument(e.to_string()))?;
        // every tile of a sample budget's pass is planned (and stored) when the pass starts:
        // full-frame integrators plan a tile per iteration
        let full_frame = integrator_settings.integrator.full_frame();
        let tiles = match (full_frame, integrator_settings.spp) {
            (true, Some(spp)) => u64::from(spp),
            _ => u64::from(w.div_ceil(TILE_SIZE)) * u64::from(h.div_ceil(TILE_SIZE)),
        };
        if tiles > self.cfg.max_tiles {
            return Err(ServiceError::InvalidArgument(format!(
                "{} spp plans {tiles} tiles ({}), over this coordinator's limit of {} per job (tessera serve --max-tiles)",
                integrator_settings.spp.unwrap_or(0),
                if full_frame { "one full frame per iteration" } else { "64² rectangles" },
                self.cfg.max_tiles
            )));
        }
        Ok(JobSpec {
            name: name.filter(|n| !n.is_empty()).unwrap_or_else(|| default_name(&bundle.scene_path)),
            priority,
            full_frame,
            settings: integrator_settings,
            width: scene.camera.width,
            height: scene.camera.height,
            bundle_digest: digest.to_string(),
            scene_path: bundle.scene_path.clone(),
            filter: scene.film.filter.kind,
        })
    }

    /// Stores the bundle blob (`encoded`, whose digest is `digest`), unpacks it and loads the
    /// scene from it to validate it. Scene errors name the file inside the bundle, its line and
    /// column.
    fn unpack_and_load(
        &self,
        bundle: &Bundle,
        encoded: &[u8],
        digest: &str,
        settings: &RenderSettings,
    ) -> Result<Scene, ServiceError> {
        let invalid = ServiceError::InvalidArgument;
        if tessera_common::bundle::safe_relative_path(&bundle.scene_path).is_none() {
            return Err(invalid(format!("bundle scene path \"{}\" is not a relative path", bundle.scene_path)));
        }
        if !bundle.files.iter().any(|(p, _)| *p == bundle.scene_path) {
            return Err(invalid(format!("bundle has no file \"{}\" (the scene)", bundle.scene_path)));
        }
        for (path, _) in &bundle.files {
            if tessera_common::bundle::safe_relative_path(path).is_none() {
                return Err(invalid(format!("bundle file path \"{path}\" must be relative without \"..\"")));
            }
        }
        self.blobs.put_digested(digest, encoded)?;
        let dir = self.scenes_dir.join(digest);
        if !dir.exists() {
            let tmp = self.scenes_dir.join(format!("{digest}.{}", uuid::Uuid::new_v4()));
            for (path, data) in &bundle.files {
                let p = tmp.join(tessera_common::bundle::safe_relative_path(path).expect("invariant: checked above"));
                std::fs::create_dir_all(p.parent().expect("invariant: joined path has a parent"))?;
                std::fs::write(&p, data)?;
            }
            if std::fs::rename(&tmp, &dir).is_err() {
                // another submission unpacked the same bundle first
                let _ = std::fs::remove_dir_all(&tmp);
            }
        }
        let options = LoadOptions {
            defines: settings.define_map(),
            texture_limits: self.cfg.texture_limits,
            confine_to: Some(dir.clone()),
        };
        let scene = Scene::load_options(&dir.join(&bundle.scene_path), &options).map_err(|e| {
            let prefix = format!("{}/", dir.display());
            invalid(e.to_string().replace(&prefix, ""))
        })?;
        Ok(scene)
    }
}

fn default_name(scene_path: &str) -> String {
    let p = Path::new(scene_path);
    let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("job");
    match (stem, p.parent().and_then(|d| d.file_name()).and_then(|s| s.to_str())) {
        ("scene", Some(dir)) => dir.to_string(),
        _ => stem.to_string(),
    }
}
