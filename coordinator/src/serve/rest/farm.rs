//! REST handlers of the farm itself: the workers (and their modes), the coordinator's disk and
//! its metrics.

use super::dto::WorkerDto;
use crate::serve::error::{ApiError, ErrorCode};
use crate::serve::state::{AppState, blocking, now_ms};
use crate::serve::storage::WorkerMode;
use axum::Json;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::IntoResponse;
use std::sync::Arc;

type St = State<Arc<AppState>>;

/// `GET /api/v1/server`: the coordinator's own state: its data folder's free space and the
/// reserve below which it takes no new work (`disk.low`).
#[utoipa::path(get, path = "/api/v1/server", tag = "farm",
    responses((status = 200, description = "`{\"disk\": {free_bytes, reserve_bytes, low}}` (`disk` null where unknown)", body = Object)))]
pub async fn server(State(st): St) -> Json<serde_json::Value> {
    let svc = st.svc.clone();
    let disk = tokio::task::spawn_blocking(move || svc.space()).await.ok().flatten();
    Json(serde_json::json!({ "disk": disk }))
}

/// `GET /api/v1/workers`.
#[utoipa::path(get, path = "/api/v1/workers", tag = "farm", responses((status = 200, body = Vec<WorkerDto>)))]
pub async fn workers(State(st): St) -> Result<Json<Vec<WorkerDto>>, ApiError> {
    let svc = st.svc.clone();
    let workers = blocking(move || Ok(svc.workers(now_ms()))).await?;
    Ok(Json(workers.into_iter().map(WorkerDto::from).collect()))
}

/// `POST /api/v1/workers/{id}/disable`, `/enable`, `/drain`.
#[utoipa::path(post, path = "/api/v1/workers/{id}/{action}", tag = "farm",
    params(("id" = String, Path, description = "worker id"), ("action" = String, Path, description = "`disable`, `enable` or `drain`")),
    responses((status = 200, body = WorkerDto)))]
pub async fn worker_mode(
    State(st): St,
    Path((id, action)): Path<(String, String)>,
) -> Result<Json<WorkerDto>, ApiError> {
    let mode = match action.as_str() {
        "disable" => WorkerMode::Disabled,
        "enable" => WorkerMode::Enabled,
        "drain" => WorkerMode::Draining,
        other => return Err(ApiError::new(ErrorCode::NotFound, format!("no worker action \"{other}\""))),
    };
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.set_worker_mode(&id, mode, now_ms())).await?.into()))
}

/// `GET /metrics`: the OpenMetrics text format, which Prometheus reads.
#[utoipa::path(get, path = "/api/v1/metrics", tag = "farm",
    responses((status = 200, description = "Prometheus metrics (also at `/metrics`)", content_type = "application/openmetrics-text", body = String)))]
pub async fn metrics(State(st): St) -> impl IntoResponse {
    let body = tokio::task::spawn_blocking(move || st.telemetry.encode()).await.unwrap_or_default();
    ([(header::CONTENT_TYPE, "application/openmetrics-text; version=1.0.0; charset=utf-8")], body)
}
