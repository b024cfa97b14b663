//! Tests of the job service over a real data directory: results that arrive out of order are
//! held, survive a restart (no checkpoint yet) and are merged exactly once afterwards.

use super::model::{JobState, LeaseRef, ResultOutcome};
use super::service::{Bundle, JobService, ServiceConfig, ServiceError};
use super::validate::ResultClaim;
use std::path::Path;
use tessera_common::film::TileAccum;
use tessera_common::integrator::TileRequest;
use tessera_common::scene::Scene;
use tessera_common::settings::{RenderSettings, Renderer};

const CFG: ServiceConfig = ServiceConfig {
    lease_timeout_ms: 10_000,
    checkpoint_interval_ms: 3_600_000,
    texture_limits: tessera_common::texture::TextureLimits { max_decoded_bytes: 1 << 30, max_total_bytes: 4 << 30 },
};

fn cornell() -> (Bundle, Scene) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.xml");
    let xml = std::fs::read(&path).unwrap();
    let bundle = Bundle { scene_path: "scene.xml".into(), files: vec![("scene.xml".into(), xml)] };
    (bundle, Scene::load(&path).unwrap())
}

/// Renders a lease's tile honestly and uploads it.
fn upload(
    svc: &JobService,
    scene: &Scene,
    worker: &str,
    lease: &LeaseRef,
    now: u64,
) -> Result<ResultOutcome, ServiceError> {
    let tile = svc.lease_spec(lease).unwrap();
    let settings = RenderSettings { spp: Some(1), seed: Some(3), ..Default::default() };
    let Ok(Renderer::Tiles(integrator)) = settings.make_renderer(scene) else { panic!("a tile integrator") };
    let mut accum = TileAccum::new(tile.rect, &scene.film);
    integrator.render_tile(scene, &TileRequest { rect: tile.rect, samples: tile.samples.clone(), seed: 3 }, &mut accum);
    let payload = tessera_proto::payload::encode_tile(&accum);
    let claim = ResultClaim { rect: tile.rect, samples: tile.samples, non_finite: accum.non_finite, pilot_bytes: 0 };
    svc.upload(worker, lease, &claim, &payload, now)
}

#[test]
fn service_holds_early_results_across_a_restart_and_merges_each_once() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, scene) = cornell();
    let settings = RenderSettings { spp: Some(1), seed: Some(3), ..Default::default() };
    let (job, worker, leases) = {
        let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
        let job = svc.submit(bundle.clone(), settings.clone(), 0, None, 1_000).unwrap();
        assert_eq!(job.tiles_total, 16);
        let worker = svc.register("w", 1, 1_000).unwrap();
        let leases: Vec<_> = svc.lease(&worker, 3, 1_000).unwrap().into_iter().map(|g| g.lease).collect();
        // tiles 1 and 2 arrive before tile 0: accepted, held, not merged
        for l in &leases[1..] {
            assert_eq!(upload(&svc, &scene, &worker, l, 1_100).unwrap(), ResultOutcome::Accepted);
        }
        let view = svc.get(&job.id, 1_100).unwrap();
        assert_eq!((view.tiles_done, view.samples_done), (2, 0));
        (job.id, worker, leases)
    };
    // restart: the held results come back from the database, tile 0 is still leased
    let svc = JobService::open(dir.path(), CFG, 50_000).unwrap();
    assert_eq!(svc.get(&job, 50_000).unwrap().tiles_done, 2);
    assert_eq!(svc.heartbeat(&worker, &leases[..1], 50_000).unwrap(), vec![], "the lease survives the restart");
    assert_eq!(upload(&svc, &scene, &worker, &leases[1], 50_001).unwrap(), ResultOutcome::Duplicate);
    assert_eq!(upload(&svc, &scene, &worker, &leases[0], 50_002).unwrap(), ResultOutcome::Accepted);
    assert_eq!(svc.get(&job, 50_002).unwrap().samples_done, 3 * 64 * 64);
    // a bad result is refused and its tile re-queued with the next epoch
    let next = svc.lease(&worker, 1, 50_003).unwrap().remove(0).lease;
    let bad = ResultClaim { rect: svc.lease_spec(&next).unwrap().rect, samples: 0..1, non_finite: 0, pilot_bytes: 0 };
    assert!(matches!(svc.upload(&worker, &next, &bad, &[0; 3], 50_004), Err(ServiceError::InvalidResult(_))));
    // the remaining tiles finish the job; the EXR has exactly one sample per pixel
    loop {
        let grants = svc.lease(&worker, 16, 50_005).unwrap();
        if grants.is_empty() {
            break;
        }
        for g in grants {
            upload(&svc, &scene, &worker, &g.lease, 50_006).unwrap();
        }
    }
    let view = svc.get(&job, 50_007).unwrap();
    assert_eq!((view.state, view.samples_done), (JobState::Done, 256 * 256));
    let exr = dir.path().join("out.exr");
    std::fs::write(&exr, svc.output(&job, super::service::OutputKind::Exr).unwrap()).unwrap();
    assert!(tessera_common::film::exr::read_sample_counts(&exr).unwrap().iter().all(|&c| c == 1));
}
