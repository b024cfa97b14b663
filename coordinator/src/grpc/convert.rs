//! Conversions between prost messages and domain types. Prost types never leave `grpc/`;
//! a message that does not convert is an `INVALID_ARGUMENT` naming the field.

use crate::job::model::{JobState, LeaseRef};
use crate::job::service::{JobView, LeaseGrant};
use tessera_common::film::Rect;
use tessera_common::settings::RenderSettings;
use tessera_proto::v1 as pb;
use tonic::Status;

/// Wire settings → domain settings.
pub fn settings_from_pb(s: Option<pb::RenderSettings>) -> Result<RenderSettings, Status> {
    let s = s.unwrap_or_default();
    let d = RenderSettings::default();
    let integrator = if s.integrator.is_empty() {
        d.integrator
    } else {
        s.integrator
            .parse()
            .map_err(|e: tessera_common::settings::SettingsError| Status::invalid_argument(e.to_string()))?
    };
    Ok(RenderSettings {
        integrator,
        spp: s.spp,
        time_s: s.time_s,
        seed: s.seed,
        max_depth: s.max_depth,
        light_paths_per_pixel: s.light_paths_per_pixel.unwrap_or(d.light_paths_per_pixel),
        connections: s.connections.unwrap_or(d.connections),
        merge: s.merge.unwrap_or(d.merge),
        correlation_aware: s.correlation_aware.unwrap_or(d.correlation_aware),
        defines: s.defines.into_iter().collect(),
    })
}

/// Domain settings → wire settings.
pub fn settings_to_pb(s: &RenderSettings) -> pb::RenderSettings {
    pb::RenderSettings {
        integrator: s.integrator.to_string(),
        spp: s.spp,
        time_s: s.time_s,
        seed: s.seed,
        max_depth: s.max_depth,
        light_paths_per_pixel: Some(s.light_paths_per_pixel),
        connections: Some(s.connections),
        merge: Some(s.merge),
        correlation_aware: Some(s.correlation_aware),
        defines: s.defines.clone().into_iter().collect(),
    }
}

/// Wire rect → domain rect.
pub fn rect_from_pb(r: Option<pb::Rect>) -> Result<Rect, Status> {
    let r = r.ok_or_else(|| Status::invalid_argument("field \"rect\" is missing"))?;
    if r.x0 >= r.x1 || r.y0 >= r.y1 {
        return Err(Status::invalid_argument(format!("field \"rect\" is empty: {r:?}")));
    }
    Ok(Rect { x0: r.x0, y0: r.y0, x1: r.x1, y1: r.y1 })
}

/// Domain rect → wire rect.
pub fn rect_to_pb(r: Rect) -> pb::Rect {
    pb::Rect { x0: r.x0, y0: r.y0, x1: r.x1, y1: r.y1 }
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
    }
}

fn state_to_pb(s: JobState) -> pb::JobState {
    match s {
        JobState::Queued => pb::JobState::Queued,
        JobState::Pilot => pb::JobState::Pilot,
        JobState::Optimizing => pb::JobState::Optimizing,
        JobState::Final => pb::JobState::Final,
        JobState::Done => pb::JobState::Done,
        JobState::Failed => pb::JobState::Failed,
        JobState::Cancelled => pb::JobState::Cancelled,
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
    }
}
