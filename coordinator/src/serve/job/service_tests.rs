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

pub(super) const CFG: ServiceConfig = ServiceConfig {
    lease_timeout_ms: 10_000,
    lease_lifetime: super::model::LeaseLifetime { floor_ms: 60_000, factor: 8.0 },
    checkpoint_interval_ms: 3_600_000,
    scene_limits: tessera_common::scene::SceneLimits::DEFAULT,
    work_limits: tessera_common::settings::WorkLimits::DEFAULT,
    max_pixels: super::service::DEFAULT_MAX_PIXELS,
    max_tiles: 1_000,
    retain_finished_ms: None,
    result_file_bytes: crate::serve::storage::blobs::RESULT_FILE_BYTES,
    max_workers: crate::serve::job::service::DEFAULT_MAX_WORKERS,
    forget_workers_ms: 3_600_000,
    min_free_bytes: 0,
};

pub(super) fn cornell() -> (Bundle, Scene) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.xml");
    let xml = std::fs::read(&path).unwrap();
    let bundle = Bundle { scene_path: "scene.xml".into(), files: vec![("scene.xml".into(), xml)] };
    (bundle, Scene::load(&path).unwrap())
}

/// Renders a lease's tile honestly and uploads it.
pub(super) fn upload(
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
    integrator.render_tile(scene, &TileRequest::new(tile.rect, tile.samples.clone(), 3), &mut accum);
    let payload = tessera_link::payload::encode_tile(&accum);
    let claim = ResultClaim { rect: tile.rect, samples: tile.samples, non_finite: accum.non_finite, pilot_bytes: 0 };
    svc.upload(worker, lease, &claim, payload, now)
}

/// Leases and uploads every tile left, 16 at a time.
fn render_the_rest(svc: &JobService, scene: &Scene, worker: &str, now: u64) {
    loop {
        let grants = svc.lease(worker, 16, now).unwrap();
        if grants.is_empty() {
            break;
        }
        for g in grants {
            upload(svc, scene, worker, &g.lease, now + 1).unwrap();
        }
    }
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
        let worker = svc.register("w", 1, &[], None, None, 1_000).unwrap();
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
    assert!(matches!(svc.upload(&worker, &next, &bad, vec![0; 3], 50_004), Err(ServiceError::InvalidResult(_))));
    // the remaining tiles finish the job; the EXR has exactly one sample per pixel
    render_the_rest(&svc, &scene, &worker, 50_005);
    let view = svc.get(&job, 50_007).unwrap();
    assert_eq!((view.state, view.samples_done), (JobState::Done, 256 * 256));
    let exr = dir.path().join("out.exr");
    std::fs::write(&exr, svc.output(&job, super::service::OutputKind::Exr).unwrap()).unwrap();
    assert!(tessera_common::film::exr::read_sample_counts(&exr).unwrap().iter().all(|&c| c == 1));
}

/// Large results are files instead of rows (every result here, with a threshold of 0): they
/// survive a restart like rows, are merged once, and go when the finished job no longer needs
/// them; the job's image is the same as with rows.
#[test]
fn results_stored_as_files_survive_a_restart_and_go_when_done() {
    let (bundle, scene) = cornell();
    let settings = RenderSettings { spp: Some(1), seed: Some(3), ..Default::default() };
    let mut images = Vec::new();
    for file_bytes in [0, usize::MAX] {
        // checkpoints as often as their spacing allows: files go with each
        let cfg = ServiceConfig { result_file_bytes: file_bytes, checkpoint_interval_ms: 0, ..CFG };
        let dir = tempfile::tempdir().unwrap();
        let files = |job: &str| match std::fs::read_dir(dir.path().join("blobs/results").join(job)) {
            Ok(entries) => entries.count(),
            Err(_) => 0,
        };
        let (job, worker, leases) = {
            let svc = JobService::open(dir.path(), cfg.clone(), 1_000).unwrap();
            let job = svc.submit(bundle.clone(), settings.clone(), 0, None, 1_000).unwrap().id;
            let worker = svc.register("w", 1, &[], None, None, 1_000).unwrap();
            let leases: Vec<_> = svc.lease(&worker, 3, 1_000).unwrap().into_iter().map(|g| g.lease).collect();
            for l in &leases[1..] {
                assert_eq!(upload(&svc, &scene, &worker, l, 1_100).unwrap(), ResultOutcome::Accepted);
            }
            assert_eq!(files(&job), if file_bytes == 0 { 2 } else { 0 });
            (job, worker, leases)
        };
        let svc = JobService::open(dir.path(), cfg, 50_000).unwrap();
        assert_eq!(svc.get(&job, 50_000).unwrap().tiles_done, 2, "held results come back from their files");
        assert_eq!(upload(&svc, &scene, &worker, &leases[1], 50_001).unwrap(), ResultOutcome::Duplicate);
        assert_eq!(files(&job), if file_bytes == 0 { 2 } else { 0 }, "a duplicate leaves the file it repeats");
        assert_eq!(upload(&svc, &scene, &worker, &leases[0], 50_002).unwrap(), ResultOutcome::Accepted);
        assert_eq!(files(&job), 0, "the checkpoint of tiles 0 to 2 holds what their files held");
        render_the_rest(&svc, &scene, &worker, 50_005);
        let view = svc.get(&job, 50_007).unwrap();
        assert_eq!((view.state, view.samples_done), (JobState::Done, 256 * 256));
        assert_eq!(files(&job), 0, "a finished job keeps no result files");
        let exr = dir.path().join("out.exr");
        std::fs::write(&exr, svc.output(&job, super::service::OutputKind::Exr).unwrap()).unwrap();
        images.push(tessera_common::film::exr::read_rgb(&exr).unwrap().pixels);
    }
    // the files hold job ids, which differ: the pixels must not
    assert!(images[0] == images[1], "files and rows give the same image");
}

/// A bundle whose scene names a file outside it, and a film over the pixel budget, are refused
/// at submission with the reason, and the service goes on taking jobs.
#[test]
fn hostile_submissions_are_refused_and_the_service_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
    let settings = RenderSettings { spp: Some(1), ..Default::default() };
    let (cornell, _) = cornell();
    let xml = String::from_utf8(cornell.files[0].1.clone()).unwrap();
    let submit = |xml: String| {
        let bundle = Bundle { scene_path: "scene.xml".into(), files: vec![("scene.xml".into(), xml.into_bytes())] };
        svc.submit(bundle, settings.clone(), 0, None, 1_000)
    };
    let escape = xml.replacen(
        "</scene>",
        "<shape type=\"obj\"><string name=\"filename\" value=\"/dev/zero\"/></shape></scene>",
        1,
    );
    match submit(escape) {
        Err(ServiceError::InvalidArgument(m)) => {
            assert!(m.contains("absolute path") && m.contains("scene.xml:"), "{m}")
        }
        other => panic!("/dev/zero accepted: {other:?}"),
    }
    let (w, h) = (
        integer_element(&xml, "width").expect("cornell names its width"),
        integer_element(&xml, "height").expect("cornell names its height"),
    );
    let huge = xml.replacen(&w, "<integer name=\"width\" value=\"65535\"/>", 1).replacen(
        &h,
        "<integer name=\"height\" value=\"65535\"/>",
        1,
    );
    match submit(huge) {
        Err(ServiceError::InvalidArgument(m)) => {
            assert!(m.contains("65535×65535") && m.contains("--max-pixels"), "{m}")
        }
        other => panic!("a 65535² film accepted: {other:?}"),
    }
    // four billion vcm iterations would plan four billion tiles up front
    let bundle = Bundle { scene_path: "scene.xml".into(), files: vec![("scene.xml".into(), xml.clone().into_bytes())] };
    let endless = RenderSettings {
        integrator: tessera_common::settings::IntegratorName::Vcm,
        spp: Some(4_000_000_000),
        ..Default::default()
    };
    match svc.submit(bundle, endless, 0, None, 1_000) {
        Err(ServiceError::InvalidArgument(m)) => {
            assert!(m.contains("4000000000 tiles") && m.contains("--max-job-tiles"), "{m}")
        }
        other => panic!("4·10⁹ iterations accepted: {other:?}"),
    }
    assert!(submit(xml).is_ok(), "the service still takes jobs");
}

/// The `<integer name="NAME" value="..."/>` element of `xml`.
pub(super) fn integer_element(xml: &str, name: &str) -> Option<String> {
    let start = xml.find(&format!("<integer name=\"{name}\""))?;
    let end = start + xml[start..].find("/>")? + 2;
    Some(xml[start..end].to_string())
}

/// When every live worker is blocklisted for a job, the job fails with that reason instead of
/// waiting forever; a worker that has gone quiet does not keep it alive.
#[test]
fn a_job_no_live_worker_may_serve_fails_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
    let (bundle, _) = cornell();
    let settings = RenderSettings { spp: Some(1), ..Default::default() };
    let job = svc.submit(bundle, settings, 0, None, 1_000).unwrap().id;
    let quiet = svc.register("quiet", 1, &[], None, None, 1_000).unwrap();
    let workers: Vec<String> =
        (0..2).map(|i| svc.register(&format!("w{i}"), 1, &[], None, None, 20_000).unwrap()).collect();
    let now = 20_100;
    let blocklist = crate::serve::job::model::BLOCKLIST_AFTER_FAILURES as usize;
    for (k, w) in workers.iter().enumerate() {
        // each fails as many different tiles as blocklist it (no tile reaches its own limit)
        for grant in svc.lease(w, blocklist, now).unwrap() {
            svc.report_failure(w, &grant.lease, "out of memory", now).unwrap();
        }
        assert!(svc.lease(w, 1, now).unwrap().is_empty(), "blocklisted");
        svc.expire(now).unwrap();
        if k == 0 {
            assert_ne!(svc.get(&job, now).unwrap().state, JobState::Failed, "w1 can still serve it");
        }
    }
    // `quiet` was last seen at 1 000, more than a lease timeout ago: only w0 and w1 are live
    let view = svc.get(&job, now).unwrap();
    assert_eq!(view.state, JobState::Failed, "{view:?}");
    let error = view.error.as_deref().unwrap_or_default();
    assert!(error.contains("no eligible worker") && error.ends_with("the last failure: out of memory"), "{view:?}");
    let _ = quiet;
}

/// The expiry timer running a minute late means the coordinator stalled: the lease it would
/// have expired is postponed by the stall, and ends at its deadline after it as usual.
#[test]
fn a_coordinator_stall_is_not_held_against_its_workers() {
    let dir = tempfile::tempdir().unwrap();
    let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
    let (bundle, _) = cornell();
    svc.submit(bundle, RenderSettings { spp: Some(1), ..Default::default() }, 0, None, 1_000).unwrap();
    let w = svc.register("w", 1, &[], None, None, 1_000).unwrap();
    let lease = svc.lease(&w, 1, 1_000).unwrap().remove(0).lease;
    svc.expire(1_000).unwrap();
    svc.expire(61_000).unwrap();
    let m = svc.metrics();
    assert_eq!((m.counters.stalls, m.counters.leases_expired), (1, 0));
    assert_eq!(svc.heartbeat(&w, std::slice::from_ref(&lease), 61_000).unwrap(), vec![], "still held");
    let mut now = 61_000;
    while svc.metrics().counters.leases_expired == 0 {
        now += svc.expiry_period_ms();
        assert!(now <= 61_000 + CFG.lease_timeout_ms + svc.expiry_period_ms(), "never expired");
        svc.expire(now).unwrap();
    }
    assert!(now >= 61_000 + CFG.lease_timeout_ms, "expired before its deadline");
    assert_eq!(svc.heartbeat(&w, std::slice::from_ref(&lease), now).unwrap(), vec![lease]);
}

/// A queued EMIS job holds no moment buffers (hundreds of bytes a pixel): they are made at its
/// first lease, and again after a restart only when it runs on.
#[test]
fn emis_state_is_made_when_the_job_first_runs() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, _) = cornell();
    let settings = RenderSettings {
        integrator: tessera_common::settings::IntegratorName::EmisVcm,
        spp: Some(2),
        ..Default::default()
    };
    let job = {
        let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
        let job = svc.submit(bundle, settings, 0, None, 1_000).unwrap().id;
        assert!(!svc.holds_emis_state(&job), "a queued job's moments allocated");
        job
    };
    let svc = JobService::open(dir.path(), CFG, 2_000).unwrap();
    assert!(!svc.holds_emis_state(&job), "allocated again at a restart");
    let w = svc.register("w", 1, &[], None, None, 2_000).unwrap();
    assert_eq!(svc.lease(&w, 1, 2_000).unwrap().len(), 1);
    assert!(svc.holds_emis_state(&job));
}
