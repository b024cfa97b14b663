//! JSON shapes of the REST API. DTOs never leave `rest/`.

use crate::serve::job::service::{JobView, WorkerView};
use crate::serve::job::view::StrategyView;
use serde::Serialize;
use tessera_common::settings::RenderSettings;

/// `GET /api/v1/jobs/{id}`.
#[derive(Serialize, utoipa::ToSchema)]
pub struct JobDto {
    /// Id.
    pub id: String,
    /// Name.
    pub name: String,
    /// queued, pilot, optimizing, final, done, failed, cancelled.
    pub state: &'static str,
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
    /// The chosen MIS strategy (EMIS; null before the first update and for other integrators):
    /// `nu`, `connections`, `mean_connections`, `mean_merge_probability` and every update.
    #[schema(value_type = Option<Object>)]
    pub strategy: Option<StrategyView>,
    /// Why the job failed.
    pub error: Option<String>,
    /// Priority.
    pub priority: i32,
    /// Resolved settings (as `tessera render` takes them).
    #[schema(value_type = Object)]
    pub settings: RenderSettings,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Submission time, Unix ms.
    pub created_unix_ms: u64,
    /// Bundle digest.
    pub scene_digest: String,
    /// A job of frames: how many (absent for a still).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_total: Option<u64>,
    /// A job of frames: those planned so far, each `{number, job_id, state, progress, eta_s,
    /// error}`; a frame's outputs are its job's.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    #[schema(value_type = Vec<Object>)]
    pub frames: Vec<serde_json::Value>,
}

impl From<JobView> for JobDto {
    fn from(j: JobView) -> Self {
        JobDto {
            id: j.id,
            name: j.name,
            state: j.state.as_str(),
            phase: j.phase,
            progress: j.progress,
            tiles_done: j.tiles_done,
            tiles_total: j.tiles_total,
            samples_done: j.samples_done,
            eta_s: j.eta_s,
            strategy: j.strategy,
            error: j.error,
            priority: j.priority,
            settings: j.settings,
            width: j.width,
            height: j.height,
            created_unix_ms: j.created_ms,
            scene_digest: j.scene_digest,
            frames_total: (j.frames_total > 0).then_some(j.frames_total),
            frames: j
                .frames
                .into_iter()
                .map(|f| {
                    serde_json::json!({"number": f.number, "job_id": f.job_id, "state": f.state.as_str(),
                        "progress": f.progress, "eta_s": f.eta_s, "error": f.error})
                })
                .collect(),
        }
    }
}

/// `GET /api/v1/workers`.
#[derive(Serialize, utoipa::ToSchema)]
pub struct WorkerDto {
    /// Id.
    pub id: String,
    /// Name.
    pub name: String,
    /// Threads.
    pub threads: u32,
    /// Seconds since last contact.
    pub last_seen_s_ago: f64,
    /// Leases held.
    pub leases: usize,
    /// `idle`, `busy`, `disabled`, `draining` or `offline`.
    pub state: &'static str,
    /// Its tags.
    pub tags: Vec<String>,
}

impl From<WorkerView> for WorkerDto {
    fn from(w: WorkerView) -> Self {
        let (id, name, threads, last_seen_s_ago, leases) = (w.id, w.name, w.threads, w.last_seen_s_ago, w.leases);
        WorkerDto { id, name, threads, last_seen_s_ago, leases, state: w.state, tags: w.tags }
    }
}

/// The parts of `POST /api/v1/jobs` (documentation only: the handler reads them as a stream).
#[derive(utoipa::ToSchema)]
#[allow(dead_code)]
pub struct SubmitForm {
    /// The scene XML; its file name is its path in the bundle (`scene.xml` if none).
    #[schema(value_type = String, format = Binary)]
    scene: (),
    /// A file the scene refers to, named by its path relative to the scene; one part each.
    #[schema(value_type = Option<Vec<String>>, format = Binary)]
    asset: (),
    /// JSON: render settings (`integrator`, `spp`, `seed`, `time_limit_s`, ...), `name`,
    /// `priority`, `after` (job ids), `require_tags`, and for frames `frames` (`"1-240"`),
    /// `frame_param`, `seed_per_frame`, `warm_start`.
    #[schema(value_type = Option<String>)]
    settings: (),
}

/// An RFC 9457 problem document: the body of every error.
#[derive(Serialize, utoipa::ToSchema)]
pub struct Problem {
    /// Always `about:blank`: the status says what kind of error it is.
    #[serde(rename = "type")]
    pub kind: String,
    /// The status's reason phrase.
    pub title: String,
    /// The HTTP status.
    pub status: u16,
    /// What went wrong, naming the field, file or line at fault.
    pub detail: String,
    /// The error class: `invalid_argument`, `not_found`, `unauthenticated`,
    /// `permission_denied`, `failed_precondition`, `payload_too_large`, `resource_exhausted`,
    /// `insufficient_storage`, `method_not_allowed`, `unsupported_media_type` or `internal`.
    pub code: String,
    /// The same as `detail` (the API's error field before problem documents).
    pub error: String,
}
