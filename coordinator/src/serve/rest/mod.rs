//! The REST API under `/api/v1` (plus `/healthz` and `/metrics` at the root):
//!
//! | route | what |
//! |---|---|
//! | `POST /api/v1/jobs` | multipart: `scene` file, asset files (`asset`, file name = path relative to the scene), `settings` JSON |
//! | `GET /api/v1/jobs`, `GET /api/v1/jobs/{id}` | job status JSON; the list is paged (`limit`, `offset`) and filtered (`state=done,failed`, `name=` part of the name) |
//! | `GET /api/v1/events`, `GET /api/v1/jobs/{id}/events` | server-sent events: job state and progress, frames, workers ([`events`]) |
//! | `POST /api/v1/jobs/{id}/cancel` | cancel: the job stops and stays, `cancelled` |
//! | `POST /api/v1/jobs/{id}/pause`, `/resume` | no more tiles handed out (`paused`; leased ones finish), and on again |
//! | `POST /api/v1/jobs/{id}/requeue` | a failed or cancelled job runs on from its last checkpoint |
//! | `PATCH /api/v1/jobs/{id}` | `{"priority": N}`: a new priority (higher runs first) |
//! | `DELETE /api/v1/jobs/{id}` | delete an ended job and all its data (204; 409 while it is active) |
//! | `GET /api/v1/jobs/{id}/result.exr`, `/preview.png` | outputs of a done job (409 before) |
//! | `GET /api/v1/jobs/{id}/frames.tar` | a job of frames' done frames, `NAME.NNNN.exr` and `.png` each, as one tar |
//! | `GET /api/v1/jobs/{id}/strategy.png`, `/emis.json` | a done EMIS job's strategy picture and report (404 for other integrators) |
//! | `GET /api/v1/workers` | registered workers: state (idle, busy, disabled, draining, offline), tags, leases |
//! | `POST /api/v1/workers/{id}/disable`, `/enable`, `/drain` | no new tiles; tiles again; no new tiles and stop when idle |
//! | `GET /api/v1/server` | the coordinator's disk: free bytes, reserve, whether it is below it (`disk.low`) |
//! | `GET /healthz`, `GET /metrics` | liveness, Prometheus text |
//! | `GET /api/v1/openapi.json` | the OpenAPI 3.1 document of all of the above, generated from the handlers ([`openapi`]) |
//! | `GET /` | the dashboard: a static page that polls the API (jobs, progress, EMIS strategy, previews, workers) |
//!
//! Every error is an RFC 9457 problem document (`application/problem+json`: `type`, `title`,
//! `status`, `detail`, and `code`, the class in the error table of [`crate::serve::error`]).

pub mod dto;
pub mod events;
pub mod farm;
pub mod jobs;
pub mod openapi;
pub mod outputs;

use crate::serve::state::AppState;
use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::routing::get;
use std::sync::Arc;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

/// The REST router. Its API routes are registered with their OpenAPI descriptions, so the
/// document at `/api/v1/openapi.json` lists exactly the routes served.
pub fn router(state: Arc<AppState>) -> Router {
    let limit = state.max_upload_bytes;
    let (api, doc) = OpenApiRouter::<Arc<AppState>>::with_openapi(openapi::base())
        .routes(routes!(jobs::list, jobs::submit))
        .routes(routes!(jobs::get_one, jobs::delete, jobs::patch))
        .routes(routes!(events::all))
        .routes(routes!(events::of_job))
        .routes(routes!(jobs::cancel))
        .routes(routes!(jobs::pause))
        .routes(routes!(jobs::resume))
        .routes(routes!(jobs::requeue))
        .routes(routes!(outputs::result_exr))
        .routes(routes!(outputs::frames_tar))
        .routes(routes!(outputs::preview_png))
        .routes(routes!(outputs::strategy_png))
        .routes(routes!(outputs::emis_json))
        .routes(routes!(farm::workers))
        .routes(routes!(farm::worker_mode))
        .routes(routes!(farm::server))
        .routes(routes!(farm::metrics))
        .routes(routes!(openapi::healthz))
        .split_for_parts();
    let doc = axum::body::Bytes::from(openapi::document(doc));
    api.route("/api/v1/openapi.json", get(move || openapi::serve(doc.clone())))
        .route("/", get(dashboard))
        .route("/dashboard", get(dashboard))
        .route("/healthz", get(openapi::healthz))
        .route("/metrics", get(farm::metrics))
        .layer(DefaultBodyLimit::max(limit))
        .layer(axum::middleware::from_fn_with_state(limit, refuse_oversized))
        .with_state(state)
}

/// The dashboard page. It holds no data (it fetches the API with the token the user types in),
/// so it is served without authentication.
async fn dashboard() -> axum::response::Html<&'static str> {
    axum::response::Html(include_str!("dashboard.html"))
}

/// Bodies up to this much over the limit are read and discarded before the 413 goes out.
const DRAIN_CAP: u64 = 64 << 20;

/// Answers 413 to a request whose `Content-Length` exceeds the upload limit. A modestly
/// oversized body is read and discarded first: closing the socket while the client is still
/// sending makes it see a connection reset instead of the 413. (Chunked bodies without a
/// length are cut off by `DefaultBodyLimit` as they are read.)
async fn refuse_oversized(
    axum::extract::State(limit): axum::extract::State<usize>,
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    use axum::response::IntoResponse;
    use tokio_stream::StreamExt;
    let length = req.headers().get(http::header::CONTENT_LENGTH).and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
    match length {
        Some(n) if n > limit as u64 => {
            if n <= limit as u64 + DRAIN_CAP {
                let mut body = req.into_body().into_data_stream();
                while let Some(Ok(_)) = body.next().await {}
            }
            let message = format!("upload of {n} bytes exceeds the limit of {limit} bytes (--max-upload-mb)");
            crate::serve::error::ApiError::new(crate::serve::error::ErrorCode::PayloadTooLarge, message).into_response()
        }
        _ => next.run(req).await,
    }
}
