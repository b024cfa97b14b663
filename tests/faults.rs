//! Faults that must end in bounded time, with real processes: a worker that heartbeats but
//! never returns its tile loses it at the lease's lifetime; cancelling a job stops the render
//! in progress within about one heartbeat; a restarted worker keeps its identity, and nobody
//! else can take it; a failed database commit stops the coordinator, and a restart finishes the
//! job.

use super::*;
use tessera_proto::v1 as pb;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;

fn submit_cornell(c: &Coordinator, settings: Value) -> String {
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    job["id"].as_str().unwrap().to_string()
}

#[test]
fn a_worker_that_heartbeats_but_never_returns_loses_its_tile() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--lease-max-floor", "1"]);
    let id = submit_cornell(&c, json!({"integrator": "pt", "spp": 2, "seed": 9}));
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let started = std::time::Instant::now();
    rt.block_on(async {
        let mut client = WorkerServiceClient::connect(c.url.clone()).await.unwrap();
        let reg = pb::RegisterRequest { name: "stuck".into(), threads: 1, ..tessera_link::build::registration() };
        let worker = client.register(reg).await.unwrap().into_inner().worker_id;
        let req = pb::LeaseTileRequest { worker_id: worker.clone(), max_tiles: 1, wait_ms: 5000 };
        let lease = client.lease_tile(req).await.unwrap().into_inner().leases.pop().unwrap().lease.unwrap();
        // heartbeats every 200 ms, far within the 30 s lease timeout, but never a result
        loop {
            let req = pb::HeartbeatRequest { worker_id: worker.clone(), leases: vec![lease.clone()] };
            if client.heartbeat(req).await.unwrap().into_inner().lost == [lease.clone()] {
                break;
            }
            assert!(started.elapsed() < Duration::from_secs(20), "the stuck lease was never taken back");
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
    });
    let held = started.elapsed();
    assert!(held >= Duration::from_secs(1), "taken back before its lifetime: {held:?}");
    // a worker that does return them finishes the job, bit for bit as a local render
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let job = wait_done(&c, &id, None);
    assert!(job["tiles_done"].as_u64().unwrap() > 0);
    let farm = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, &id)), None, &farm);
    assert_same_image(&farm, &local_render(dir.path(), &scene("cornell-box"), "pt", 2, 9));
}

/// One worker renders a tile that would take minutes; cancelling its job frees the worker
/// for the next job within about a heartbeat (500 ms here), because the render stops.
#[test]
fn cancel_stops_the_render_in_progress() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--lease-timeout", "2"]);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let long = submit_cornell(&c, json!({"integrator": "pt", "spp": 100000, "seed": 1}));
    wait_for(TIMEOUT, "the long job to be rendering", || {
        let (_, metrics) = rest::get(&format!("{}/metrics", c.url), None);
        String::from_utf8(metrics).unwrap().contains("tessera_tiles_leased 1").then_some(())
    });
    let (ok, _, err) = tessera(&["cancel", &long, "--server", &c.url]);
    assert!(ok, "{err}");
    let cancelled = std::time::Instant::now();
    let next = submit_cornell(&c, json!({"integrator": "pt", "spp": 1, "seed": 2}));
    wait_done(&c, &next, None);
    // a 64² tile at 100 000 spp on one thread takes minutes; the next job took seconds
    let took = cancelled.elapsed();
    assert!(took < Duration::from_secs(60), "the cancelled render went on: {took:?}");
}

#[test]
fn a_restarted_worker_keeps_its_identity_and_nobody_else_can_take_it() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let workers = || -> Vec<String> {
        let (_, list) = rest::get_json(&format!("{}/api/v1/workers", c.url), None);
        list.as_array().unwrap().iter().map(|w| w["id"].as_str().unwrap().to_string()).collect()
    };
    let cache = dir.path().join("cache");
    let mut w = Worker::start(&c.url, &cache, &[]);
    let first = wait_for(TIMEOUT, "a worker", || workers().pop());
    w.kill();
    let _w = Worker::start(&c.url, &cache, &[]);
    wait_for(TIMEOUT, "the worker to register again", || {
        let log = std::fs::read_to_string(&c.log).unwrap();
        (log.matches("worker registered").count() == 2).then_some(())
    });
    assert_eq!(workers(), [first.clone()], "the same id, not a second worker");
    // its id without its secret is refused
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut client = WorkerServiceClient::connect(c.url.clone()).await.unwrap();
        let reg = pb::RegisterRequest {
            name: "impostor".into(),
            threads: 1,
            worker_id: first.clone(),
            worker_secret: "0123456789abcdef0123456789abcdef".into(),
            ..tessera_link::build::registration()
        };
        let e = client.register(reg).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{e:?}");
        assert!(e.message().contains("another secret"), "{}", e.message());
    });
}

/// A real storage fault: the coordinator may not write files past 3 MiB (`RLIMIT_FSIZE`, with
/// `SIGXFSZ` ignored so that the write fails instead of killing it), so the database commit
/// that grows its log past that fails. The coordinator stops with exit code 70; restarted
/// without the limit on the same data folder, it finishes the job bit for bit as a local render.
#[test]
fn a_failed_commit_stops_the_coordinator_and_a_restart_finishes_the_job() {
    use std::os::unix::process::CommandExt;
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // 64 tiles of 64² whose results (112 KiB each) stay in the database without checkpoints
    let xml = std::fs::read_to_string(scene("cornell-box")).unwrap().replace("value=\"256\"", "value=\"512\"");
    let path = dir.path().join("scene.xml");
    std::fs::write(&path, &xml).unwrap();
    let flags = ["--checkpoint-interval", "100000"];
    let mut c = Coordinator::start_with(&data, "127.0.0.1:0", &flags, |command| {
        // SAFETY: only async-signal-safe calls between fork and exec
        unsafe {
            command.pre_exec(|| {
                let limit = libc::rlimit { rlim_cur: 3 << 20, rlim_max: 3 << 20 };
                libc::setrlimit(libc::RLIMIT_FSIZE, &limit);
                libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
                Ok(())
            });
        }
    });
    let (status, job) = rest::submit(
        &c.url,
        None,
        ("scene.xml", xml.into_bytes()),
        vec![],
        json!({"integrator": "pt", "spp": 2, "seed": 5}),
    );
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap().to_string();
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let exit = wait_for(TIMEOUT, "the coordinator to stop", || c.child.try_wait().unwrap());
    let log = std::fs::read_to_string(&c.log).unwrap();
    assert_eq!(exit.code(), Some(70), "{log}");
    assert!(log.contains("database commit failed"), "{log}");
    let listen = format!("127.0.0.1:{}", c.port());
    let c = wait_for(Duration::from_secs(20), "port to be free", || {
        std::net::TcpListener::bind(&listen).ok().map(drop)?;
        Some(Coordinator::start(&data, &listen, &flags))
    });
    let (_, resumed) = rest::get_json(&job_url(&c, &id), None);
    let before = resumed["tiles_done"].as_u64().unwrap();
    assert!((1..64).contains(&before), "the fault should come mid-job: {resumed}");
    let done = wait_done(&c, &id, None);
    assert_eq!(done["samples_done"], 512 * 512 * 2, "every sample merged once: {done}");
    let farm = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, &id)), None, &farm);
    assert_same_image(&farm, &local_render(dir.path(), &path, "pt", 2, 5));
}
