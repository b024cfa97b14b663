//! The operator's log of what happens to jobs and workers: passes planned, EMIS decisions,
//! workers lost and back, leases expired. Each line is one `tracing`
//! event with `job_id` or `worker_id` as a field (a JSON log has them at the top level); the
//! service calls these after the transition, since the pure model logs nothing.
//!
//! Submission, completion, cancellation, failures found by the service and registrations are
//! logged where they happen (`submit`, `merge`, `query`, `leases`).

use crate::serve::job::model::{JobsModel, PassKind};
use crate::serve::storage::WorkerRow;
use std::collections::HashMap;
use tessera_common::emis::UpdateReport;

/// The last planned pass of `job`: its index, kind, tiles and sample range.
pub(super) fn pass_planned(model: &JobsModel, job: &str) {
    let Some(j) = model.jobs.get(job) else { return };
    let Some(pass) = j.passes().last() else { return };
    let tiles = &j.tiles[pass.tiles.clone()];
    let first = tiles.iter().map(|t| t.spec.samples.start).min().unwrap_or(0);
    let end = tiles.iter().map(|t| t.spec.samples.end).max().unwrap_or(0);
    tracing::info!(
        job_id = %job,
        pass = j.passes().len() - 1,
        kind = match pass.kind {
            PassKind::Pilot => "pilot",
            PassKind::Final => "final",
        },
        tiles = tiles.len(),
        samples = %format_args!("{first}..{end}"),
        collects_moments = pass.collect,
        restart = pass.restart,
        "pass planned"
    );
}

/// The decision of an EMIS update: the strategy the next pass renders with.
pub(super) fn emis_update(job: &str, report: &UpdateReport) {
    tracing::info!(
        job_id = %job,
        iteration = report.iteration,
        light_paths_per_pixel = report.nu,
        connections = report.connections,
        mean_merge_probability = report.mean_merge_probability,
        merging_pixels = report.merging_pixels,
        reduced_candidates = report.reduced,
        restarted = report.restarted,
        settled = report.settled,
        update_ms = (report.denoise_ms + report.optimize_ms).round() as u64,
        "emis update"
    );
}

/// Workers whose silence reached `timeout_ms` between the expiry runs at `previous_ms` and
/// `now_ms`, with the leases each held (`held`, by worker id, taken before the expiry).
pub(super) fn workers_lost<'a>(
    workers: impl Iterator<Item = &'a WorkerRow>,
    held: &HashMap<String, usize>,
    previous_ms: u64,
    now_ms: u64,
    timeout_ms: u64,
) {
    for w in workers {
        let silent_from = w.last_seen_ms.saturating_add(timeout_ms);
        if silent_from >= previous_ms && silent_from < now_ms {
            tracing::warn!(
                worker_id = %w.id,
                name = %w.name,
                silent_ms = now_ms.saturating_sub(w.last_seen_ms),
                leases = held.get(&w.id).copied().unwrap_or(0),
                "worker lost: no heartbeat within the lease timeout"
            );
        }
    }
}

/// Leases the expiry took from each worker: `before` and `after` are the lease counts by
/// worker around it (nothing else leases meanwhile: the caller holds the lock).
pub(super) fn leases_expired(before: &HashMap<String, usize>, after: &HashMap<&str, usize>) {
    for (worker, &held) in before {
        let expired = held.saturating_sub(after.get(worker.as_str()).copied().unwrap_or(0));
        if expired > 0 {
            tracing::warn!(worker_id = %worker, tiles = expired, "leases expired: tiles re-queued");
        }
    }
}
