//! REST handlers: decode → call the job service → encode.

use super::dto::{JobDto, SubmitForm};
use crate::serve::bundle_stream::StreamedBundle;
use crate::serve::error::{ApiError, ErrorCode};
use crate::serve::job::service::{FramesRequest, JobFilter};
use crate::serve::job::spec::Placement;
use crate::serve::state::{AppState, blocking, now_ms};
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
    // the error names the setting at fault (`integrator`), not only the part
    let settings = serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        let at = if path == "." { String::new() } else { format!(" field \"{path}\"") };
        invalid(format!("settings{at}: {}", e.into_inner()))
    })?;
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
#[utoipa::path(post, path = "/api/v1/jobs", tag = "jobs",
    request_body(content = SubmitForm, content_type = "multipart/form-data"),
    responses((status = 201, description = "the job, accepted", body = JobDto)))]
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

/// A page of `GET /api/v1/jobs`.
#[derive(serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct Page {
    /// Jobs per page: [`DEFAULT_PAGE`] unless given, at most [`MAX_PAGE`].
    #[param(minimum = 1, maximum = 1000)]
    limit: Option<usize>,
    /// Jobs to skip, newest first (at most [`MAX_OFFSET`]).
    #[param(minimum = 0, maximum = 1_000_000_000)]
    offset: Option<usize>,
    /// Only jobs in these states (comma-separated names, as in `state`).
    #[param(pattern = r"^\s*((queued|pilot|optimizing|final|done|failed|cancelled|paused|blocked)?\s*(,\s*|$))*$")]
    state: Option<String>,
    /// Only jobs whose name contains this (case-insensitive).
    name: Option<String>,
}

/// The states a client may filter by.
const STATES: [&str; 9] =
    ["queued", "pilot", "optimizing", "final", "done", "failed", "cancelled", "paused", "blocked"];

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
/// The most jobs a list may skip (far more than a coordinator holds).
pub const MAX_OFFSET: usize = 1_000_000_000;

/// `GET /api/v1/jobs?limit=N&offset=M&state=S,T&name=PART`: newest first, one page of the jobs
/// the filters let through; `X-Total-Count` says how many they let through and a
/// `Link: <...>; rel="next"` header where the next page is.
#[utoipa::path(get, path = "/api/v1/jobs", tag = "jobs", params(Page),
    responses((status = 200, description = "one page of jobs, newest first; `X-Total-Count` and `Link: rel=\"next\"` headers", body = Vec<JobDto>)))]
pub async fn list(State(st): St, Query(page): Query<Page>) -> Result<Response, ApiError> {
    let limit = page.limit.unwrap_or(DEFAULT_PAGE);
    if !(1..=MAX_PAGE).contains(&limit) {
        return Err(ApiError::new(ErrorCode::InvalidArgument, format!("limit must be 1 to {MAX_PAGE}, got {limit}")));
    }
    let offset = page.offset.unwrap_or(0);
    if offset > MAX_OFFSET {
        return Err(invalid(format!("offset must be at most {MAX_OFFSET}, got {offset}")));
    }
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
#[utoipa::path(get, path = "/api/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path, description = "job id or unique prefix")), responses((status = 200, body = JobDto)))]
pub async fn get_one(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.get(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/cancel`: the job stops and stays, `cancelled`.
#[utoipa::path(post, path = "/api/v1/jobs/{id}/cancel", tag = "jobs", params(("id" = String, Path, description = "job id or unique prefix")), responses((status = 200, body = JobDto)))]
pub async fn cancel(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.cancel(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/pause`: no more tiles are handed out until it is resumed.
#[utoipa::path(post, path = "/api/v1/jobs/{id}/pause", tag = "jobs", params(("id" = String, Path, description = "job id or unique prefix")), responses((status = 200, body = JobDto)))]
pub async fn pause(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.pause(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/resume`.
#[utoipa::path(post, path = "/api/v1/jobs/{id}/resume", tag = "jobs", params(("id" = String, Path, description = "job id or unique prefix")), responses((status = 200, body = JobDto)))]
pub async fn resume(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.resume_job(&id, now_ms())).await?.into()))
}

/// `POST /api/v1/jobs/{id}/requeue`: a failed or cancelled job runs on from its checkpoint.
#[utoipa::path(post, path = "/api/v1/jobs/{id}/requeue", tag = "jobs", params(("id" = String, Path, description = "job id or unique prefix")), responses((status = 200, body = JobDto)))]
pub async fn requeue(State(st): St, Path(id): Path<String>) -> Result<Json<JobDto>, ApiError> {
    let svc = st.svc.clone();
    Ok(Json(blocking(move || svc.requeue(&id, now_ms())).await?.into()))
}

/// What `PATCH /api/v1/jobs/{id}` may change.
#[derive(serde::Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JobPatch {
    /// Higher runs first (an integer: `3` or `3.0`).
    #[schema(value_type = Option<i32>)]
    priority: Option<serde_json::Number>,
}

/// A JSON number as an `i32` priority: integral values in range only (JSON Schema counts
/// `3.0` as an integer, so it is one).
fn priority_of(n: &serde_json::Number) -> Result<i32, ApiError> {
    let whole = n.as_i64().or_else(|| n.as_f64().filter(|f| f.fract() == 0.0 && f.abs() < 1e15).map(|f| f as i64));
    whole.and_then(|p| i32::try_from(p).ok()).ok_or_else(|| {
        invalid(format!("field \"priority\" must be an integer from {} to {}, got {n}", i32::MIN, i32::MAX))
    })
}

/// `PATCH /api/v1/jobs/{id}` with `{"priority": N}`.
#[utoipa::path(patch, path = "/api/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path, description = "job id or unique prefix")), request_body = JobPatch,
    responses((status = 200, body = JobDto)))]
pub async fn patch(
    State(st): St,
    Path(id): Path<String>,
    body: Result<Json<JobPatch>, axum::extract::rejection::JsonRejection>,
) -> Result<Json<JobDto>, ApiError> {
    let Json(patch) = body.map_err(|e| ApiError::new(ErrorCode::InvalidArgument, e.body_text()))?;
    let priority = patch.priority.as_ref().map(priority_of).transpose()?;
    let svc = st.svc.clone();
    let view = blocking(move || match priority {
        Some(p) => svc.set_priority(&id, p, now_ms()),
        None => svc.get(&id, now_ms()),
    })
    .await?;
    Ok(Json(view.into()))
}

/// `DELETE /api/v1/jobs/{id}`: removes an ended job and its data (204); an active one is a
/// conflict (409) until it is cancelled.
#[utoipa::path(delete, path = "/api/v1/jobs/{id}", tag = "jobs", params(("id" = String, Path, description = "job id or unique prefix")),
    responses((status = 204, description = "deleted with all its data")))]
pub async fn delete(State(st): St, Path(id): Path<String>) -> Result<axum::http::StatusCode, ApiError> {
    let svc = st.svc.clone();
    blocking(move || svc.delete(&id)).await?;
    Ok(axum::http::StatusCode::NO_CONTENT)
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
        let e = parse_settings(r#"{"integrator":"nonsense"}"#).unwrap_err();
        assert!(e.message.starts_with("settings field \"integrator\": unknown variant"), "{}", e.message);
        let e = parse_settings(r#"{"priority":"high"}"#).unwrap_err();
        assert!(e.message.contains("priority"));
        // retired settings: their old default accepted, a retired variant refused by name
        let (s, _, _, _) = parse_settings(r#"{"integrator":"emis-vcm","merge_ratio":"principled"}"#).unwrap();
        assert_eq!(s.integrator, tessera_common::settings::IntegratorName::EmisVcm);
        let e = parse_settings(r#"{"integrator":"emis-vcm","cost_model":"reference"}"#).unwrap_err();
        assert!(e.message.contains("cost_model") && e.message.contains("retired"), "{}", e.message);
    }

    #[test]
    fn priorities_are_whole_numbers_in_range() {
        let n = |text: &str| serde_json::from_str::<serde_json::Number>(text).unwrap();
        assert_eq!(priority_of(&n("3")).unwrap(), 3);
        assert_eq!(priority_of(&n("-7.0")).unwrap(), -7);
        assert!(priority_of(&n("2.5")).unwrap_err().message.contains("priority"));
        assert!(priority_of(&n("4294967296")).is_err());
        assert!(priority_of(&n("1e300")).is_err());
    }

    #[test]
    fn list_filters_name_unknown_states() {
        let page =
            |state: &str| Page { limit: None, offset: None, state: Some(state.into()), name: Some("Shot 1".into()) };
        let f = filter_of(&page("done, failed")).unwrap();
        assert_eq!((f.states, f.name.as_deref()), (vec!["done".to_string(), "failed".into()], Some("Shot 1")));
        let e = filter_of(&page("done,finished")).unwrap_err();
        assert!(e.message.contains("\"finished\"") && e.message.contains("cancelled"), "{}", e.message);
    }
}
