//! Workers on a real farm: one of another build is refused at registration (naming both
//! builds), one with a wrong token exits with a clear error instead of retrying forever as if
//! the coordinator were down; tags route jobs to the workers that have them; operators
//! disable, enable and drain workers from the server.

use super::*;
use serde_json::json;
use std::process::{Command, Stdio};
use tessera_proto::v1 as pb;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;

/// A registration from another build is FAILED_PRECONDITION with both builds named; this
/// build's is accepted.
#[test]
fn a_worker_of_another_build_is_refused_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut client = WorkerServiceClient::connect(c.url.clone()).await.unwrap();
        let ours = tessera_link::build::registration();
        for (version, revision) in [("0.0.1", ours.renderer_revision.as_str()), (&ours.version, "0123456789ab")] {
            let reg = pb::RegisterRequest {
                name: "old".into(),
                threads: 1,
                version: version.into(),
                renderer_revision: revision.into(),
                ..Default::default()
            };
            let e = client.register(reg).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{e:?}");
            let (theirs, mine) = (format!("{version} (renderer {revision})"), tessera_common::build_id());
            assert!(e.message().contains(&theirs) && e.message().contains(&mine), "{}", e.message());
        }
        let reg = pb::RegisterRequest { name: "same".into(), threads: 1, ..ours };
        client.register(reg).await.unwrap();
    });
    let (_, workers) = rest::get_json(&format!("{}/api/v1/workers", c.url), None);
    assert_eq!(workers.as_array().map(Vec::len), Some(1), "{workers}");
    let (ok, out, _) = tessera(&["version"]);
    assert!(ok && out.contains(&tessera_common::build_id()), "{out}");
}

/// A worker started with a wrong token exits with an error that says so.
#[test]
fn a_worker_with_a_wrong_token_exits_saying_so() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--worker-token", "right-token-0123"]);
    let mut child = Command::new(tessera_tests::bin("tessera-worker"))
        .args(["--coordinator", &c.url, "--token", "wrong-token-0123", "--cache-dir"])
        .arg(dir.path().join("cache"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_for(TIMEOUT, "the worker to exit", || child.try_wait().unwrap());
    assert!(!status.success());
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(err.contains("refused this worker's token"), "{err}");
}

/// Starts `tessera-worker` with its log in `log` (to see which jobs it rendered).
fn worker_logged(c: &Coordinator, dir: &std::path::Path, name: &str, extra: &[&str]) -> std::process::Child {
    let log = std::fs::File::create(dir.join(format!("{name}.log"))).unwrap();
    Command::new(tessera_tests::bin("tessera-worker"))
        .args(["--coordinator", &c.url, "--threads", "1", "--name", name, "--cache-dir"])
        .arg(dir.join(name))
        .args(extra)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .unwrap()
}

fn submit_pt(c: &Coordinator, spp: u32, more: serde_json::Value) -> String {
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let mut settings = json!({"integrator": "pt", "spp": spp, "seed": 1});
    settings.as_object_mut().unwrap().extend(more.as_object().unwrap().clone());
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    job["id"].as_str().unwrap().to_string()
}

fn worker_named(c: &Coordinator, name: &str) -> Option<serde_json::Value> {
    let (_, workers) = rest::get_json(&format!("{}/api/v1/workers", c.url), None);
    workers.as_array()?.iter().find(|w| w["name"] == name).cloned()
}

/// A job requiring a tag waits, saying so, while only an untagged worker is up (which renders
/// another job meanwhile); a worker with the tag then renders all of it.
#[test]
fn a_job_with_required_tags_waits_then_runs_only_on_tagged_workers() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let mut plain = worker_logged(&c, dir.path(), "plain", &[]);
    let tagged = submit_pt(&c, 4, json!({"require_tags": ["big"]}));
    let (_, job) = rest::get_json(&job_url(&c, &tagged), None);
    assert_eq!(job["phase"], "waiting for a worker with tags big", "{job}");
    let other = submit_pt(&c, 2, json!({}));
    wait_done(&c, &other, None);
    assert_eq!(rest::get_json(&job_url(&c, &tagged), None).1["tiles_done"], 0);
    let mut big = worker_logged(&c, dir.path(), "big", &["--tags", "big,fast"]);
    wait_done(&c, &tagged, None);
    let w = wait_for(TIMEOUT, "the tagged worker", || worker_named(&c, "big"));
    assert_eq!(w["tags"], json!(["big", "fast"]));
    for child in [&mut plain, &mut big] {
        child.kill().unwrap();
        child.wait().unwrap();
    }
    let plain_log = std::fs::read_to_string(dir.path().join("plain.log")).unwrap();
    let big_log = std::fs::read_to_string(dir.path().join("big.log")).unwrap();
    assert!(plain_log.contains(&other) && !plain_log.contains(&tagged), "{plain_log}");
    assert!(big_log.contains(&tagged), "{big_log}");
}

/// Disabled from the server, a worker gets nothing (it asks after the job is there and is
/// turned away) until it is enabled; drained, a worker started with `--exit-when-drained`
/// finishes the tile it holds and exits with status 0.
#[test]
fn disable_enable_and_drain_from_the_server() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let mut w = worker_logged(&c, dir.path(), "w", &["--exit-when-drained"]);
    let id = wait_for(TIMEOUT, "the worker", || worker_named(&c, "w"))["id"].as_str().unwrap().to_string();
    let (ok, out, err) = tessera(&["worker", "disable", &id[..8], "--server", &c.url]);
    assert!(ok && out.contains("disabled"), "{err}");
    let submitted = std::time::Instant::now();
    let job = submit_pt(&c, 64, json!({}));
    wait_for(TIMEOUT, "the disabled worker to ask for work", || {
        let w = worker_named(&c, "w")?;
        (w["last_seen_s_ago"].as_f64()? < submitted.elapsed().as_secs_f64()).then_some(())
    });
    let (_, held) = rest::get_json(&job_url(&c, &job), None);
    assert_eq!((held["tiles_done"].as_u64(), worker_named(&c, "w").unwrap()["leases"].as_u64()), (Some(0), Some(0)));
    assert!(tessera(&["worker", "enable", &id, "--server", &c.url]).0);
    let before = wait_for(TIMEOUT, "a tile in hand", || {
        let busy = worker_named(&c, "w")?;
        (busy["state"] == "busy").then(|| rest::get_json(&job_url(&c, &job), None).1["tiles_done"].as_u64().unwrap())
    });
    let (status, drained) = rest::post(&format!("{}/api/v1/workers/{id}/drain", c.url), None);
    assert_eq!((status, drained["state"].as_str()), (200, Some("draining")), "{drained}");
    let exit = wait_for(TIMEOUT, "the drained worker to exit", || w.try_wait().unwrap());
    assert!(exit.success(), "{exit:?}");
    let after = rest::get_json(&job_url(&c, &job), None).1["tiles_done"].as_u64().unwrap();
    assert!(after > before, "the tile in hand was not finished");
    let (ok, listed, _) = tessera(&["workers", "--server", &c.url, "--json"]);
    assert!(ok && (listed.contains("\"draining\"") || listed.contains("\"offline\"")), "{listed}");
}
