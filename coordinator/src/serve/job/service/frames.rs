//! Jobs of many frames on the service's side (the model's `sequence.rs` says what they are):
//! submitting one, planning its frames as room frees up (each frame's scene is loaded first,
//! without the lock, and a frame whose scene does not load fails alone), and what clients see
//! of it: one job whose state, progress and ETA cover its frames, with a line per frame; and
//! with `--warm-start`, each frame's decision handed to the next.

use super::upload::BundleUpload;
use super::{Inner, JobService, ServiceError};
use crate::serve::job::model::{Changes, Event, JobSpec, JobState, SequenceSpec};
use crate::serve::job::spec::Placement;
use crate::serve::job::view::{FrameView, JobView};
use tessera_common::settings::RenderSettings;

/// How a submission asks for frames.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramesRequest {
    /// The frame numbers (`tessera_link::frames::parse`).
    pub frames: Vec<u32>,
    /// The scene parameter that carries the frame number.
    pub param: String,
    /// Frame N renders with the seed plus N.
    pub seed_per_frame: bool,
    /// EMIS: frame N+1 starts from frame N's decision.
    pub warm_start: bool,
}

impl JobService {
    /// Validates and stores a received bundle and queues a job of `frames`: the first frame's
    /// scene must load (the others are loaded as they are planned); `scene_path` may hold runs
    /// of `#`, the frame number (one scene file per frame).
    #[allow(clippy::too_many_arguments)]
    pub fn submit_frames(
        &self,
        mut upload: BundleUpload,
        scene_path: &str,
        settings: RenderSettings,
        placement: Placement,
        name: Option<String>,
        frames: FramesRequest,
        now_ms: u64,
    ) -> Result<JobView, ServiceError> {
        check_frames(&frames)?;
        if frames.warm_start && settings.integrator.emis_method().is_none() {
            let message = format!("field \"warm_start\" needs an emis-* integrator, not {}", settings.integrator);
            return Err(ServiceError::InvalidArgument(message));
        }
        let placement = self.check_placement(&settings, placement)?;
        // the bundle's own scene is the first frame's (its file, when each frame has one)
        let first = tessera_link::frames::expand(scene_path, frames.frames[0]);
        let (digest, pin) = self.store_upload(&mut upload, &first)?;
        let spec = SequenceSpec {
            name: name.filter(|n| !n.is_empty()).unwrap_or_else(|| super::submit::default_name(scene_path)),
            priority: placement.priority,
            settings,
            frames: frames.frames,
            frame_param: frames.param,
            seed_per_frame: frames.seed_per_frame,
            warm_start: frames.warm_start,
            scene_path: scene_path.to_string(),
            bundle_digest: digest.clone(),
            after: placement.after,
            require_tags: placement.require_tags,
        };
        if let Err(e) = self.frame_spec(&spec, 0) {
            return Err(self.refused_bundle(e, pin, digest));
        }
        let id = uuid::Uuid::new_v4().to_string();
        let mut inner = self.lock();
        let event = Event::SubmitSequence { id: &id, spec: Box::new(spec.clone()) };
        let changes = inner.model.apply(event, now_ms)?.changes;
        drop(pin);
        self.persist(&mut inner, &changes, &[])?;
        self.sync(&inner)?;
        tracing::info!(job_id = %id, name = %spec.name, frames = spec.frames.len(), "job of frames submitted");
        drop(inner);
        self.plan_frames(now_ms)?;
        Ok(self.view(&self.lock(), &id, now_ms))
    }

    /// Frame `index`'s job, from its scene (loaded now).
    fn frame_spec(&self, s: &SequenceSpec, index: usize) -> Result<JobSpec, ServiceError> {
        let (scene_path, settings) = s.frame(index);
        let placement =
            Placement { priority: s.priority, after: s.after.clone(), require_tags: s.require_tags.clone() };
        let name = format!("{} frame {}", s.name, s.frames[index]);
        self.check_scene(&scene_path, &s.bundle_digest, settings, placement, Some(name))
    }

    /// Plans the frames every sequence has room for (the timer calls it too): loads each
    /// frame's scene without the lock, then adds it as a job, or failed with the scene's
    /// error.
    pub fn plan_frames(&self, now_ms: u64) -> Result<(), ServiceError> {
        let due = self.lock().model.frames_due();
        if due.is_empty() {
            return Ok(());
        }
        for (sequence, indices) in due {
            let Some(s) = self.lock().model.sequences.get(&sequence).map(|s| s.spec.clone()) else { continue };
            for index in indices {
                let (spec, error) = match self.frame_spec(&s, index) {
                    Ok(spec) => (JobSpec { warm: self.lock().model.warm_start_of(&sequence, index), ..spec }, None),
                    Err(e) => {
                        let (scene_path, settings) = s.frame(index);
                        let spec = JobSpec {
                            settings,
                            scene_path,
                            ..JobSpec::bare(&s.name, s.settings.integrator, Some(1), 1, 1)
                        };
                        (spec, Some(format!("frame {}: {e}", s.frames[index])))
                    }
                };
                let mut inner = self.lock();
                let event = Event::PlanFrame { sequence: &sequence, index, spec: Box::new(spec), error };
                // a cancel or delete in between: the sequence plans no more
                let Ok(effects) = inner.model.apply(event, now_ms) else { break };
                self.persist(&mut inner, &effects.changes, &[])?;
                self.ended(&mut inner, &effects);
            }
        }
        self.sync(&self.lock())?;
        self.work.notify_waiters();
        Ok(())
    }

    /// Records the decision of a warm-started job of frames' frame once its EMIS strategy is
    /// final: its last planned pass collects no moments, or it is `finishing`. Returns the
    /// changes to commit with what the caller commits. The decision's masks live as long as
    /// the frame (and the next frame's spec) names them.
    pub(super) fn decide(
        &self,
        inner: &mut Inner,
        job: &str,
        finishing: bool,
        now_ms: u64,
    ) -> Result<Changes, ServiceError> {
        let Some(j) = inner.model.jobs.get(job).filter(|j| j.decided.is_none()) else { return Ok(Changes::new()) };
        let sequence = j.spec.frame.as_ref().and_then(|f| inner.model.sequences.get(&f.sequence));
        let collects = j.driver.passes().last().is_some_and(|p| p.collect);
        if !sequence.is_some_and(|s| s.spec.warm_start) || (collects && !finishing) {
            return Ok(Changes::new());
        }
        let runtime = inner.job(job);
        let Some(emis) = runtime.emis.as_mut() else { return Ok(Changes::new()) };
        let decision = emis.decision(&self.blobs)?;
        runtime.masks.extend(decision.blobs().cloned());
        tracing::debug!(job_id = %job, nu = decision.nu, "frame decided: the next frame starts from it");
        Ok(inner.model.apply(Event::Decided { job, decision: Box::new(decision) }, now_ms)?.changes)
    }

    /// The outputs of a job of frames' done frames, for one archive: each frame's EXR and PNG
    /// under `NAME.NNNN.exr` and `.png`, open.
    pub fn frame_files(&self, id: &str) -> Result<Vec<(String, std::fs::File)>, ServiceError> {
        let inner = self.lock();
        let id = &Self::resolve(&inner, id)?;
        let s = inner.model.sequences.get(id).ok_or_else(|| {
            ServiceError::FailedPrecondition(format!(
                "job {id} is not a job of frames: its outputs are result.exr and preview.png"
            ))
        })?;
        let plain = !s.spec.name.is_empty() && !s.spec.name.contains(['/', '\\']) && !s.spec.name.starts_with('.');
        let name = if plain { s.spec.name.clone() } else { id.clone() };
        let mut files = Vec::new();
        for job in inner.model.frames_of(id).into_iter().filter(|j| j.state == JobState::Done) {
            let number = job.spec.frame.as_ref().map_or(0, |f| f.number);
            let stored = inner.jobs.get(&job.id).map(|r| r.files.clone()).unwrap_or_default();
            for (digest, ext) in [(stored.result_exr, "exr"), (stored.preview_png, "png")] {
                let missing = || ServiceError::NotFound(format!("frame {number} of job {id} has no stored {ext}"));
                let file = self.blobs.open_blob(&digest.ok_or_else(missing)?)?.ok_or_else(missing)?;
                files.push((format!("{name}.{number:04}.{ext}"), file));
            }
        }
        Ok(files)
    }

    /// The view of a sequence: its frames' work summed, a line per frame.
    pub(super) fn sequence_view(&self, inner: &Inner, id: &str, now_ms: u64) -> JobView {
        let s = &inner.model.sequences[id];
        let frames = inner.model.frames_of(id);
        let views: Vec<JobView> = frames.iter().map(|j| self.view_without_strategy(inner, &j.id, now_ms)).collect();
        let total = s.spec.frames.len();
        let progress = views.iter().map(|v| v.progress).sum::<f64>() / total.max(1) as f64;
        let count = |state: JobState| views.iter().filter(|v| v.state == state).count();
        let (done, failed) = (count(JobState::Done), count(JobState::Failed));
        let state = match inner.model.sequence_state(id).unwrap_or(JobState::Queued) {
            s_state if s.paused_ms.is_some() && !s_state.is_terminal() => JobState::Paused,
            s_state => s_state,
        };
        let elapsed_s = now_ms.saturating_sub(s.created_ms) as f64 / 1000.0;
        let first = views.first();
        JobView {
            id: id.to_string(),
            name: s.spec.name.clone(),
            state,
            phase: format!("frames: {done} of {total} done, {failed} failed"),
            progress,
            tiles_done: views.iter().map(|v| v.tiles_done).sum(),
            tiles_total: views.iter().map(|v| v.tiles_total).sum(),
            samples_done: views.iter().map(|v| v.samples_done).sum(),
            eta_s: (!state.is_terminal() && progress > 0.0).then(|| elapsed_s * (1.0 - progress) / progress),
            error: views.iter().find_map(|v| v.error.clone()),
            priority: s.spec.priority,
            settings: first.map_or_else(|| s.spec.settings.clone(), |v| v.settings.clone()),
            width: first.map_or(0, |v| v.width),
            height: first.map_or(0, |v| v.height),
            created_ms: s.created_ms,
            scene_digest: s.spec.bundle_digest.clone(),
            strategy: None,
            frames_total: total as u64,
            frames: views
                .into_iter()
                .zip(&s.spec.frames)
                .map(|(v, &number)| FrameView {
                    number,
                    job_id: v.id,
                    state: v.state,
                    progress: v.progress,
                    eta_s: v.eta_s,
                    error: v.error,
                })
                .collect(),
        }
    }
}

fn check_frames(f: &FramesRequest) -> Result<(), ServiceError> {
    let invalid = |m: String| Err(ServiceError::InvalidArgument(m));
    if f.frames.is_empty() {
        return invalid("field \"frames\" names no frame".into());
    }
    if f.frames.len() > tessera_link::frames::MAX_FRAMES {
        return invalid(format!("field \"frames\" names more than {} frames", tessera_link::frames::MAX_FRAMES));
    }
    let good = |c: char| c.is_ascii_alphanumeric() || c == '_';
    if f.param.is_empty() || f.param.len() > 64 || !f.param.chars().all(good) {
        return invalid(format!("field \"frame_param\" \"{}\" must be 1 to 64 letters, digits or '_'", f.param));
    }
    Ok(())
}
