//! Tests of deleting jobs through the service over a real data directory: a finished job and a
//! job cancelled in the middle of EMIS leave no trace in memory, in SQLite or in the blob
//! folder, except a bundle another job still uses; `--retain-finished` does the same on its
//! own; a restart deletes the files a crash could leave behind.

use super::emis::MergeSpec;
use super::model::{JobState, ResultOutcome};
use super::service::{Bundle, JobService, LeaseGrant, ServiceConfig, ServiceError};
use super::service_tests::{CFG, cornell, integer_element, upload};
use super::validate::ResultClaim;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tessera_common::emis::{Strategy, render_iterations};
use tessera_common::integrator::path::connections::Connections;
use tessera_common::integrator::path::merge::MergeMask;
use tessera_common::scene::Scene;
use tessera_common::settings::{IntegratorName, RenderSettings, Renderer};

/// The Cornell box at 48×36 pixels, as a bundle and loaded.
fn small_cornell(dir: &Path) -> (Bundle, Scene) {
    let (bundle, _) = cornell();
    let xml = String::from_utf8(bundle.files[0].1.clone()).unwrap();
    let (w, h) = (integer_element(&xml, "width").unwrap(), integer_element(&xml, "height").unwrap());
    let xml = xml.replacen(&w, "<integer name=\"width\" value=\"48\"/>", 1).replacen(
        &h,
        "<integer name=\"height\" value=\"36\"/>",
        1,
    );
    let path = dir.join("small-cornell.xml");
    std::fs::write(&path, &xml).unwrap();
    let bundle = Bundle { scene_path: "scene.xml".into(), files: vec![("scene.xml".into(), xml.into_bytes())] };
    (bundle, Scene::load(&path).unwrap())
}

/// Renders an EMIS lease as a worker does (its strategy, the merge mask fetched by digest, the
/// pilot data when it collects) and uploads it.
fn upload_emis(svc: &JobService, scene: &Scene, worker: &str, g: &LeaseGrant, now: u64) -> ResultOutcome {
    let Ok(Renderer::Emis(config, settings)) = g.job.settings.make_renderer(scene) else { panic!("an EMIS job") };
    let s = g.strategy.as_ref().expect("EMIS leases carry a strategy");
    let merge = match &s.merge {
        MergeSpec::None => None,
        MergeSpec::Constant(c) => Some(MergeMask::Constant(*c)),
        MergeSpec::Mask(d) => {
            let bytes = svc.blob(d).unwrap();
            Some(MergeMask::PerPixel(Arc::new(
                bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect(),
            )))
        }
    };
    let floats = |d: &str| -> Arc<Vec<f32>> {
        Arc::new(svc.blob(d).unwrap().chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect())
    };
    let connections = match &s.connection_mask {
        None => Connections::Fixed(s.connections),
        Some(d) => Connections::PerPixel(floats(d)),
    };
    let strategy = Strategy { nu: s.nu, connections, merge };
    let seed = g.job.settings.seed.unwrap_or(0);
    let collect = s.collect.then_some(s.candidates);
    let (accum, pilot) = render_iterations(scene, settings, &config, &strategy, seed, g.tile.samples.clone(), collect);
    let pilot = pilot.map(|p| p.encode()).unwrap_or_default();
    let mut payload = tessera_link::payload::encode_tile(&accum);
    payload.extend_from_slice(&pilot);
    let claim = ResultClaim {
        rect: g.tile.rect,
        samples: g.tile.samples.clone(),
        non_finite: accum.non_finite,
        pilot_bytes: pilot.len() as u64,
    };
    svc.upload(worker, &g.lease, &claim, payload, now).unwrap()
}

/// Rows that name `job` in each table.
fn rows(data: &Path, job: &str) -> [i64; 3] {
    let conn = rusqlite::Connection::open(data.join("tessera.sqlite")).unwrap();
    let count = |sql: &str| conn.query_row(sql, [job], |r| r.get::<_, i64>(0)).unwrap();
    [
        count("SELECT count(*) FROM jobs WHERE id = ?1"),
        count("SELECT count(*) FROM tiles WHERE job_id = ?1"),
        count("SELECT count(*) FROM results WHERE job_id = ?1"),
    ]
}

fn cas(data: &Path, digest: &str) -> PathBuf {
    data.join("blobs").join("cas").join(&digest[..2]).join(digest)
}

/// The checkpoint files of `job`.
fn checkpoints(data: &Path, job: &str) -> Vec<PathBuf> {
    let dir = std::fs::read_dir(data.join("blobs").join("checkpoints")).unwrap();
    dir.map(|e| e.unwrap().path()).filter(|p| p.file_name().unwrap().to_string_lossy().starts_with(job)).collect()
}

/// Settings for `integrator`; emis-* with the bidirectional pilot, which merges from its
/// first update on.
fn settings(integrator: IntegratorName, spp: u32) -> RenderSettings {
    let emis_pilot = tessera_common::emis::PilotStart::Bidirectional;
    RenderSettings { integrator, spp: Some(spp), seed: Some(3), emis_pilot, ..Default::default() }
}

#[test]
fn cancel_and_delete_mid_emis_frees_memory_rows_and_files() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let svc = JobService::open(&data, CFG, 1_000).unwrap();
    let worker = svc.register("w", 1, &[], None, None, 1_000).unwrap();
    // a finished pt job with a bundle of its own
    let (big, big_scene) = cornell();
    let done = svc.submit(big, settings(IntegratorName::Pt, 1), 5, None, 1_000).unwrap();
    loop {
        let grants = svc.lease(&worker, 16, 1_100).unwrap();
        if grants.is_empty() {
            break;
        }
        for g in grants {
            assert_eq!(upload(&svc, &big_scene, &worker, &g.lease, 1_200).unwrap(), ResultOutcome::Accepted);
        }
    }
    assert_eq!(svc.get(&done.id, 1_300).unwrap().state, JobState::Done);
    let outputs: Vec<String> = [super::service::OutputKind::Exr, super::service::OutputKind::Png]
        .map(|k| tessera_proto::blob_digest(&svc.output(&done.id, k).unwrap()))
        .into();
    // an emis-vcm job and a queued pt job sharing one bundle
    let (small, scene) = small_cornell(dir.path());
    let emis = svc.submit(small.clone(), settings(IntegratorName::EmisVcm, 8), 1, None, 2_000).unwrap();
    let other = svc.submit(small, settings(IntegratorName::Pt, 1), 0, None, 2_000).unwrap();
    assert_eq!(emis.scene_digest, other.scene_digest);
    // the pilot, its update (a checkpoint) and one tile of the next pass, accepted but not yet
    // covered by a checkpoint (a row in `results`), rendered with the update's merge mask
    let pilot = svc.lease(&worker, 1, 2_100).unwrap().remove(0);
    assert_eq!((pilot.lease.job.as_str(), pilot.tile.samples.clone()), (emis.id.as_str(), 0..1));
    assert_eq!(upload_emis(&svc, &scene, &worker, &pilot, 2_200), ResultOutcome::Accepted);
    let next = svc.lease(&worker, 1, 2_300).unwrap().remove(0);
    assert_eq!((next.lease.job.as_str(), next.tile.samples.clone()), (emis.id.as_str(), 1..2));
    let Some(MergeSpec::Mask(mask)) = next.strategy.as_ref().map(|s| s.merge.clone()) else {
        panic!("the update chose no per-pixel merge mask: {:?}", next.strategy)
    };
    assert_eq!(upload_emis(&svc, &scene, &worker, &next, 2_400), ResultOutcome::Accepted);
    let view = svc.get(&emis.id, 2_500).unwrap();
    assert_eq!((view.state, view.strategy.map(|s| s.updates.len())), (JobState::Final, Some(1)), "mid-EMIS");
    let emis_checkpoints = checkpoints(&data, &emis.id);
    assert_eq!(emis_checkpoints.len(), 1);
    assert_eq!(rows(&data, &emis.id)[2], 1, "the tile after the checkpoint is a row in results");
    assert!(cas(&data, &mask).exists());

    // an active job is refused, an unknown one is not found
    assert!(matches!(svc.delete(&emis.id), Err(ServiceError::FailedPrecondition(m)) if m.contains("cancel it")));
    assert!(matches!(svc.delete("no-such-job"), Err(ServiceError::NotFound(_))));
    assert_eq!(svc.cancel(&emis.id, 2_600).unwrap().state, JobState::Cancelled);
    // after a restart the cancelled job shows its decisions, read from its checkpoint's head
    drop(svc);
    let svc = JobService::open(&data, CFG, 2_650).unwrap();
    let view = svc.get(&emis.id, 2_650).unwrap();
    assert_eq!((view.state, view.strategy.map(|s| s.updates.len())), (JobState::Cancelled, Some(1)));
    for job in [&done.id, &emis.id] {
        assert_ne!(rows(&data, job), [0, 0, 0]);
        svc.delete(job).unwrap();
        assert!(matches!(svc.get(job, 2_700), Err(ServiceError::NotFound(_))), "GET answers not found");
        assert!(matches!(svc.delete(job), Err(ServiceError::NotFound(_))));
        assert_eq!(svc.holds(job), (false, false), "the model and the service's memory let it go");
        assert_eq!(rows(&data, job), [0, 0, 0], "no rows left");
        assert!(svc.list(2_700).unwrap().iter().all(|j| j.id != *job));
    }
    assert!(matches!(svc.output(&done.id, super::service::OutputKind::Exr), Err(ServiceError::NotFound(_))));
    // its files are gone: outputs, bundle and unpacked scene, checkpoint, merge mask
    for digest in outputs.iter().chain([&done.scene_digest, &mask]) {
        assert!(!cas(&data, digest).exists(), "blob {digest} is still there");
    }
    assert!(!data.join("scenes").join(&done.scene_digest).exists());
    assert!(emis_checkpoints.iter().all(|p| !p.exists()));
    // the bundle the queued job shares stays, and the job still runs
    assert!(cas(&data, &other.scene_digest).exists() && data.join("scenes").join(&other.scene_digest).exists());
    assert_eq!(rows(&data, &other.id)[..2], [1, 1]);
    let grant = svc.lease(&worker, 1, 2_800).unwrap().remove(0);
    assert_eq!(grant.lease.job, other.id);
    assert!(svc.blob(&other.scene_digest).is_ok());
    // and after a restart only it comes back
    drop(svc);
    let svc = JobService::open(&data, CFG, 3_000).unwrap();
    let ids: Vec<String> = svc.list(3_000).unwrap().into_iter().map(|j| j.id).collect();
    assert_eq!(ids, vec![other.id.clone()]);
}

#[test]
fn finished_jobs_expire_after_retain_finished() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = ServiceConfig { retain_finished_ms: Some(60_000), ..CFG };
    let svc = JobService::open(dir.path(), cfg, 1_000).unwrap();
    let (bundle, _) = cornell();
    let pt = settings(IntegratorName::Pt, 1);
    let ended = svc.submit(bundle.clone(), pt.clone(), 0, None, 1_000).unwrap();
    svc.cancel(&ended.id, 10_000).unwrap();
    let running = svc.submit(bundle, pt, 0, None, 1_000).unwrap();
    assert_eq!(svc.expire_finished(69_999).unwrap(), 0, "not yet a minute after it ended");
    assert!(svc.get(&ended.id, 69_999).is_ok());
    assert_eq!(svc.expire_finished(70_000).unwrap(), 1);
    assert!(matches!(svc.get(&ended.id, 70_000), Err(ServiceError::NotFound(_))));
    assert_eq!((svc.holds(&ended.id), rows(dir.path(), &ended.id)), ((false, false), [0, 0, 0]));
    // an active job never expires, and its bundle (shared with the expired one) stays
    assert_eq!(svc.expire_finished(10_000_000).unwrap(), 0);
    assert_eq!(svc.get(&running.id, 10_000_000).unwrap().state, JobState::Queued);
    assert!(cas(dir.path(), &running.scene_digest).exists());
    // without --retain-finished nothing expires
    drop(svc);
    let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
    svc.cancel(&running.id, 20_000).unwrap();
    assert_eq!(svc.expire_finished(u64::MAX).unwrap(), 0);
}

/// A crash between a delete's commit and the removal of its files, or between writing a file
/// and committing its name, leaves files nobody names: the next start deletes them.
#[test]
fn a_restart_deletes_files_no_job_names() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, _) = cornell();
    let job = {
        let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
        svc.submit(bundle, settings(IntegratorName::Pt, 1), 0, None, 1_000).unwrap()
    };
    let orphan = tessera_proto::blob_digest(b"orphan");
    std::fs::create_dir_all(cas(dir.path(), &orphan).parent().unwrap()).unwrap();
    std::fs::write(cas(dir.path(), &orphan), b"orphan").unwrap();
    let strays = [
        dir.path().join("blobs").join("checkpoints").join("gone.3.film"),
        dir.path().join("blobs").join("tmp").join("half.exr"),
        dir.path().join("scenes").join(&orphan),
    ];
    for p in &strays {
        std::fs::write(p, b"x").unwrap();
    }
    let svc = JobService::open(dir.path(), CFG, 2_000).unwrap();
    assert!(!cas(dir.path(), &orphan).exists());
    for p in &strays {
        assert!(!p.exists(), "{} survived", p.display());
    }
    assert!(cas(dir.path(), &job.scene_digest).exists(), "the live job's bundle stays");
    assert!(svc.blob(&job.scene_digest).is_ok());
}

/// A finished EMIS job stores its strategy PNG and report beside the EXR and PNG; other
/// integrators' jobs have none (not found, whatever their state). After a restart the start-up
/// sweep keeps the four outputs and the job shows the same decisions, read back from the
/// report; deleting it removes all four.
#[test]
fn a_finished_emis_job_keeps_its_strategy_outputs_across_a_restart_until_deleted() {
    use super::service::OutputKind;
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let svc = JobService::open(&data, CFG, 1_000).unwrap();
    let worker = svc.register("w", 1, &[], None, None, 1_000).unwrap();
    let (small, scene) = small_cornell(dir.path());
    let pt = svc.submit(small.clone(), settings(IntegratorName::Pt, 1), 0, None, 1_000).unwrap();
    let not_emis = |svc: &JobService, job: &str| {
        for kind in [OutputKind::StrategyPng, OutputKind::EmisJson] {
            let e = svc.output(job, kind).unwrap_err();
            assert!(
                matches!(&e, ServiceError::NotFound(m) if m.contains(kind.file_name()) && m.contains("emis-vcm")),
                "{e}"
            );
        }
    };
    not_emis(&svc, &pt.id);
    // updates after iterations 1 and 4 (the defaults), then 2 more
    let emis = svc.submit(small, settings(IntegratorName::EmisVcm, 6), 1, None, 1_000).unwrap();
    assert!(matches!(svc.output(&emis.id, OutputKind::EmisJson), Err(ServiceError::FailedPrecondition(_))));
    let mut now = 2_000;
    loop {
        let grants = svc.lease(&worker, 4, now).unwrap();
        if grants.is_empty() {
            break;
        }
        for g in grants {
            now += 10;
            let outcome = match g.strategy {
                Some(_) => upload_emis(&svc, &scene, &worker, &g, now),
                None => upload(&svc, &scene, &worker, &g.lease, now).unwrap(),
            };
            assert_eq!(outcome, ResultOutcome::Accepted);
        }
    }
    let before = svc.get(&emis.id, now).unwrap();
    assert_eq!((before.state, svc.get(&pt.id, now).unwrap().state), (JobState::Done, JobState::Done));
    let strategy = serde_json::to_value(before.strategy.as_ref().expect("EMIS decisions")).unwrap();
    assert_eq!(strategy["updates"].as_array().map(Vec::len), Some(2), "{strategy}");
    not_emis(&svc, &pt.id);
    let kinds = [OutputKind::Exr, OutputKind::Png, OutputKind::StrategyPng, OutputKind::EmisJson];
    let outputs = kinds.map(|k| svc.output(&emis.id, k).unwrap());
    assert_eq!(&outputs[2][1..4], b"PNG");
    let report: serde_json::Value = serde_json::from_slice(&outputs[3]).unwrap();
    assert_eq!((report["integrator"].as_str(), report["iterations"].as_u64()), (Some("emis-vcm"), Some(6)));
    assert_eq!(report["updates"], strategy["updates"], "the report holds the decisions the job shows");
    let digests = outputs.each_ref().map(|b| tessera_proto::blob_digest(b));

    drop(svc);
    let svc = JobService::open(&data, CFG, now + 1_000).unwrap();
    let after = svc.get(&emis.id, now + 1_000).unwrap();
    assert_eq!(serde_json::to_value(after.strategy.as_ref()).unwrap(), strategy, "the decisions came back");
    assert_eq!(kinds.map(|k| svc.output(&emis.id, k).unwrap()), outputs, "the sweep kept every output");
    assert!(svc.get(&pt.id, now + 1_000).unwrap().strategy.is_none());
    not_emis(&svc, &pt.id);
    svc.delete(&emis.id).unwrap();
    for digest in &digests {
        assert!(!cas(&data, digest).exists(), "output {digest} is still there");
    }
}
