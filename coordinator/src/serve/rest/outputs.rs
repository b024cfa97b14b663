//! REST handlers of a job's outputs: the finished EXR and PNG, a job of frames' tar, and an
//! EMIS job's strategy picture and report.

use crate::serve::error::ApiError;
use crate::serve::job::service::OutputKind;
use crate::serve::state::{AppState, blocking};
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

type St = State<Arc<AppState>>;

async fn output(st: Arc<AppState>, id: String, kind: OutputKind) -> Result<impl IntoResponse, ApiError> {
    let svc = st.svc.clone();
    let bytes = blocking(move || svc.output(&id, kind)).await?;
    Ok(([(header::CONTENT_TYPE, kind.mime())], bytes))
}

/// `GET /api/v1/jobs/{id}/frames.tar`: a job of frames' done frames, each `NAME.NNNN.exr` and
/// `.png`, as one tar streamed as it is written.
#[utoipa::path(get, path = "/api/v1/jobs/{id}/frames.tar", tag = "outputs", params(("id" = String, Path, description = "job id or unique prefix")),
    responses((status = 200, description = "the done frames, `NAME.NNNN.exr` and `.png` each", content_type = "application/x-tar", body = Vec<u8>)))]
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
#[utoipa::path(get, path = "/api/v1/jobs/{id}/result.exr", tag = "outputs", params(("id" = String, Path, description = "job id or unique prefix")),
    responses((status = 200, description = "the image (409 until the job is done)", content_type = "image/x-exr", body = Vec<u8>)))]
pub async fn result_exr(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::Exr).await
}

/// `GET /api/v1/jobs/{id}/preview.png`.
#[utoipa::path(get, path = "/api/v1/jobs/{id}/preview.png", tag = "outputs", params(("id" = String, Path, description = "job id or unique prefix")),
    responses((status = 200, description = "the tone-mapped image (409 until the job is done)", content_type = "image/png", body = Vec<u8>)))]
pub async fn preview_png(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::Png).await
}

/// `GET /api/v1/jobs/{id}/strategy.png`: EMIS jobs only (404 for others).
#[utoipa::path(get, path = "/api/v1/jobs/{id}/strategy.png", tag = "outputs", params(("id" = String, Path, description = "job id or unique prefix")),
    responses((status = 200, description = "the EMIS strategy picture", content_type = "image/png", body = Vec<u8>)))]
pub async fn strategy_png(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::StrategyPng).await
}

/// `GET /api/v1/jobs/{id}/emis.json`: EMIS jobs only (404 for others).
#[utoipa::path(get, path = "/api/v1/jobs/{id}/emis.json", tag = "outputs", params(("id" = String, Path, description = "job id or unique prefix")),
    responses((status = 200, description = "the EMIS report of every update", body = Object)))]
pub async fn emis_json(State(st): St, Path(id): Path<String>) -> Result<impl IntoResponse, ApiError> {
    output(st, id, OutputKind::EmisJson).await
}
