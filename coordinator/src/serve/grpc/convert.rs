//! Conversions between prost messages and domain types. Prost types never leave `grpc/`;
//! a message that does not convert is an `INVALID_ARGUMENT` naming the field.

use crate::serve::job::emis::{MergeSpec, TileStrategy};
use crate::serve::job::model::{JobState, LeaseRef};
use crate::serve::job::service::{JobView, LeaseGrant, WorkerView};
use tessera_common::emis::CandidateSet;
use tessera_common::film::Rect;
use tessera_common::settings::RenderSettings;
use tessera_proto::v1 as pb;
use tonic::Status;

/// Wire settings → domain settings (`tessera_link::convert` holds the rules).
pub fn settings_from_pb(s: Option<pb::RenderSettings>) -> Result<RenderSettings, Status> {
    tessera_link::convert::settings_from_pb(&s.unwrap_or_default()).map_err(Status::invalid_argument)
}

pub use tessera_link::convert::{rect_to_pb, settings_to_pb};

/// Wire rect → domain rect.
pub fn rect_from_pb(r: Option<pb::Rect>) -> Result<Rect, Status> {
    tessera_link::convert::rect_from_pb(r.as_ref()).map_err(Status::invalid_argument)
}

/// Wire lease → domain lease.
pub fn lease_from_pb(l: Option<pb::LeaseRef>) -> Result<LeaseRef, Status> {
    let l = l.ok_or_else(|| Status::invalid_argument("field \"lease\" is missing"))?;
    Ok(LeaseRef { job: l.job_id, tile: l.tile as usize, epoch: l.epoch })
}

/// Domain lease → wire lease.
pub fn lease_to_pb(l: &LeaseRef) -> pb::LeaseRef {
    pb::LeaseRef { job_id: l.job.clone(), tile: l.tile as u32, epoch: l.epoch }
}

/// A grant → the wire lease a worker renders.
pub fn grant_to_pb(g: &LeaseGrant) -> pb::TileLease {
    pb::TileLease {
        lease: Some(lease_to_pb(&g.lease)),
        bundle_digest: g.job.bundle_digest.clone(),
        settings: Some(settings_to_pb(&g.job.settings)),
        rect: Some(rect_to_pb(g.tile.rect)),
        sample_begin: g.tile.samples.start,
        sample_end: g.tile.samples.end,
        strategy: g.strategy.as_ref().map(strategy_to_pb),
        scene_path: g.job.scene_path.clone(),
    }
}

fn strategy_to_pb(s: &TileStrategy) -> pb::TileStrategy {
    pb::TileStrategy {
        light_paths_per_pixel: s.nu,
        connections: s.connections,
        merge: match &s.merge {
            MergeSpec::None => None,
            MergeSpec::Constant(c) => Some(pb::tile_strategy::Merge::MergeConstant(*c)),
            MergeSpec::Mask(digest) => Some(pb::tile_strategy::Merge::MergeMaskDigest(digest.clone())),
        },
        collect_moments: s.collect,
        reduced_candidates: s.candidates == CandidateSet::Reduced,
        connection_mask_digest: s.connection_mask.clone().unwrap_or_default(),
    }
}

/// A worker's view as sent to clients.
pub fn worker_to_pb(w: &WorkerView) -> pb::Worker {
    pb::Worker {
        id: w.id.clone(),
        name: w.name.clone(),
        threads: w.threads,
        state: w.state.into(),
        tags: w.tags.clone(),
        last_seen_s_ago: w.last_seen_s_ago,
        leases: w.leases as u64,
    }
}

fn state_to_pb(s: JobState) -> pb::JobState {
    match s {
        JobState::Queued => pb::JobState::Queued,
        JobState::Pilot => pb::JobState::Pilot,
        JobState::Optimizing => pb::JobState::Optimizing,
        JobState::Final | JobState::Finishing => pb::JobState::Final,
        JobState::Done => pb::JobState::Done,
        JobState::Failed => pb::JobState::Failed,
        JobState::Cancelled => pb::JobState::Cancelled,
        JobState::Paused => pb::JobState::Paused,
        JobState::Blocked => pb::JobState::Blocked,
    }
}

/// A job view → the wire job.
pub fn job_to_pb(j: &JobView) -> pb::Job {
    pb::Job {
        id: j.id.clone(),
        name: j.name.clone(),
        state: state_to_pb(j.state) as i32,
        phase: j.phase.clone(),
        progress: j.progress,
        tiles_done: j.tiles_done,
        tiles_total: j.tiles_total,
        samples_done: j.samples_done,
        eta_s: j.eta_s,
        error: j.error.clone(),
        priority: j.priority,
        settings: Some(settings_to_pb(&j.settings)),
        width: j.width,
        height: j.height,
        created_unix_ms: j.created_ms,
        scene_digest: j.scene_digest.clone(),
        strategy: j.strategy.as_ref().map(|s| pb::EmisStrategy {
            light_paths_per_pixel: s.nu,
            connections: s.connections,
            mean_merge_probability: s.mean_merge_probability,
            updates: s.updates.len() as u32,
            mean_connections: s.mean_connections,
        }),
        frames_total: j.frames_total,
        frames: j
            .frames
            .iter()
            .map(|f| pb::Frame {
                number: f.number,
                job_id: f.job_id.clone(),
                state: state_to_pb(f.state) as i32,
                progress: f.progress,
                eta_s: f.eta_s,
                error: f.error.clone(),
            })
            .collect(),
    }
}
