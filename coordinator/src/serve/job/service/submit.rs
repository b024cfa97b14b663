//! Submission: a received scene bundle (see [`super::upload`]) is stored as a blob and kept
//! unpacked, the scene is loaded from it to refuse a bad one with its file, line and column,
//! settings and limits are checked, and the job is queued.

use super::upload::BundleUpload;
use super::{Bundle, JobService, ServiceError};
use crate::serve::job::model::{Event, JobSpec};
use crate::serve::job::spec::TILE_SIZE;
use crate::serve::job::spec::{MAX_AFTER, Placement, check_tags};
use crate::serve::job::view::JobView;
use std::path::Path;
use tessera_common::scene::{LoadOptions, Scene};
use tessera_common::settings::RenderSettings;

impl JobService {
    /// Validates and stores a scene bundle held in memory, and queues the job: the bundle goes
    /// through [`JobService::submit_upload`] like a streamed one.
    pub fn submit(
        &self,
        bundle: Bundle,
        settings: RenderSettings,
        placement: impl Into<Placement>,
        name: Option<String>,
        now_ms: u64,
    ) -> Result<JobView, ServiceError> {
        let mut upload = self.begin_upload(u64::MAX)?;
        for (path, data) in &bundle.files {
            upload.start_file(path)?;
            upload.write(data)?;
        }
        drop(bundle.files);
        self.submit_upload(upload, &bundle.scene_path, settings, placement, name, now_ms)
    }

    /// Validates and stores a received bundle (its scene at `scene_path`) and settings, and
    /// queues the job.
    #[tracing::instrument(skip_all, fields(scene = %scene_path))]
    pub fn submit_upload(
        &self,
        mut upload: BundleUpload,
        scene_path: &str,
        settings: RenderSettings,
        placement: impl Into<Placement>,
        name: Option<String>,
        now_ms: u64,
    ) -> Result<JobView, ServiceError> {
        let placement = self.check_placement(&settings, placement.into())?;
        let (digest, pin) = self.store_upload(&mut upload, scene_path)?;
        let spec = match self.check_scene(scene_path, &digest, settings, placement, name) {
            Ok(spec) => spec,
            Err(e) => return Err(self.refused_bundle(e, pin, digest)),
        };
        let id = uuid::Uuid::new_v4().to_string();
        let mut inner = self.lock();
        let changes = inner.model.apply(Event::Submit { id: &id, spec: Box::new(spec.clone()) }, now_ms)?.changes;
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

    /// Checks a submission's settings and placement; the jobs waited for must exist now (and
    /// so cannot wait for this one), named by their full ids afterwards.
    pub(super) fn check_placement(
        &self,
        settings: &RenderSettings,
        mut placement: Placement,
    ) -> Result<Placement, ServiceError> {
        settings.validate().map_err(|e| ServiceError::InvalidArgument(e.to_string()))?;
        check_tags("require_tags", &placement.require_tags).map_err(ServiceError::InvalidArgument)?;
        placement.after = self.resolve_after(&placement.after)?;
        Ok(placement)
    }

    /// Stores a received bundle as a blob and unpacked; returns its digest, pinned until the
    /// job using it is in the model (so that a delete of another job with this bundle leaves
    /// it alone meanwhile).
    pub(super) fn store_upload(
        &self,
        upload: &mut BundleUpload,
        scene_path: &str,
    ) -> Result<(String, super::retention::BundlePin<'_>), ServiceError> {
        // the bundle just received may have taken the last of the reserve
        self.check_space()?;
        let blob = self.blobs.temp_path(".bundle");
        let digest = match upload.finish(scene_path, &blob) {
            Ok(digest) => digest,
            Err(e) => {
                let _ = std::fs::remove_file(&blob);
                return Err(e);
            }
        };
        let pin = self.pin_bundle(&digest);
        let stored = self.blobs.put_file_digested(&blob, &digest).map_err(ServiceError::from);
        let _ = std::fs::remove_file(&blob);
        match stored.and_then(|()| upload.unpack_to(&self.scenes_dir.join(&digest))) {
            Ok(()) => Ok((digest, pin)),
            Err(e) => Err(self.refused_bundle(e, pin, digest)),
        }
    }

    /// A refused submission leaves no files behind (unless a job or submission uses them).
    pub(super) fn refused_bundle(
        &self,
        e: ServiceError,
        pin: super::retention::BundlePin<'_>,
        digest: String,
    ) -> ServiceError {
        drop(pin);
        self.remove_unused_blobs(&self.lock(), [digest].into());
        e
    }

    /// The full ids of the jobs a submission waits for: each must exist (by its id or a
    /// unique prefix), at most [`MAX_AFTER`] of them, each once.
    fn resolve_after(&self, after: &[String]) -> Result<Vec<String>, ServiceError> {
        if after.len() > MAX_AFTER {
            return Err(ServiceError::InvalidArgument(format!("field \"after\" names more than {MAX_AFTER} jobs")));
        }
        let inner = self.lock();
        let mut ids = Vec::new();
        for id in after {
            let full = inner.model.resolve(id).map_err(|e| {
                ServiceError::InvalidArgument(format!("field \"after\": {}", super::retention::refused(e)))
            })?;
            if !ids.iter().any(|i: &String| i == full) {
                ids.push(full.to_string());
            }
        }
        Ok(ids)
    }

    /// Loads the stored bundle's scene (see [`JobService::load_unpacked`]) and checks it against
    /// the settings and limits: the job's description.
    pub(super) fn check_scene(
        &self,
        scene_path: &str,
        digest: &str,
        settings: RenderSettings,
        placement: Placement,
        name: Option<String>,
    ) -> Result<JobSpec, ServiceError> {
        let scene = self.load_unpacked(scene_path, digest, &settings)?;
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
                "{} spp plans {tiles} tiles ({}), over this coordinator's limit of {} per job (tessera serve --max-job-tiles)",
                integrator_settings.spp.unwrap_or(0),
                if full_frame { "one full frame per iteration" } else { "64² rectangles" },
                self.cfg.max_tiles
            )));
        }
        integrator_settings.check_work(w, h, &self.cfg.work_limits).map_err(|e| {
            let e = e.to_string();
            let hint = if e.contains("MiB per tile") { " (tessera serve --max-tile-memory)" } else { "" };
            ServiceError::InvalidArgument(format!("{e}{hint}"))
        })?;
        Ok(JobSpec {
            name: name.filter(|n| !n.is_empty()).unwrap_or_else(|| default_name(scene_path)),
            priority: placement.priority,
            after: placement.after,
            require_tags: placement.require_tags,
            frame: None,
            warm: None,
            full_frame,
            settings: integrator_settings,
            width: scene.camera.width,
            height: scene.camera.height,
            bundle_digest: digest.to_string(),
            scene_path: scene_path.to_string(),
            filter: scene.film.filter.kind,
        })
    }

    /// Loads the scene from the unpacked bundle `digest`, confined to it, to validate it.
    /// Scene errors name the file inside the bundle, its line and column.
    fn load_unpacked(&self, scene_path: &str, digest: &str, settings: &RenderSettings) -> Result<Scene, ServiceError> {
        let dir = self.scenes_dir.join(digest);
        let options = LoadOptions {
            defines: settings.define_map(),
            limits: self.cfg.scene_limits,
            confine_to: Some(dir.clone()),
        };
        // confined, so the error names files inside the bundle
        Scene::load_options(&dir.join(scene_path), &options).map_err(|e| {
            let hint = if e.message.contains("triangles, the limit") { " (tessera serve --max-triangles)" } else { "" };
            ServiceError::InvalidArgument(format!("{e}{hint}"))
        })
    }
}

pub(super) fn default_name(scene_path: &str) -> String {
    let p = Path::new(scene_path);
    let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("job");
    match (stem, p.parent().and_then(|d| d.file_name()).and_then(|s| s.to_str())) {
        ("scene", Some(dir)) => dir.to_string(),
        _ => stem.to_string(),
    }
}
