//! Server-sent events: `GET /api/v1/events` (everything) and `GET /api/v1/jobs/{id}/events`
//! (one job, opening with its current state and ending once it is done, failed, cancelled or
//! deleted). Each event's `data` is JSON; its `event` name says what it is (see
//! [`crate::serve::events::Event::kind`]); a subscriber that fell behind gets a `lagged` event
//! with how many it missed and should read the jobs again. Events carry the whole state of
//! what changed, seen at most [`crate::serve::events::PERIOD`] after the change: a state that
//! lasted less than that may be skipped, never the one a job ends in.

use crate::serve::error::ApiError;
use crate::serve::events::{Event, JobLine};
use crate::serve::state::{AppState, blocking, now_ms};
use axum::extract::{Path, State};
use axum::response::sse::{self, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use std::convert::Infallible;
use std::sync::Arc;
use tokio::sync::{broadcast, mpsc};
use tokio_stream::wrappers::ReceiverStream;

/// One event of a stream, as OpenAPI describes it (documentation only).
#[derive(utoipa::ToSchema)]
#[allow(dead_code)]
pub struct SseEvent {
    /// Increasing number.
    id: Option<String>,
    /// `job.state`, `job.progress`, `job.deleted`, `frame.state`, `worker`, `worker.gone` or
    /// `lagged`.
    event: Option<String>,
    /// JSON: the whole new state of what changed (`job_id` names a job).
    data: Option<String>,
    /// Unused (the client's default reconnection delay applies).
    retry: Option<u64>,
}

fn to_sse(e: &Event) -> sse::Event {
    sse::Event::default().id(e.id.to_string()).event(e.kind).data(&e.data)
}

/// Forwards `rx`'s events that `keep` lets through to a new stream, until the client goes away
/// or an event `last` says ends it. The stream opens with `opening`.
fn stream(
    mut rx: broadcast::Receiver<Arc<Event>>,
    opening: Vec<sse::Event>,
    keep: impl Fn(&Event) -> bool + Send + 'static,
    last: impl Fn(&Event) -> bool + Send + 'static,
) -> Response {
    let (tx, out) = mpsc::channel::<Result<sse::Event, Infallible>>(16);
    tokio::spawn(async move {
        for e in opening {
            if tx.send(Ok(e)).await.is_err() {
                return;
            }
        }
        loop {
            let event = tokio::select! {
                _ = tx.closed() => return,
                event = rx.recv() => event,
            };
            let (sse, end) = match event {
                Ok(e) if keep(&e) => (to_sse(&e), last(&e)),
                Ok(_) => continue,
                Err(broadcast::error::RecvError::Lagged(n)) => {
                    (sse::Event::default().event("lagged").data(format!("{{\"missed\":{n}}}")), false)
                }
                Err(broadcast::error::RecvError::Closed) => return,
            };
            if tx.send(Ok(sse)).await.is_err() || end {
                return;
            }
        }
    });
    Sse::new(ReceiverStream::new(out)).keep_alive(KeepAlive::default()).into_response()
}

/// `GET /api/v1/events`: every change of every job, frame and worker from now on.
#[utoipa::path(get, path = "/api/v1/events", tag = "events",
    responses((status = 200, description = "server-sent events: job.state, job.progress, job.deleted, frame.state, worker, worker.gone, lagged", content_type = "text/event-stream", body = SseEvent)))]
pub async fn all(State(st): State<Arc<AppState>>) -> Response {
    stream(st.events.subscribe(), Vec::new(), |_| true, |_| false)
}

/// `GET /api/v1/jobs/{id}/events`: the job's state now (a `job.state` event), then its changes
/// (a job of frames' frames included) until it ends.
#[utoipa::path(get, path = "/api/v1/jobs/{id}/events", tag = "events", params(("id" = String, Path, description = "job id or unique prefix")),
    responses((status = 200, description = "server-sent events of one job, ending with the state it ends in", content_type = "text/event-stream", body = SseEvent)))]
pub async fn of_job(State(st): State<Arc<AppState>>, Path(id): Path<String>) -> Result<Response, ApiError> {
    // subscribed before the state is read, so no change in between is missed
    let rx = st.events.subscribe();
    let svc = st.svc.clone();
    let view = blocking(move || svc.get(&id, now_ms())).await?;
    let opening = st.events.single("job.state", &JobLine::of(&view));
    let ends_now = opening.ends_job;
    let id = view.id;
    let first = vec![to_sse(&opening)];
    if ends_now {
        let once = tokio_stream::iter(first.into_iter().map(Ok::<_, Infallible>));
        return Ok(Sse::new(once).into_response());
    }
    let keep_id = id.clone();
    Ok(stream(rx, first, move |e| e.concerns(&keep_id), move |e| e.ends(&id)))
}
