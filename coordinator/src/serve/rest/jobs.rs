//! REST handlers: decode → call the job service → encode.

use super::dto::{JobDto, WorkerDto};
use crate::serve::bundle_stream::StreamedBundle;
use crate::serve::error::{ApiError, ErrorCode};
use crate::serve::job::service::{FramesRequest, JobFilter, OutputKind};
use crate::serve::job::spec::Placement;
use crate::serve::state::{AppState, blocking, now_ms};
use crate::serve::storage::WorkerMode;
use axum::Json;
use axum::extract::{Multipart, Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use tessera_common::settings::RenderSettings;

type St = State<Arc<AppState>>;

fn invalid(message: impl Into<String>) -> ApiError {
    ApiError::new(ErrorCode::InvalidArgument, message)
}

fn multipart_error(e: axum::extract::multipart::MultipartError) -> ApiError {
    if e.status() == axum::http::StatusCode::PAYLOAD_TOO_LARGE {
        let message = format!("upload too large: {} (tessera serve --max-upload-mb)", e.body_text());
        ApiError::new(ErrorCode::PayloadTooLarge, message)
    } else {
        invalid(format!("malformed multipart body: {}", e.body_text()))
    }
}

/// What a submission's `settings` part holds besides the render settings.
type Submission = (RenderSettings, Placement, Option<String>, Option<FramesRequest>);

/// Splits the `settings` JSON into render settings, placement (`priority`, `after`,
/// `require_tags`), name and frames (`frames`, `frame_param`, `seed_per_frame`, `warm_start`).
fn parse_settings(text: &str) -> Result<Submission, ApiError> {
    let mut value: serde_json::Value =
        serde_json::from_str(text).map_err(|e| invalid(format!("field \"settings\" is not JSON: {e}")))?;
    let obj = value.as_object_mut().ok_or_else(|| invalid("field \"settings\" must be a JSON object"))?;
    let priority = match obj.remove("priority") {
        None => 0,
        Some(p) => p
            .as_i64()
            .and_then(|p| i32::try_from(p).ok())
            .ok_or_else(|| invalid("settings field \"priority\" must be an integer"))?,
    };
    let mut list = |field: &str, what: &str| match obj.remove(field) {
        None => Ok(Vec::new()),
        Some(a) => serde_json::from_value(a)
            .map_err(|_| invalid(format!("settings field \"{field}\" must be an array of {what}"))),
    };
    let after = list("after", "job ids")?;
    let require_tags = list("require_tags", "tags")?;
    let frames = frames_of(obj)?;
    let name = obj.remove("name").and_then(|n| n.as_str().map(str::to_string));
    tessera_common::settings::strip_retired(obj).map_err(|e| invalid(e.to_string()))?;
    let settings = serde_json::from_value(value).map_err(|e| invalid(format!("field \"settings\": {e}")))?;
    Ok((settings, Placement { priority, after, require_tags }, name, frames))
}

/// The settings' `frames` (`"1-240"`), `frame_param`, `seed_per_frame` and `warm_start`, if it
/// asks for any.
fn frames_of(obj: &mut serde_json::Map<String, serde_json::Value>) -> Result<Option<FramesRequest>, ApiError> {
    let mut text = |field: &str| match obj.remove(field) {
        None => Ok(None),
        Some(serde_json::Value::String(s)) => Ok(Some(s)),
        Some(_) => Err(invalid(format!("settings field \"{field}\" must be a string"))),
    };
    let (frames, param) = (text("frames")?, text("frame_param")?);
    let mut flag = |field: &str| match obj.remove(field) {
        None => Ok(false),
        Some(v) => v.as_bool().ok_or_else(|| invalid(format!("settings field \"{field}\" must be true or false"))),
    };
    let (seed_per_frame, warm_start) = (flag("seed_per_frame")?, flag("warm_start")?);
    let Some(frames) = frames else {
        if warm_start {
            return Err(invalid("settings field \"warm_start\" needs \"frames\""));
        }
        return Ok(None);
    };
    let frames =
        tessera_link::frames::parse(&frames).map_err(|e| invalid(format!("settings field \"frames\": {e}")))?;
    let param = param.unwrap_or_else(|| "frame".into());
    Ok(Some(FramesRequest { frames, param, seed_per_frame, warm_start }))
}

/// Most bytes the `settings` part may have.
const MAX_SETTINGS_BYTES: usize = 1 << 20;

/// `POST /api/v1/jobs`: a multipart form with a `settings` JSON part, the `scene` part and a
/// part per further file (its file name the path in the bundle). Files are written to disk as
/// they arrive.
pub async fn submit(State(st): St, mut form: Multipart) -> Result<impl IntoResponse, ApiError> {
    let mut bundle = StreamedBundle::begin(st.svc.clone(), st.max_upload_bytes as u64).await?;
    let mut scene_path = None;
    let mut settings = (RenderSettings::default(), Placement::default(), None, None);
    while let Some(mut field) = form.next_field().await.map_err(multipart_error)? {
        let name = field.name().unwrap_or("").to_string();
        let file_name = field.file_name().map(str::to_string);
        if name == "settings" {
            let mut data = Vec::new();
            while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
                data.extend_from_slice(&chunk);
                if data.len() > MAX_SETTINGS_BYTES {
                    return Err(invalid(format!("field \"settings\" is over {MAX_SETTINGS_BYTES} bytes")));
                }
            }
            let text = std::str::from_utf8(&data).map_err(|_| invalid("field \"settings\" is not UTF-8"))?;
            settings = parse_settings(text)?;
            continue;
        }
        let path = if name == "scene" {
            let path = file_name.unwrap_or_else(|| "scene.xml".into());
            scene_path = Some(path.clone());
            path
        } else {
            file_name.ok_or_else(|| invalid(format!("part \"{name}\" needs a file name (its path)")))?
        };
        bundle.start_file(path).await?;
        while let Some(chunk) = field.chunk().await.map_err(multipart_error)? {
            bundle.write(&chunk).await?;
        }
    }
    let scene_path = scene_path.ok_or_else(|| invalid("field \"scene\" is missing (the scene XML file)"))?;
    let (settings, placement, name, frames) = settings;
    let view = bundle.submit(scene_path, settings, placement, name, frames).await?;
    Ok((axum::http::StatusCode::CREATED, Json(JobDto::from(view))))
}

/// `GET /api/v1/server`: the coordinator's own state: its data folder's free space and the
/// reserve below which it takes no new work (`disk.low`).
pub async fn server(State(st): St) -> Json<serde_json::Value> {
    let svc = st.svc.clone();
    let disk = tokio::task::spawn_blocking(move || svc.space()).await.ok().flatten();
    Json(serde_json::json!({ "disk": disk }))
}

/// A page of `GET /api/v1/jobs`.
#[derive(serde::Deserialize)]
pub struct Page {
    /// Jobs per page: [`DEFAULT_PAGE`] unless given, at most [`MAX_PAGE`].
    limit: Option<usize>,
    /// Jobs to skip, newest first.
    offset: Option<usize>,
    /// Only jobs in these states (comma-separated names, as in `state`).
    state: Option<String>,
    /// Only jobs whose name contains this (case-insensitive).
    name: Option<String>,
}

/// The states a client may filter by.
const STATES: [&str; 9] = ["queued", "pilot", "optimizing", "final", "done", "failed", "cancelled", "paused", "blocked"];

/// The filter of a list request: unknown state names are refused by name.
fn filter_of(page: &Page) -> Result<JobFilter, ApiError> {
    let mut states = Vec::new();
    for s in page.state.iter().flat_map(|s| s.split(',')).map(str::trim).filter(|s| !s.is_empty()) {
        if !STATES.contains(&s) {
            return Err(invalid(format!("state \"{s}\" is not one of {}", STATES.join(", "))));
        }
        states.push(s.to_string());
    }
    Ok(JobFilter { states, name: page.name.clone().filter(|n| !n.is_empty()) })
}

/// Jobs per page of `GET /api/v1/jobs` unless `limit` says otherwise ...
pub const DEFAULT_PAGE: usize = 100;
/// ... and at most.
pub const MAX_PAGE: usize = 1000;

/// `GET /api/v1/jobs?limit=N&offset=M&state=S,T&name=PART`: newest first, one page of the jobs
/// the filters let through; `X-Total-Count` says how many they let through and a
/// `Link: <...>; rel="next"` header where the next page is.
pub async fn list(State(st): St, Query(page): Query<Page>) -> Result<Response, ApiError> {
    let limit = page.limit.unwrap_or(DEFAULT_PAGE);
    if !(1..=MAX_PAGE).contains(&limit) {
        return Err(ApiError::new(ErrorCode::InvalidArgument, format!("limit must be 1 to {MAX_PAGE}, got {limit}")));
    }
    let offset = page.offset.unwrap_or(0);
    let filter = filter_of(&page)?;
    let svc = st.svc.clone();
    let (jobs, total) = blocking(move || svc.list_page(now_ms(), offset, limit, &filter)).await?;
    let mut response = Json(jobs.into_iter().map(JobDto::from).collect::<Vec<_>>()).into_response();
    let headers = response.headers_mut();
    headers.insert("x-total-count", total.into());
    if offset + limit < total {
        let mut query = form_urlencoded::Serializer::new(String::new());
        query.append_pair("limit", &limit.to_string()).append_pair("offset", &(offset + limit).to_string());
        for (key, value) in [("state", &page.state), ("name", &page.name)] {
            if let Some(value) = value {
                query.append_pair(key, value);
            }
        }
        let next = format!("</api/v1/jobs?{}>; rel=\"next\"", query.finish());
        headers.insert(header::LINK, next.parse().expect("invariant: ASCII header"));
    }
    Ok(response)
}

/// `GET /api/v1/jobs/{id}`.
pub async fn get_one(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.get(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/cancel`: the job stops and stays, `cancelled`.
pub async fn cancel(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.cancel(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/pause`: no more tiles are handed out until it is resumed.
pub async fn pause(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.pause(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/resume`.
pub async fn resume(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.resume_job(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/requeue`: a failed or cancelled job runs on from its checkpoint.
pub async fn requeue(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.requeue(&id, now_ms())).await?.into()))
}

/// What `PATCH /api/v1/jobs/{id}` may change.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JobPatch {
    /// Higher runs first.
    priority: Option<i32>,
}

/// `PATCH /api/v1/jobs/{id}` with `{"priority": N}`.
pub async fn patch(
    State(st): St,
    Path(id): Path<String>,
    body: Result<Json<JobPatch>, axum::extract::rejection::JsonRejection>,
) -> Result<Json<JobDto>, ApiError> {
    let Json(patch) = body.map_err(|e| ApiError::new(ErrorCode::InvalidArgument, e.body_text()))?;
    let svc = st.svc.clone();
    let view = blocking(move || match patch.priority {
        Some(p) => svc.set_priority(&id, p, now_ms()),
        None => svc.get(&id, now_ms()),
    })
    .await?;
    Ok(Json(view.into()))
}

/// `DELETE /api/v1/jobs/{id}`: removes an ended job and its data (204); an active one is a
/// conflict (409) until it is cancelled.
pub async fn delete(State(st): St, Path(id): Path<String>) -> Result<axum::http::StatusCode, ApiError> {
    let svc = st.svc.clone();
    blocking(move || svc.delete(&id)).await?;
    Ok(axum::http::StatusCode::NO_CONTENT)
}

async fn output(st: Arc<AppState>, id: String, kind: OutputKind) -> Result<impl IntoResponse, ApiError> {
    let svc = st.svc.clone();
    let bytes = blocking(move || svc.output(&id, kind)).await?;
    Ok(([(header::CONTENT_TYPE, kind.mime())], bytes))
}

/// `GET /api/v1/jobs/{id}/frames.tar`: a job of frames' done frames, each `NAME.NNNN.exr` and
/// `.png`, as one tar streamed as it is written.
pub async fn frames_tar(State(st): St, Path(id): Path<String>) -> Result<Response, ApiError> {
    let svc = st.svc.clone();
    let files = blocking(move || svc.frame_files(&id)).await?;
    let (tx, rx) = tokio::sync::mpsc::channel::<std::io::Result<axum::body::Bytes>>(8);
    tokio::task::spawn_blocking(move || {
        let mut tar = tar::Builder::new(ChannelWriter(tx.clone()));
        let written = files.into_iter().try_for_each(|(name, mut file)| {
            let mut header = tar::Header::new_gnu();
            header.set_size(file.metadata()?.len());
            header.set_mode(0o644);
            header.set_cksum();
            tar.append_data(&mut header, name, &mut file)
        });
        // a failure midway ends the body with an error, so the client sees a broken download
        if let Err(e) = written.and_then(|()| tar.finish()) {
            let _ = tx.blocking_send(Err(e));
        }
    });
    let body = axum::body::Body::from_stream(tokio_stream::wrappers::ReceiverStream::new(rx));
    Ok(([(header::CONTENT_TYPE, "application/x-tar")], body).into_response())
}

/// Sends what a blocking writer writes to an async body, a chunk at a time.
struct ChannelWriter(tokio::sync::mpsc::Sender<std::io::Result<axum::body::Bytes>>);

impl std::io::Write for ChannelWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let chunk = axum::body::Bytes::copy_from_slice(buf);
        self.0.blocking_send(Ok(chunk)).map_err(|_| std::io::Error::other("the client went away"))?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// `GET /api/v1/jobs/{id}/result.exr`.
pub async fn result_exr(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::Exr).await
}

/// `GET /api/v1/jobs/{id}/preview.png`.
pub async fn preview_png(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::Png).await
}

/// `GET /api/v1/jobs/{id}/strategy.png`: EMIS jobs only (404 for others).
pub async fn strategy_png(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::StrategyPng).await
}

/// `GET /api/v1/jobs/{id}/emis.json`: EMIS jobs only (404 for others).
pub async fn emis_json(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::EmisJson).await
}

/// `GET /api/v1/workers`.
pub async fn workers(State(st): St) -> Result<Json<Vec<WorkerDto>>, ApiError> {
    let svc = st.svc.clone();
    let workers = blocking(move || Ok(svc.workers(now_ms()))).await?;
    Ok(Json(workers.into_iter().map(WorkerDto::from).collect()))
}

/// `POST /api/v1/workers/{id}/disable`, `/enable`, `/drain`.
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
pub async fn metrics(State(st): St) -> impl IntoResponse {
    let body = tokio::task::spawn_blocking(move || st.telemetry.encode()).await.unwrap_or_default();
    ([(header::CONTENT_TYPE, "application/openmetrics-text; version=1.0.0; charset=utf-8")], body)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_json_names_the_bad_field() {
        let (s, p, n, _) =
            parse_settings(r#"{"integrator":"vcm","spp":2,"priority":3,"name":"x","after":["j1"]}"#).unwrap();
        let placement = Placement { priority: 3, after: vec!["j1".into()], require_tags: vec![] };
        assert_eq!((s.spp, p, n.as_deref()), (Some(2), placement, Some("x")));
        let e = parse_settings(r#"{"after":"j1"}"#).unwrap_err();
        assert!(e.message.contains("after"), "{}", e.message);
        let e = parse_settings(r#"{"integrator":"vcm","spq":2}"#).unwrap_err();
        assert!(e.message.contains("spq"), "{}", e.message);
        let e = parse_settings(r#"{"priority":"high"}"#).unwrap_err();
        assert!(e.message.contains("priority"));
        // retired settings: their old default accepted, a retired variant refused by name
        let (s, _, _, _) = parse_settings(r#"{"integrator":"emis-vcm","merge_ratio":"principled"}"#).unwrap();
        assert_eq!(s.integrator, tessera_common::settings::IntegratorName::EmisVcm);
        let e = parse_settings(r#"{"integrator":"emis-vcm","cost_model":"reference"}"#).unwrap_err();
        assert!(e.message.contains("cost_model") && e.message.contains("retired"), "{}", e.message);
    }

    #[test]
    fn list_filters_name_unknown_states() {
        let page = |state: &str| Page { limit: None, offset: None, state: Some(state.into()), name: Some("Shot 1".into()) };
        let f = filter_of(&page("done, failed")).unwrap();
        assert_eq!((f.states, f.name.as_deref()), (vec!["done".to_string(), "failed".into()], Some("Shot 1")));
        let e = filter_of(&page("done,finished")).unwrap_err();
        assert!(e.message.contains("\"finished\"") && e.message.contains("cancelled"), "{}", e.message);
    }
}
