//! The REST API under `/api/v1` (plus `/healthz` and `/metrics` at the root):
//!
//! | route | what |
//! |---|---|
//! | `POST /api/v1/jobs` | multipart: `scene` file, asset files (`asset`, file name = path relative to the scene), `settings` JSON |
//! | `GET /api/v1/jobs`, `GET /api/v1/jobs/{id}` | job status JSON |
//! | `DELETE /api/v1/jobs/{id}` | cancel |
//! | `GET /api/v1/jobs/{id}/result.exr`, `/preview.png` | outputs of a done job |
//! | `GET /api/v1/workers` | registered workers |
//! | `GET /healthz`, `GET /metrics` | liveness, Prometheus text |

pub mod dto;
pub mod jobs;

use crate::app::AppState;
use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::routing::get;
use std::sync::Arc;

/// The REST router.
pub fn router(state: Arc<AppState>) -> Router {
    let limit = state.max_upload_bytes;
    Router::new()
        .route("/api/v1/jobs", get(jobs::list).post(jobs::submit))
        .route("/api/v1/jobs/{id}", get(jobs::get_one).delete(jobs::cancel))
        .route("/api/v1/jobs/{id}/result.exr", get(jobs::result_exr))
        .route("/api/v1/jobs/{id}/preview.png", get(jobs::preview_png))
        .route("/api/v1/workers", get(jobs::workers))
        .route("/healthz", get(|| async { "ok" }))
        .route("/api/v1/healthz", get(|| async { "ok" }))
        .route("/metrics", get(jobs::metrics))
        .route("/api/v1/metrics", get(jobs::metrics))
        .layer(DefaultBodyLimit::max(limit))
        .with_state(state)
}
