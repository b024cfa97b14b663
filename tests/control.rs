//! Job control on a real farm: pause and resume, a priority change, and requeueing a
//! cancelled job, each driven by the `tessera` commands and checked against a local render
//! bit for bit.

use super::{TIMEOUT, job_url, wait_done};
use serde_json::json;
use std::path::Path;
use tessera_tests::{Coordinator, Worker, assert_same_image, local_render, rest, scene, tessera, wait_for};

fn submit(c: &Coordinator, spp: u32, seed: u64) -> String {
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let settings = json!({"integrator": "pt", "spp": spp, "seed": seed});
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    job["id"].as_str().unwrap().to_string()
}

fn control(c: &Coordinator, args: &[&str]) -> String {
    let mut all = args.to_vec();
    all.extend(["--server", &c.url]);
    let (ok, out, err) = tessera(&all);
    assert!(ok, "tessera {args:?}: {err}");
    out
}

fn job(c: &Coordinator, id: &str) -> serde_json::Value {
    rest::get_json(&job_url(c, id), None).1
}

fn assert_like_local(c: &Coordinator, dir: &Path, id: &str, spp: u32, seed: u64) {
    let out = dir.join(format!("{id}.exr"));
    let (status, bytes) = rest::get(&format!("{}/result.exr", job_url(c, id)), None);
    assert_eq!(status, 200);
    std::fs::write(&out, bytes).unwrap();
    assert_same_image(&out, &local_render(dir, &scene("cornell-box"), "pt", spp, seed));
}

/// A paused job hands out nothing while the worker renders another job to the end; resumed, it
/// finishes with the image of a local render.
#[test]
fn a_paused_job_holds_while_others_run_and_finishes_when_resumed() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let a = submit(&c, 64, 3);
    wait_for(TIMEOUT, "a tile of the job", || (job(&c, &a)["tiles_done"].as_u64() >= Some(1)).then_some(()));
    assert!(control(&c, &["pause", &a]).contains("paused"));
    // the tiles it held finish; then nothing more of it is handed out, while the worker
    // leases and renders a whole other job
    let held = wait_for(TIMEOUT, "the worker to let go of the paused job", || {
        let workers = rest::get_json(&format!("{}/api/v1/workers", c.url), None).1;
        (workers[0]["leases"] == 0).then(|| job(&c, &a))
    });
    let b = submit(&c, 4, 1);
    wait_done(&c, &b, None);
    let still = job(&c, &a);
    assert_eq!((still["state"].as_str(), &still["tiles_done"]), (Some("paused"), &held["tiles_done"]), "{still}");
    assert!(still["tiles_done"].as_u64() < still["tiles_total"].as_u64(), "{still}");
    assert!(control(&c, &["resume", &a]).contains(": final"));
    wait_done(&c, &a, None);
    assert_like_local(&c, dir.path(), &a, 64, 3);
}

/// Raising a later job's priority puts it first: it is done before the job submitted ahead of
/// it, which a worker started after both would otherwise render first.
#[test]
fn a_priority_change_reorders_the_queue() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let (first, second) = (submit(&c, 8, 1), submit(&c, 8, 2));
    assert!(control(&c, &["priority", &second, "10"]).contains("priority 10"));
    let (status, patched) =
        rest::send(None, Default::default(), |client| client.patch(job_url(&c, &first)).json(&json!({"priority": -1})));
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&patched));
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let done = wait_for(TIMEOUT, "a job to finish", || {
        [&first, &second].into_iter().find(|id| job(&c, id)["state"] == "done").cloned()
    });
    assert_eq!(done, second, "the job given priority 10 was not first");
    assert_eq!(job(&c, &first)["priority"], -1);
    wait_done(&c, &first, None);
}

/// A cancelled job, requeued, runs on from what it had and ends with the local render's image.
#[test]
fn a_requeued_cancelled_job_finishes_with_the_local_image() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--lease-timeout", "2"]);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let a = submit(&c, 64, 5);
    wait_for(TIMEOUT, "a tile of the job", || (job(&c, &a)["tiles_done"].as_u64() >= Some(2)).then_some(()));
    control(&c, &["cancel", &a]);
    let cancelled = job(&c, &a);
    assert!(cancelled["tiles_done"].as_u64() < cancelled["tiles_total"].as_u64(), "{cancelled}");
    let (status, requeued) = rest::post(&format!("{}/requeue", job_url(&c, &a)), None);
    assert_eq!(status, 200, "{requeued}");
    assert_ne!(requeued["state"], "cancelled");
    wait_done(&c, &a, None);
    assert_like_local(&c, dir.path(), &a, 64, 5);
    // a done job is not requeued
    let (status, body) = rest::post(&format!("{}/requeue", job_url(&c, &a)), None);
    assert_eq!(status, 409, "{body}");
}

/// A chain a → b → c submitted with `--after` (by id prefix): while a is cancelled, b and c
/// are blocked naming why; a requeued runs, then b, then c, all as local renders.
#[test]
fn a_dependency_chain_waits_blocks_and_runs_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let cornell = scene("cornell-box");
    let cli_submit = |seed: &str, after: &str| {
        let mut args = vec!["submit", cornell.to_str().unwrap(), "--server", &c.url, "--integrator", "pt"];
        args.extend(["--spp", "2", "--seed", seed, "--priority", "5"]);
        if !after.is_empty() {
            args.extend(["--after", after]);
        }
        let (ok, out, err) = tessera(&args);
        assert!(ok, "{err}");
        out.trim().to_string()
    };
    let a = submit(&c, 8, 1);
    let b = cli_submit("2", &a[..8]);
    let c_id = cli_submit("3", &b);
    assert_eq!(job(&c, &b)["phase"], format!("waiting for job {a}"));
    control(&c, &["cancel", &a]);
    let (b_now, c_now) = (job(&c, &b), job(&c, &c_id));
    assert_eq!((b_now["state"].as_str(), c_now["state"].as_str()), (Some("blocked"), Some("blocked")));
    assert_eq!(b_now["phase"], format!("blocked: job {a} was cancelled"));
    assert_eq!(c_now["phase"], format!("blocked: job {b} is blocked"));
    let (ok, _, err) = tessera(&["submit", cornell.to_str().unwrap(), "--server", &c.url, "--after", "nosuchjob"]);
    assert!(!ok && err.contains("after"), "{err}");
    control(&c, &["requeue", &a]);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let last = wait_done(&c, &c_id, None);
    let (a_done, b_done) = (job(&c, &a), job(&c, &b));
    assert_eq!((a_done["state"].as_str(), b_done["state"].as_str()), (Some("done"), Some("done")), "{last}");
    for (id, seed) in [(&b, 2), (&c_id, 3)] {
        assert_like_local(&c, dir.path(), id, 2, seed);
    }
}
