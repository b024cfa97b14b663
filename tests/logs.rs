//! The operators' logs: with `--log-format json` every line of the coordinator's and the
//! worker's stderr is a JSON object, and a job's lifecycle (submitted, passes planned, EMIS
//! decisions, done, cancelled), the workers' arrivals and losses, and each tile's start and end
//! on the worker are events carrying `job_id` or `worker_id`.

use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::Duration;
use tessera_tests::{Coordinator, bin, scene, submit_and_wait, tessera, wait_for};

/// Every line of `path` as JSON (a line that is not is a failure).
fn json_lines(path: &std::path::Path) -> Vec<Value> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l:?} in {}", path.display())))
        .collect()
}

/// The events of `lines` with message `message`.
fn events<'a>(lines: &'a [Value], message: &str) -> Vec<&'a Value> {
    lines.iter().filter(|l| l["message"].as_str().is_some_and(|m| m.starts_with(message))).collect()
}

#[test]
fn json_logs_carry_the_job_lifecycle_and_worker_events_with_ids() {
    let dir = tempfile::tempdir().unwrap();
    let c =
        Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--log-format", "json", "--lease-timeout", "2"]);
    let worker_log = dir.path().join("worker.log");
    let mut worker = Command::new(bin("tessera-worker"))
        .args(["--coordinator", &c.url, "--threads", "1", "--log-format", "json", "--cache-dir"])
        .arg(dir.path().join("cache"))
        .env_remove("RUST_LOG")
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&worker_log).unwrap())
        .spawn()
        .unwrap();

    // an EMIS job: a pilot pass, one update, a final pass
    let out = dir.path().join("farm.exr");
    let box_scene = scene("cornell-box");
    let (ok, stdout, stderr) = submit_and_wait(&c.url, &box_scene, ("emis-vcm", 3, 4), &out, &["--emis-updates", "1"]);
    assert!(ok, "submit failed: {stderr}\nlog: {}", c.log.display());
    let job = stdout.lines().next().unwrap().trim().to_string();
    // a job cancelled before it can finish
    let (ok, stdout, stderr) =
        tessera(&["submit", box_scene.to_str().unwrap(), "--server", &c.url, "--spp", "100000", "--seed", "1"]);
    assert!(ok, "{stderr}");
    let cancelled = stdout.trim().to_string();
    let (ok, _, stderr) = tessera(&["cancel", &cancelled, "--server", &c.url]);
    assert!(ok, "{stderr}");
    // the worker stops: the coordinator notices within the lease timeout
    worker.kill().unwrap();
    worker.wait().unwrap();
    let log = wait_for(Duration::from_secs(30), "the worker's loss in the log", || {
        let lines = json_lines(&c.log);
        (!events(&lines, "worker lost").is_empty()).then_some(lines)
    });

    let with_job = |message: &str, id: &str| -> Vec<&Value> {
        events(&log, message).into_iter().filter(|e| e["job_id"] == id).collect()
    };
    assert_eq!(with_job("job submitted", &job).len(), 1, "log: {}", c.log.display());
    assert_eq!(with_job("job submitted", &job)[0]["integrator"], "emis-vcm");
    let passes = with_job("pass planned", &job);
    let kinds: Vec<_> = passes.iter().map(|p| p["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["pilot", "final"], "{passes:?}");
    let updates = with_job("emis update", &job);
    assert_eq!(updates.len(), 1, "{updates:?}");
    assert_eq!(updates[0]["iteration"], 1);
    assert!(updates[0]["light_paths_per_pixel"].is_number() && updates[0]["connections"].is_number());
    assert!(updates[0]["mean_merge_probability"].is_number(), "{}", updates[0]);
    assert_eq!(with_job("job done", &job).len(), 1);
    assert_eq!(with_job("job cancelled", &cancelled).len(), 1);
    assert!(with_job("job done", &cancelled).is_empty());
    for e in events(&log, "job submitted").iter().chain(&events(&log, "job done")) {
        assert_eq!(e["level"], "INFO", "{e}");
    }
    let registered = events(&log, "worker registered");
    assert_eq!(registered.len(), 1, "{registered:?}");
    let worker_id = registered[0]["worker_id"].as_str().unwrap();
    assert!(events(&log, "worker lost").iter().any(|e| e["worker_id"] == worker_id));

    // the worker: each tile's start and end with the job, the tile and the time it took
    let wlog = json_lines(&worker_log);
    let started = events(&wlog, "tile started");
    let finished = events(&wlog, "tile finished");
    assert!(started.iter().any(|e| e["job_id"] == job.as_str()), "worker log: {}", worker_log.display());
    let of_job: Vec<_> = finished.iter().filter(|e| e["job_id"] == job.as_str()).collect();
    assert!(!of_job.is_empty());
    for e in &of_job {
        assert!(e["tile"].is_u64() && e["duration_ms"].is_u64(), "{e}");
    }
    assert!(events(&wlog, "registered").iter().any(|e| e["worker_id"] == worker_id));
}

/// A job that no worker can render fails, and the coordinator says so once, as an error
/// carrying the job's id and the reason.
#[test]
fn a_failed_job_is_logged_once_with_its_reason() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--log-format", "json"]);
    // a worker whose texture budget no textured scene fits in
    let mut worker = Command::new(bin("tessera-worker"))
        .args(["--coordinator", &c.url, "--threads", "1", "--texture-budget", "0", "--cache-dir"])
        .arg(dir.path().join("cache"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let textured = scene("textured-room");
    let (ok, stdout, stderr) = tessera(&["submit", textured.to_str().unwrap(), "--server", &c.url, "--spp", "4"]);
    assert!(ok, "{stderr}");
    let job = stdout.trim().to_string();
    let failed = wait_for(Duration::from_secs(60), "the job's failure in the log", || {
        let lines = json_lines(&c.log);
        let failed: Vec<Value> =
            events(&lines, "job failed").into_iter().filter(|e| e["job_id"] == job.as_str()).cloned().collect();
        (!failed.is_empty()).then_some(failed)
    });
    worker.kill().unwrap();
    worker.wait().unwrap();
    assert_eq!(failed.len(), 1, "{failed:?}");
    assert_eq!(failed[0]["level"], "ERROR", "{}", failed[0]);
    let error = failed[0]["error"].as_str().unwrap_or_default();
    // why the worker could not render it, not only that it could not
    assert!(error.contains("no eligible worker") && error.contains("texture"), "reason: {}", failed[0]);
}
