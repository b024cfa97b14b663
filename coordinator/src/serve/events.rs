//! The event stream behind `GET /api/v1/events`: one task compares the service's jobs and
//! workers from one moment to the next ([`Snapshot::changes`]) and broadcasts each change,
//! encoded once, to every subscriber. Nothing is computed while nobody listens, and a slow
//! subscriber loses events (it is told so) instead of holding memory.

use crate::serve::job::service::{JobService, JobView, WorkerView};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tokio::sync::broadcast;

/// How often the publisher looks for changes: the most an event lags behind the change.
pub const PERIOD: Duration = Duration::from_millis(250);
/// Events a subscriber may fall behind before it loses some.
const BACKLOG: usize = 1024;

/// One event, encoded once for all subscribers.
#[derive(Debug, PartialEq)]
pub struct Event {
    /// Increasing over the coordinator's life (the SSE `id`).
    pub id: u64,
    /// `job.state`, `job.progress`, `job.deleted`, `frame.state`, `worker` or `worker.gone`.
    pub kind: &'static str,
    /// The job it is about (a frame's job of frames), for the per-job streams.
    pub job: Option<String>,
    /// A frame's own job id, so a frame's job can be watched by its id too.
    pub frame_job: Option<String>,
    /// After it, the job (for `frame.state`, the frame's job) stays as it is unless a client
    /// acts: done, failed, cancelled, deleted.
    pub ends_job: bool,
    /// The JSON payload.
    pub data: String,
}

impl Event {
    /// Whether a stream of `job` shows it.
    pub fn concerns(&self, job: &str) -> bool {
        self.job.as_deref() == Some(job) || self.frame_job.as_deref() == Some(job)
    }

    /// Whether a stream of `job` ends with it: `job` (a job, or a frame's job watched by its
    /// own id) has ended; a frame ending does not end its job of frames' stream.
    pub fn ends(&self, job: &str) -> bool {
        let about = if self.kind == "frame.state" { &self.frame_job } else { &self.job };
        self.ends_job && about.as_deref() == Some(job)
    }
}

/// A job as events show it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct JobLine {
    /// Id.
    pub job_id: String,
    /// Name.
    pub name: String,
    /// State, as in the job's JSON.
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
    /// A job of frames: how many are done.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_done: Option<usize>,
    /// Estimated seconds left (not compared: it moves with the clock).
    pub eta_s: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
}

impl JobLine {
    /// The line of a job's view.
    pub fn of(v: &JobView) -> JobLine {
        let frames_done = (v.frames_total > 0).then(|| v.frames.iter().filter(|f| f.state.as_str() == "done").count());
        JobLine {
            job_id: v.id.clone(),
            name: v.name.clone(),
            state: v.state.as_str(),
            phase: v.phase.clone(),
            progress: v.progress,
            tiles_done: v.tiles_done,
            tiles_total: v.tiles_total,
            samples_done: v.samples_done,
            frames_done,
            eta_s: v.eta_s,
            error: v.error.clone(),
        }
    }

    fn same_but_eta(&self, other: &JobLine) -> bool {
        let mut same_eta = self.clone();
        same_eta.eta_s = other.eta_s;
        same_eta == *other
    }
}

/// A frame as events show it.
#[derive(Clone, Debug, PartialEq, Serialize)]
struct FrameLine {
    job_id: String,
    frame: u32,
    frame_job_id: String,
    state: &'static str,
    error: Option<String>,
}

/// A worker as events show it.
#[derive(Clone, Debug, PartialEq, Serialize)]
struct WorkerLine {
    worker_id: String,
    name: String,
    state: &'static str,
    leases: usize,
    threads: u32,
    tags: Vec<String>,
}

fn ended(state: &str) -> bool {
    matches!(state, "done" | "failed" | "cancelled")
}

/// What the service showed at one moment.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Snapshot {
    jobs: BTreeMap<String, JobLine>,
    frames: BTreeMap<String, FrameLine>,
    workers: BTreeMap<String, WorkerLine>,
}

/// An event before it is numbered.
type Change = (&'static str, Option<String>, Option<String>, bool, String);

fn encode(value: &impl Serialize) -> String {
    serde_json::to_string(value).expect("invariant: event lines serialise")
}

impl Snapshot {
    /// The snapshot of the service's views.
    pub fn of(jobs: &[JobView], workers: &[WorkerView]) -> Snapshot {
        let mut s = Snapshot::default();
        for v in jobs {
            for f in &v.frames {
                let line = FrameLine {
                    job_id: v.id.clone(),
                    frame: f.number,
                    frame_job_id: f.job_id.clone(),
                    state: f.state.as_str(),
                    error: f.error.clone(),
                };
                s.frames.insert(f.job_id.clone(), line);
            }
            s.jobs.insert(v.id.clone(), JobLine::of(v));
        }
        for w in workers {
            let line = WorkerLine {
                worker_id: w.id.clone(),
                name: w.name.clone(),
                state: w.state,
                leases: w.leases,
                threads: w.threads,
                tags: w.tags.clone(),
            };
            s.workers.insert(w.id.clone(), line);
        }
        s
    }

    /// What changed from `self` to `next`, in a fixed order (jobs, frames, workers).
    pub fn changes(&self, next: &Snapshot) -> Vec<Change> {
        let mut out = Vec::new();
        for (id, line) in &next.jobs {
            let kind = match self.jobs.get(id) {
                Some(old) if old.same_but_eta(line) => continue,
                Some(old) if old.state == line.state => "job.progress",
                _ => "job.state",
            };
            out.push((kind, Some(id.clone()), None, kind == "job.state" && ended(line.state), encode(line)));
        }
        for id in self.jobs.keys().filter(|id| !next.jobs.contains_key(*id)) {
            let data = encode(&serde_json::json!({ "job_id": id }));
            out.push(("job.deleted", Some(id.clone()), None, true, data));
        }
        for (id, line) in &next.frames {
            if self.frames.get(id).is_none_or(|old| old != line) {
                let ends = ended(line.state);
                out.push(("frame.state", Some(line.job_id.clone()), Some(id.clone()), ends, encode(line)));
            }
        }
        for (id, line) in &next.workers {
            if self.workers.get(id) != Some(line) {
                out.push(("worker", None, None, false, encode(line)));
            }
        }
        for id in self.workers.keys().filter(|id| !next.workers.contains_key(*id)) {
            out.push(("worker.gone", None, None, false, encode(&serde_json::json!({ "worker_id": id }))));
        }
        out
    }
}

/// Where events are published and subscribed to.
pub struct Hub {
    tx: broadcast::Sender<Arc<Event>>,
    next_id: AtomicU64,
}

impl Default for Hub {
    fn default() -> Self {
        Hub { tx: broadcast::channel(BACKLOG).0, next_id: AtomicU64::new(1) }
    }
}

impl Hub {
    /// A new subscription: every event published from now on.
    pub fn subscribe(&self) -> broadcast::Receiver<Arc<Event>> {
        self.tx.subscribe()
    }

    /// Numbers and sends `changes`.
    pub fn publish(&self, changes: Vec<Change>) {
        for (kind, job, frame_job, ends_job, data) in changes {
            let id = self.next_id.fetch_add(1, Ordering::Relaxed);
            // no subscriber is not an error: the event is simply not needed
            let _ = self.tx.send(Arc::new(Event { id, kind, job, frame_job, ends_job, data }));
        }
    }

    /// An event for one subscriber only (its opening state), numbered like the others.
    pub fn single(&self, kind: &'static str, line: &JobLine) -> Event {
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let (job, ends_job) = (Some(line.job_id.clone()), ended(line.state));
        Event { id, kind, job, frame_job: None, ends_job, data: encode(line) }
    }

    fn listened(&self) -> bool {
        self.tx.receiver_count() > 0
    }
}

/// The publisher: every [`PERIOD`] while anyone listens, the service's views are compared with
/// the last ones seen and the changes published. (Changes made while nobody listened are
/// published when someone does: they are still changes.)
pub fn spawn_publisher(svc: Arc<JobService>, hub: Arc<Hub>) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut seen: Option<Snapshot> = None;
        let mut tick = tokio::time::interval(PERIOD);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            tick.tick().await;
            if !hub.listened() && seen.is_some() {
                continue;
            }
            let svc = svc.clone();
            let now = match tokio::task::spawn_blocking(move || svc.watch(crate::serve::clock::now_ms())).await {
                Ok(Ok((jobs, workers))) => Snapshot::of(&jobs, &workers),
                Ok(Err(e)) => {
                    tracing::warn!(error = %e, "the event stream could not read the jobs");
                    continue;
                }
                Err(_) => continue,
            };
            if let Some(before) = &seen {
                hub.publish(before.changes(&now));
            }
            seen = Some(now);
        }
    })
}

#[cfg(test)]
#[path = "events_tests.rs"]
mod tests;
