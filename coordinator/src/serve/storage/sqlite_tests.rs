//! Tests of the SQLite storage: the model round-trips, `merged` pairs with its checkpoint, and
//! a finished job's outputs come back with their digests.

use super::*;
use crate::serve::job::model::JobSpec;
use crate::serve::job::model::calls::Calls;
use tessera_common::settings::{IntegratorName, RenderSettings};

#[test]
fn store_round_trips_the_model_and_pairs_merged_with_its_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let mut store = Store::open(&dir.path().join("db.sqlite")).unwrap();
    let mut m = JobsModel::default();
    let spec = JobSpec {
        name: "n".into(),
        priority: 2,
        settings: RenderSettings { integrator: IntegratorName::Pt, spp: Some(2), ..Default::default() },
        width: 100,
        height: 70,
        full_frame: false,
        bundle_digest: "d".into(),
        scene_path: "scene.xml".into(),
        filter: tessera_common::film::filter::FilterKind::Gaussian { stddev: 0.5 },
        after: Vec::new(),
        require_tags: Vec::new(),
        frame: None,
        warm: None,
    };
    let c = m.submit("a", spec, 5).unwrap();
    store.persist(&m, &c, &[]).unwrap();
    let (leases, c) = m.lease("w", 3, 10, 1000);
    store.persist(&m, &c, &[]).unwrap();
    let (_, c) = m.result("w", &leases[0], Ok(()), 11);
    store.persist(&m, &c, &[]).unwrap();
    let (_, c) = m.result("w", &leases[1], Ok(()), 11);
    store.persist(&m, &c, &[]).unwrap();
    let (_, c) = m.merged("a", 2, 12);
    // merged but not yet checkpointed: reloads as accepted
    store.persist(&m, &c, &[]).unwrap();
    // a pause and a new priority are stored with the job
    for c in [m.pause("a", 12).unwrap(), m.set_priority("a", -3).unwrap()] {
        store.persist(&m, &c, &[]).unwrap();
    }
    let loaded: Vec<_> = store.load_jobs(10 + 1000).unwrap().into_iter().map(Result::unwrap).collect();
    let mut expected = m.jobs["a"].clone();
    // what is not stored: the measured tile rate, a lease's start (counted from its
    // restored deadline)
    expected.slowest_ms_per_sample = None;
    if let TileState::Leased { since_ms, deadline_ms, .. } = &mut expected.tiles[2].state {
        *since_ms = *deadline_ms;
    }
    let restored = expected.clone();
    expected.merged = 0;
    expected.tiles[0].state = TileState::Accepted;
    expected.tiles[1].state = TileState::Accepted;
    assert_eq!(loaded[0].0, expected);
    store.persist(&m, &Changes::new(), &[Extra::Checkpoint { job: "a".into(), merged: 2, file: "f".into() }]).unwrap();
    let loaded: Vec<_> = store.load_jobs(10 + 1000).unwrap().into_iter().map(Result::unwrap).collect();
    assert_eq!(loaded[0].0, restored);
    assert_eq!(loaded[0].1.checkpoint.as_deref(), Some("f"));
    // outputs replace the checkpoint, EMIS ones included
    let outputs =
        OutputDigests { exr: "e".into(), png: "p".into(), strategy_png: Some("s".into()), emis_json: Some("j".into()) };
    store.persist(&m, &Changes::new(), &[Extra::Outputs { job: "a".into(), outputs, merged: 2 }]).unwrap();
    let files = store.job_files("a").unwrap().unwrap();
    assert_eq!(files.outputs().map(String::as_str).collect::<Vec<_>>(), ["e", "p", "s", "j"]);
    assert_eq!(files.checkpoint, None);
    let loaded: Vec<_> = store.load_jobs(10 + 1000).unwrap().into_iter().map(Result::unwrap).collect();
    assert_eq!(loaded[0].1, files);
}

/// A database made before EMIS outputs were stored gains their columns on opening.
#[test]
fn an_older_database_gains_the_emis_output_columns() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("db.sqlite");
    let old = Connection::open(&path).unwrap();
    old.execute_batch(
        "CREATE TABLE jobs (
            id TEXT PRIMARY KEY, seq INTEGER NOT NULL, spec TEXT NOT NULL, state TEXT NOT NULL,
            passes TEXT NOT NULL, worker_failures TEXT NOT NULL, error TEXT,
            created_ms INTEGER NOT NULL, started_ms INTEGER, finished_ms INTEGER,
            merged INTEGER NOT NULL DEFAULT 0, checkpoint TEXT, result_exr TEXT, preview_png TEXT);
         INSERT INTO jobs (id, seq, spec, state, passes, worker_failures, created_ms, result_exr, preview_png)
            VALUES ('a', 1, '{}', 'done', '[]', '{}', 0, 'e', 'p');",
    )
    .unwrap();
    drop(old);
    let store = Store::open(&path).unwrap();
    // every column a job is loaded with exists (the row's own spec does not decode)
    assert!(store.load_jobs(0).unwrap()[0].is_err());
    let files = store.job_files("a").unwrap().unwrap();
    assert_eq!((files.result_exr.as_deref(), files.strategy_png, files.emis_json), (Some("e"), None, None));
}
