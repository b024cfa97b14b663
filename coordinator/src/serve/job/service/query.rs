//! The calls clients make besides submission and deletion: job views, cancellation, finished
//! outputs, blobs, the workers' list and the figures behind `/metrics`.

use super::{Counters, Inner, JobService, ServiceError};
use crate::serve::job::model::{Event, JobState, Waiting};
use crate::serve::job::view::{JobView, WorkerView};
use std::collections::BTreeMap;

/// Which finished output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputKind {
    /// The EXR.
    Exr,
    /// The PNG preview.
    Png,
    /// EMIS: the strategy PNG (the image in grey, tinted by the merge probability).
    StrategyPng,
    /// EMIS: the JSON report of every update.
    EmisJson,
}

impl OutputKind {
    /// Its media type.
    pub fn mime(self) -> &'static str {
        match self {
            OutputKind::Exr => "image/x-exr",
            OutputKind::Png | OutputKind::StrategyPng => "image/png",
            OutputKind::EmisJson => "application/json",
        }
    }

    /// Its name in the REST API, `result.exr` etc.
    pub fn file_name(self) -> &'static str {
        match self {
            OutputKind::Exr => "result.exr",
            OutputKind::Png => "preview.png",
            OutputKind::StrategyPng => "strategy.png",
            OutputKind::EmisJson => "emis.json",
        }
    }

    /// Whether only EMIS jobs have it.
    pub fn emis_only(self) -> bool {
        matches!(self, OutputKind::StrategyPng | OutputKind::EmisJson)
    }
}

/// Which jobs a list shows: all unless it names states or a part of the name.
#[derive(Clone, Debug, Default)]
pub struct JobFilter {
    /// State names as clients see them (`final` includes finishing); any of them.
    pub states: Vec<String>,
    /// A part of the name, case-insensitive.
    pub name: Option<String>,
}

impl JobFilter {
    fn passes_name(&self, name: &str) -> bool {
        self.name.as_ref().is_none_or(|part| name.to_lowercase().contains(&part.to_lowercase()))
    }
}

/// What `/metrics` reports of the service.
#[derive(Clone, Debug, Default)]
pub struct Metrics {
    /// Results and leases so far.
    pub counters: Counters,
    /// Jobs per state name.
    pub jobs_by_state: BTreeMap<&'static str, usize>,
    /// Tiles waiting for a worker (the backlog) in unfinished jobs.
    pub tiles_queued: usize,
    /// Tiles leased to workers.
    pub tiles_leased: usize,
}

impl JobService {
    /// A job's view with its EMIS decisions (kept after the job ends).
    pub(super) fn view(&self, inner: &Inner, job: &str, now_ms: u64) -> JobView {
        let mut view = self.view_without_strategy(inner, job, now_ms);
        if !inner.model.sequences.contains_key(job) {
            view.strategy = inner.jobs.get(job).and_then(|r| r.strategy());
        }
        view
    }

    /// [`JobService::view`] without the EMIS decisions, which copy every update's report: for
    /// the event stream's comparisons and a job of frames' lines, which show none of it.
    pub(super) fn view_without_strategy(&self, inner: &Inner, job: &str, now_ms: u64) -> JobView {
        if inner.model.sequences.contains_key(job) {
            return self.sequence_view(inner, job, now_ms);
        }
        let j = inner.model.jobs.get(job).expect("invariant: callers check the job exists");
        let mut view = JobView::of(j, now_ms);
        if let Some(waiting) = inner.model.waiting(j) {
            if matches!(waiting, Waiting::Blocked { .. }) && j.paused_ms.is_none() {
                view.state = JobState::Blocked;
            }
            view.phase = waiting.phase();
        } else if !j.spec.require_tags.is_empty() && !j.state.is_terminal() && !self.anyone_serves(inner, j, now_ms) {
            view.phase = format!("waiting for a worker with tags {}", j.spec.require_tags.join(", "));
        }
        view
    }

    /// Cancels a job.
    pub fn cancel(&self, job: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        self.disk.make_room();
        let mut inner = self.lock();
        let job = &Self::resolve(&inner, job)?;
        let effects = inner.model.apply(Event::Cancel { job }, now_ms).map_err(super::retention::refused)?;
        self.persist(&mut inner, &effects.changes, &[])?;
        self.sync(&inner)?;
        self.ended(&mut inner, &effects);
        tracing::info!(job_id = %job, "job cancelled");
        Ok(self.view(&inner, job, now_ms))
    }

    /// One job.
    ///
    /// Answered only once everything the view shows is committed (uploads are answered after
    /// their commit but become visible before it), so a client never sees progress that a
    /// crash could take back.
    pub fn get(&self, job: &str, now_ms: u64) -> Result<JobView, ServiceError> {
        let inner = self.lock();
        let job = &Self::resolve(&inner, job)?;
        let view = self.view(&inner, job, now_ms);
        let ticket = inner.ticket;
        drop(inner);
        self.commits.wait(ticket)?;
        Ok(view)
    }

    /// Every job, newest first (committed state, as [`JobService::get`]).
    pub fn list(&self, now_ms: u64) -> Result<Vec<JobView>, ServiceError> {
        Ok(self.list_page(now_ms, 0, usize::MAX, &JobFilter::default())?.0)
    }

    /// Up to `limit` of the jobs `filter` lets through, from the `offset`-th, newest first, and
    /// how many it lets through: without a state filter only the page's views are built.
    pub fn list_page(
        &self,
        now_ms: u64,
        offset: usize,
        limit: usize,
        filter: &JobFilter,
    ) -> Result<(Vec<JobView>, usize), ServiceError> {
        let inner = self.lock();
        // a job of frames is one entry: its frames are in its view
        let stills = inner.model.jobs.values().filter(|j| j.spec.frame.is_none()).map(|j| (j.seq, &j.id, &j.spec.name));
        let sequences = inner.model.sequences.values().map(|s| (s.seq, &s.id, &s.spec.name));
        let mut jobs: Vec<_> = stills.chain(sequences).filter(|(_, _, name)| filter.passes_name(name)).collect();
        jobs.sort_unstable_by_key(|&(seq, _, _)| std::cmp::Reverse(seq));
        // a list shows a job of frames by its summary: its frames' lines are in its own view
        let summary = |id: &str| JobView { frames: Vec::new(), ..self.view(&inner, id, now_ms) };
        let (views, total) = if filter.states.is_empty() {
            let total = jobs.len();
            (jobs.into_iter().skip(offset).take(limit).map(|(_, id, _)| summary(id)).collect(), total)
        } else {
            // states are read off views without the EMIS decisions; only the page gets them
            let state = |id: &str| self.view_without_strategy(&inner, id, now_ms).state;
            let all: Vec<&String> = jobs
                .into_iter()
                .map(|(_, id, _)| id)
                .filter(|id| filter.states.iter().any(|s| s == state(id).as_str()))
                .collect();
            let total = all.len();
            (all.into_iter().skip(offset).take(limit).map(|id| summary(id)).collect(), total)
        };
        let ticket = inner.ticket;
        drop(inner);
        self.commits.wait(ticket)?;
        Ok((views, total))
    }

    /// Every job's whole view (a job of frames with its frames' lines) and every worker: what
    /// the event stream compares from one moment to the next (committed state, as
    /// [`JobService::get`]).
    pub fn watch(&self, now_ms: u64) -> Result<(Vec<JobView>, Vec<WorkerView>), ServiceError> {
        let inner = self.lock();
        let stills = inner.model.jobs.values().filter(|j| j.spec.frame.is_none()).map(|j| &j.id);
        let ids: Vec<&String> = stills.chain(inner.model.sequences.keys()).collect();
        let views = ids.into_iter().map(|id| self.view_without_strategy(&inner, id, now_ms)).collect();
        let workers = inner.workers.values().map(|w| self.worker_view(&inner, w, now_ms)).collect();
        let ticket = inner.ticket;
        drop(inner);
        self.commits.wait(ticket)?;
        Ok((views, workers))
    }

    /// A finished job's output: not found for an EMIS output of another integrator's job
    /// (whatever its state: it will never have one), a failed precondition while the job is not
    /// done.
    pub fn output(&self, job: &str, kind: OutputKind) -> Result<Vec<u8>, ServiceError> {
        let digest = {
            let inner = self.lock();
            let job = &Self::resolve(&inner, job)?;
            if inner.model.sequences.contains_key(job) {
                return Err(ServiceError::FailedPrecondition(format!(
                    "job {job} is a job of frames: each frame's outputs are its frame job's (`frames[].job_id`)"
                )));
            }
            let j = inner.model.jobs.get(job).ok_or_else(|| ServiceError::NotFound(format!("job {job} not found")))?;
            let integrator = j.spec.settings.integrator;
            if kind.emis_only() && integrator.emis_method().is_none() {
                return Err(ServiceError::NotFound(format!(
                    "job {job} has no {}: only emis-bdpt and emis-vcm jobs do, and it is {integrator}",
                    kind.file_name()
                )));
            }
            if j.state != JobState::Done {
                return Err(ServiceError::FailedPrecondition(format!("job {job} is {}, not done", j.state.as_str())));
            }
            let files = inner.jobs.get(job).map(|r| r.files.clone()).unwrap_or_default();
            match kind {
                OutputKind::Exr => files.result_exr,
                OutputKind::Png => files.preview_png,
                OutputKind::StrategyPng => files.strategy_png,
                OutputKind::EmisJson => files.emis_json,
            }
        };
        // an EMIS job finished by a version that did not store its EMIS outputs has none
        let digest =
            digest.ok_or_else(|| ServiceError::NotFound(format!("job {job} has no stored {}", kind.file_name())))?;
        self.blob(&digest)
    }

    /// A content-addressed blob.
    pub fn blob_file(&self, digest: &str) -> Result<std::fs::File, ServiceError> {
        self.blobs.open_blob(digest)?.ok_or_else(|| ServiceError::NotFound(format!("blob {digest} not found")))
    }

    /// A blob's bytes, read whole and checked against the digest.
    pub fn blob(&self, digest: &str) -> Result<Vec<u8>, ServiceError> {
        self.blobs.get(digest)?.ok_or_else(|| ServiceError::NotFound(format!("blob {digest} not found")))
    }

    /// Counters and gauges for `/metrics`.
    pub fn metrics(&self) -> Metrics {
        let inner = self.lock();
        let mut metrics = Metrics { counters: inner.counters.clone(), ..Metrics::default() };
        for j in inner.model.jobs.values() {
            *metrics.jobs_by_state.entry(j.state.as_str()).or_default() += 1;
            if !j.state.is_terminal() {
                metrics.tiles_queued += j.index.queued.len();
                metrics.tiles_leased += j.index.leased.len();
            }
        }
        metrics
    }
}
