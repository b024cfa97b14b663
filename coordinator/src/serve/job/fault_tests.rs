//! Storage faults injected into the job service: a failed commit acknowledges nothing (not
//! even as a duplicate) and a restart merges every tile exactly once; a stored result or a job
//! row that cannot be read back fails its job, and the other jobs go on.

use super::model::{JobState, ResultOutcome};
use super::service::{JobService, ServiceError};
use super::service_tests::{CFG, cornell, upload};
use tessera_common::settings::RenderSettings;

fn settings() -> RenderSettings {
    RenderSettings { spp: Some(1), seed: Some(3), ..Default::default() }
}

/// Leases and uploads until nothing is left to lease.
fn finish(svc: &JobService, scene: &tessera_common::scene::Scene, worker: &str, now: u64) {
    loop {
        let grants = svc.lease(worker, 16, now).unwrap();
        if grants.is_empty() {
            return;
        }
        for g in grants {
            upload(svc, scene, worker, &g.lease, now).unwrap();
        }
    }
}

fn sample_counts(svc: &JobService, job: &str, dir: &std::path::Path) -> Vec<u32> {
    let exr = dir.join(format!("{job}.exr"));
    std::fs::write(&exr, svc.output(job, super::service::OutputKind::Exr).unwrap()).unwrap();
    tessera_common::film::exr::read_sample_counts(&exr).unwrap()
}

#[test]
fn a_failed_commit_acknowledges_nothing_and_a_restart_merges_each_tile_once() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, scene) = cornell();
    let (job, worker, leases) = {
        let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
        let job = svc.submit(bundle, settings(), 0, None, 1_000).unwrap().id;
        let worker = svc.register("w", 1, &[], None, None, 1_000).unwrap();
        let leases: Vec<_> = svc.lease(&worker, 3, 1_000).unwrap().into_iter().map(|g| g.lease).collect();
        assert_eq!(upload(&svc, &scene, &worker, &leases[0], 1_100).unwrap(), ResultOutcome::Accepted);
        svc.fail_commits_after(0);
        // the commit of tile 1's acceptance fails: an error, and so is every later answer,
        // a repeat of tile 1 above all (its acceptance is in memory only)
        let failed = |r: Result<ResultOutcome, ServiceError>| matches!(r, Err(e) if e.is_storage());
        assert!(failed(upload(&svc, &scene, &worker, &leases[1], 1_200)));
        assert!(failed(upload(&svc, &scene, &worker, &leases[1], 1_300)), "an unsaved result acknowledged");
        assert!(failed(upload(&svc, &scene, &worker, &leases[2], 1_400)));
        assert!(svc.lease(&worker, 1, 1_500).is_err(), "nothing goes on after a failed commit");
        (job, worker, leases)
    };
    // the next start finds what the database holds: tile 0 merged, tiles 1 and 2 still leased
    let svc = JobService::open(dir.path(), CFG, 50_000).unwrap();
    assert_eq!(svc.get(&job, 50_000).unwrap().tiles_done, 1);
    for l in &leases[1..] {
        assert_eq!(upload(&svc, &scene, &worker, l, 50_001).unwrap(), ResultOutcome::Accepted);
    }
    finish(&svc, &scene, &worker, 50_002);
    assert_eq!(svc.get(&job, 50_003).unwrap().state, JobState::Done);
    let counts = sample_counts(&svc, &job, dir.path());
    assert!(counts.iter().all(|&c| c == 1), "a tile merged twice or never");
}

#[test]
fn unreadable_results_and_rows_fail_their_job_and_the_others_go_on() {
    let dir = tempfile::tempdir().unwrap();
    let (bundle, scene) = cornell();
    let (broken, unreadable, fine, worker, first) = {
        let svc = JobService::open(dir.path(), CFG, 1_000).unwrap();
        let broken = svc.submit(bundle.clone(), settings(), 2, None, 1_000).unwrap().id;
        let unreadable = svc.submit(bundle.clone(), settings(), 1, None, 1_000).unwrap().id;
        let fine = svc.submit(bundle, settings(), 0, None, 1_000).unwrap().id;
        let worker = svc.register("w", 1, &[], None, None, 1_000).unwrap();
        // `broken` (highest priority) gets tiles 1 and 2 accepted and stored, tile 0 not yet
        let leases: Vec<_> = svc.lease(&worker, 3, 1_000).unwrap().into_iter().map(|g| g.lease).collect();
        assert!(leases.iter().all(|l| l.job == broken));
        for l in &leases[1..] {
            assert_eq!(upload(&svc, &scene, &worker, l, 1_100).unwrap(), ResultOutcome::Accepted);
        }
        (broken, unreadable, fine, worker, leases[0].clone())
    };
    let db = rusqlite::Connection::open(dir.path().join("tessera.sqlite")).unwrap();
    assert_eq!(db.execute("UPDATE results SET payload = x'0102' WHERE job_id = ?1", [&broken]).unwrap(), 2);
    db.execute("UPDATE jobs SET passes = 'not json' WHERE id = ?1", [&unreadable]).unwrap();
    drop(db);
    let svc = JobService::open(dir.path(), CFG, 50_000).expect("one job's bad rows do not stop the service");
    let view = svc.get(&unreadable, 50_000).unwrap();
    assert_eq!(view.state, JobState::Failed);
    assert!(view.error.as_deref().is_some_and(|e| e.contains("passes")), "{view:?}");
    // tile 0 makes tiles 0..3 mergeable, and tile 1 cannot be read back: nothing is merged
    // and the job fails, naming the result
    assert_eq!(upload(&svc, &scene, &worker, &first, 50_001).unwrap(), ResultOutcome::Accepted);
    let view = svc.get(&broken, 50_001).unwrap();
    assert_eq!((view.state, view.samples_done), (JobState::Failed, 0));
    assert!(view.error.as_deref().is_some_and(|e| e.contains("stored result")), "{view:?}");
    finish(&svc, &scene, &worker, 50_002);
    assert_eq!(svc.get(&fine, 50_003).unwrap().state, JobState::Done);
    assert!(sample_counts(&svc, &fine, dir.path()).iter().all(|&c| c == 1));
}
