//! Read-only views of jobs and workers that the API layers encode (REST JSON, gRPC messages):
//! state, phase, progress, tiles, samples and an ETA computed from the model and the time.

use super::model::{Job, JobState};
use serde::Serialize;
use tessera_common::emis::UpdateReport;
use tessera_common::settings::RenderSettings;

/// What EMIS has chosen so far.
#[derive(Clone, Debug, Serialize)]
pub struct StrategyView {
    /// Light paths per pixel per iteration (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex (0 with per-pixel connections).
    pub connections: u32,
    /// With per-pixel connections: their mean expected count.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_connections: Option<f64>,
    /// Mean per-pixel merge probability.
    pub mean_merge_probability: f64,
    /// Every update: the chosen counts and every candidate's predicted moment and cost.
    pub updates: Vec<UpdateReport>,
}

impl StrategyView {
    /// The decisions of a finished job read back from its stored EMIS report, as
    /// `EmisJob::view` showed them before (`None` before the first update, as there).
    pub fn from_report(report: crate::output::ReportDecisions) -> Option<StrategyView> {
        let last = report.updates.last()?;
        Some(StrategyView {
            nu: report.last.nu,
            connections: report.last.connections,
            mean_connections: last.mean_connections,
            mean_merge_probability: last.mean_merge_probability,
            updates: report.updates,
        })
    }
}

/// A job as clients see it.
#[derive(Clone, Debug)]
pub struct JobView {
    /// Id.
    pub id: String,
    /// Display name.
    pub name: String,
    /// Lifecycle state.
    pub state: JobState,
    /// E.g. `final pass 1/1`.
    pub phase: String,
    /// 0..1.
    pub progress: f64,
    /// Tiles accepted or merged.
    pub tiles_done: u64,
    /// Tiles planned.
    pub tiles_total: u64,
    /// Pixel samples merged.
    pub samples_done: u64,
    /// Estimated seconds left.
    pub eta_s: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
    /// Priority.
    pub priority: i32,
    /// Resolved settings.
    pub settings: RenderSettings,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Submission time (Unix ms).
    pub created_ms: u64,
    /// Bundle digest.
    pub scene_digest: String,
    /// EMIS decisions once known (filled in by the service, which holds them).
    pub strategy: Option<StrategyView>,
    /// A job of frames: how many (0 for a still).
    pub frames_total: u64,
    /// A job of frames: those planned so far.
    pub frames: Vec<FrameView>,
}

/// One frame of a job of frames.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameView {
    /// Its number.
    pub number: u32,
    /// The id of its job (for its outputs).
    pub job_id: String,
    /// Its state.
    pub state: JobState,
    /// 0..1.
    pub progress: f64,
    /// Estimated seconds left.
    pub eta_s: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
}

/// The fraction of a sample-budget job's samples merged, never decreasing: passes are planned
/// at barriers, so the budget is the measure of the whole; when an EMIS update discards a
/// path-tracing start, the progress shown at that barrier is kept and the rest of the bar is
/// the new film's share.
fn sample_progress(job: &Job) -> f64 {
    let pixels = job.spec.width as u64 * job.spec.height as u64;
    let target = job.spec.settings.spp.map_or(0, |n| n as u64 * pixels);
    let kept_from = job.passes().iter().rev().find(|p| p.restart).map_or(0, |p| p.tiles.start);
    let discarded: u64 = job.tiles[..kept_from].iter().map(|t| t.spec.pixel_samples()).sum();
    let before = discarded as f64 / discarded.max(target).max(1) as f64;
    let kept_merged = job.samples_merged().saturating_sub(discarded);
    let kept_planned = (job.samples_planned() - discarded).max(target);
    before + (1.0 - before) * kept_merged as f64 / kept_planned.max(1) as f64
}

impl JobView {
    /// The view of `job` at `now_ms`.
    pub fn of(job: &Job, now_ms: u64) -> JobView {
        let state = job.shown_state();
        let elapsed_s = job.started_ms().map(|t| now_ms.saturating_sub(t) as f64 / 1000.0);
        let progress = match (state, job.spec.settings.time_s) {
            (JobState::Done, _) => 1.0,
            (_, Some(budget)) => (elapsed_s.unwrap_or(0.0) / budget).clamp(0.0, 0.99),
            _ => sample_progress(job),
        };
        let eta_s = match elapsed_s {
            Some(e) if !state.is_terminal() && progress > 0.0 => Some(e * (1.0 - progress) / progress),
            _ => None,
        };
        let current_pass =
            job.passes().iter().position(|p| p.tiles.end > job.merged).unwrap_or(job.passes().len().max(1) - 1);
        let phase = match state {
            JobState::Queued | JobState::Done | JobState::Failed | JobState::Cancelled => state.as_str().to_string(),
            s => format!("{} pass {}/{}", s.as_str(), current_pass + 1, job.passes().len()),
        };
        JobView {
            id: job.id.clone(),
            name: job.spec.name.clone(),
            state,
            phase,
            progress,
            tiles_done: job.tiles_done() as u64,
            tiles_total: job.tiles.len() as u64,
            samples_done: job.samples_merged(),
            eta_s,
            error: job.error.clone(),
            priority: job.spec.priority,
            settings: job.spec.settings.clone(),
            width: job.spec.width,
            height: job.spec.height,
            created_ms: job.created_ms,
            scene_digest: job.spec.bundle_digest.clone(),
            strategy: None,
            frames_total: 0,
            frames: Vec::new(),
        }
    }
}

/// A worker as clients see it.
#[derive(Clone, Debug, PartialEq)]
pub struct WorkerView {
    /// Id.
    pub id: String,
    /// Name.
    pub name: String,
    /// Render threads.
    pub threads: u32,
    /// Seconds since the last contact.
    pub last_seen_s_ago: f64,
    /// Leases held.
    pub leases: usize,
    /// `idle`, `busy`, `disabled`, `draining` or `offline`.
    pub state: &'static str,
    /// Its tags.
    pub tags: Vec<String>,
}
