//! Farm integration tests: the real `tessera serve` coordinator and `tessera-worker` processes
//! on loopback ports. Every finished image is compared **bit for bit** with `tessera render` on
//! the same scene, integrator, spp and seed: the farm cuts work and merges it in the same
//! canonical order as local rendering, since both run the same job driver
//! (`common/src/driver/`).

use serde_json::{Value, json};
use std::path::Path;
use std::time::Duration;
use tessera_tests::{
    Coordinator, Worker, assert_same_emis_outputs, assert_same_image, farm, local_render, local_render_with, rest,
    scene, submit_and_wait, tessera, wait_for, wait_for_or,
};

const TIMEOUT: Duration = Duration::from_secs(240);

fn job_url(c: &Coordinator, id: &str) -> String {
    format!("{}/api/v1/jobs/{id}", c.url)
}

/// Polls a job over REST until it is done, checking that its state only moves forward and
/// its progress never goes back.
fn wait_done(c: &Coordinator, id: &str, token: Option<&str>) -> Value {
    let order = ["queued", "pilot", "optimizing", "final", "done"];
    let (mut rank, mut progress, mut tiles) = (0, 0.0, 0);
    wait_for(TIMEOUT, "job done", || {
        let (status, job) = rest::get_json(&job_url(c, id), token);
        assert_eq!(status, 200, "{job}");
        let state = job["state"].as_str().unwrap_or("?");
        let r = order.iter().position(|s| *s == state).unwrap_or_else(|| panic!("job ended {state}: {job}"));
        assert!(r >= rank, "state went back to {state}");
        let p = job["progress"].as_f64().unwrap();
        let t = job["tiles_done"].as_u64().unwrap();
        assert!(p >= progress && t >= tiles, "progress went back: {job}");
        (rank, progress, tiles) = (r, p, t);
        (state == "done").then_some(job)
    })
}

fn download(url: &str, token: Option<&str>, path: &Path) {
    let (status, bytes) = rest::get(url, token);
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&bytes));
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn grpc_submit_pt_with_two_workers_equals_local_render() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 2);
    let out = dir.path().join("farm.exr");
    let box_scene = scene("cornell-box");
    let (ok, stdout, stderr) = submit_and_wait(&c.url, &box_scene, ("pt", 3, 5), &out, &[]);
    assert!(ok, "submit failed: {stderr}\nlog: {}", c.log.display());
    assert!(out.with_extension("png").exists());
    let id = stdout.lines().next().unwrap().trim().to_string();
    let (ok, status, _) = tessera(&["status", &id, "--server", &c.url, "--json"]);
    assert!(ok);
    let status: Value = serde_json::from_str(&status).unwrap();
    assert_eq!((status["state"].as_str(), status["progress"].as_f64()), (Some("done"), Some(1.0)));
    assert_same_image(&out, &local_render(dir.path(), &box_scene, "pt", 3, 5));
    // a scene named from its own folder, as users type it
    let submitted = std::process::Command::new(tessera_tests::bin("tessera"))
        .args(["submit", "scene.xml", "--server", &c.url, "--spp", "1"])
        .current_dir(box_scene.parent().unwrap())
        .output()
        .unwrap();
    assert!(submitted.status.success(), "{}", String::from_utf8_lossy(&submitted.stderr));
}

/// Mitsuba's default Gaussian filter reaches across 64² tile borders (pt) and spreads splats
/// (bdpt), and a crop window renders part of the film: the farm still adds exactly what a
/// local render adds.
#[test]
fn a_gaussian_filter_and_a_crop_window_render_on_the_farm_as_locally() {
    let dir = tempfile::tempdir().unwrap();
    let xml = std::fs::read_to_string(scene("cornell-box")).unwrap();
    let filtered = xml.replace(
        r#"<rfilter type="box"/>"#,
        r#"<integer name="crop_offset_x" value="20"/><integer name="crop_offset_y" value="40"/>
           <integer name="crop_width" value="150"/><integer name="crop_height" value="130"/>"#,
    );
    assert_ne!(filtered, xml, "the box filter line is gone, so the default Gaussian applies");
    let path = dir.path().join("filtered.xml");
    std::fs::write(&path, filtered).unwrap();
    let (c, _w) = farm(dir.path(), 2);
    for integrator in ["pt", "bdpt"] {
        let out = dir.path().join(format!("farm-{integrator}.exr"));
        let (ok, _, stderr) = submit_and_wait(&c.url, &path, (integrator, 2, 9), &out, &[]);
        assert!(ok, "submit failed: {stderr}\nlog: {}", c.log.display());
        let local = local_render(dir.path(), &path, integrator, 2, 9);
        assert_eq!(tessera_common::film::exr::read_rgb(&local).unwrap().width, 150);
        assert_same_image(&out, &local);
    }
}

/// Users' scenes on the farm: an OpenEXR environment map with the Gaussian filter (pt and
/// bdpt, whose light paths start on the map), bitmap textures and an RGBE map, and a scene split
/// over `<include>` files found through `<path>`. The client bundles every file, the workers
/// resolve names inside the bundle, and the image equals a local render bit for bit.
#[test]
fn environment_maps_textures_and_includes_render_on_the_farm_as_locally() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 2);
    for (name, integrator) in
        [("envmap-glossy", "pt"), ("envmap-glossy", "bdpt"), ("textured-room", "pt"), ("included-scene", "pt")]
    {
        let sub = dir.path().join(format!("{name}-{integrator}"));
        std::fs::create_dir_all(&sub).unwrap();
        let out = sub.join("farm.exr");
        let path = scene(name);
        let (ok, _, stderr) = submit_and_wait(&c.url, &path, (integrator, 2, 4), &out, &[]);
        assert!(ok, "{name} {integrator}: submit failed: {stderr}\nlog: {}", c.log.display());
        assert_same_image(&out, &local_render(&sub, &path, integrator, 2, 4));
    }
}

#[test]
fn rest_submit_vcm_equals_local_render_and_reports_progress() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 2);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let (status, job) =
        rest::submit(&c.url, None, ("scene.xml", xml), vec![], json!({"integrator": "vcm", "spp": 3, "seed": 9}));
    assert_eq!(status, 201, "{job}");
    assert_eq!(job["tiles_total"], 3, "one full-frame tile per iteration: {job}");
    assert!(job["strategy"].is_null());
    let id = job["id"].as_str().unwrap();
    let done = wait_done(&c, id, None);
    assert_eq!(done["samples_done"], 256 * 256 * 3);
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, id)), None, &out);
    assert_same_image(&out, &local_render(dir.path(), &scene("cornell-box"), "vcm", 3, 9));
    let (status, png) = rest::get(&format!("{}/preview.png", job_url(&c, id)), None);
    assert_eq!((status, &png[1..4]), (200, &b"PNG"[..]));
    for name in ["strategy.png", "emis.json"] {
        let (status, body) = rest::get_json(&format!("{}/{name}", job_url(&c, id)), None);
        assert_eq!(status, 404, "{body}");
        assert!(body["error"].as_str().unwrap().contains("only emis-bdpt and emis-vcm jobs"), "{body}");
    }
    let (_, workers) = rest::get_json(&format!("{}/api/v1/workers", c.url), None);
    assert_eq!(workers.as_array().unwrap().len(), 2);
    let (_, metrics) = rest::get(&format!("{}/metrics", c.url), None);
    let metrics = String::from_utf8(metrics).unwrap();
    assert!(metrics.contains("tessera_jobs{state=\"done\"} 1"), "{metrics}");
    assert!(metrics.contains("tessera_tiles_merged_total 3"), "{metrics}");
}

#[test]
fn scene_with_assets_renders_over_rest() {
    // caustic-glass references gem.obj: the bundle must carry it to the workers
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let glass = scene("caustic-glass");
    let xml = std::fs::read(&glass).unwrap();
    let obj = std::fs::read(glass.with_file_name("gem.obj")).unwrap();
    let settings = json!({"integrator": "pt", "spp": 1, "seed": 2, "defines": {}});
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml.clone()), vec![], settings.clone());
    assert_eq!(status, 400, "a missing mesh is refused at submission: {job}");
    assert!(job["error"].as_str().unwrap().contains("gem.obj"), "{job}");
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![("gem.obj".into(), obj)], settings);
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    wait_done(&c, id, None);
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, id)), None, &out);
    assert_same_image(&out, &local_render(dir.path(), &glass, "pt", 1, 2));
}

#[test]
fn killing_one_of_three_workers_mid_job_leaves_the_image_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--lease-timeout", "1"]);
    let mut workers: Vec<_> =
        (0..3).map(|i| Worker::start(&c.url, &dir.path().join("cache"), &["--name", &format!("w{i}")])).collect();
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let (_, job) =
        rest::submit(&c.url, None, ("scene.xml", xml), vec![], json!({"integrator": "pt", "spp": 96, "seed": 4}));
    let id = job["id"].as_str().unwrap().to_string();
    // kill w0 once some tiles are in and a lease it held expired: freeze it (SIGSTOP) and wait
    // until it holds no lease. A lease ends then by its expiry, or by an upload w0 had sent
    // whole before it froze; if none expired, let w0 go on and try again.
    let pid = workers[0].child.id() as i32;
    let expired = |c: &Coordinator| {
        let metrics = String::from_utf8(rest::get(&format!("{}/metrics", c.url), None).1).unwrap();
        !metrics.contains("tessera_leases_expired_total 0")
    };
    let at_kill = wait_for(TIMEOUT, "a lease of w0 to expire after the first tile", || {
        // SAFETY: signalling our own child process
        unsafe { libc::kill(pid, libc::SIGSTOP) };
        // the last answers, for the message should w0 never be seen idle (it once was not,
        // under load, for 240 s)
        let mut last = (0, serde_json::Value::Null);
        let job = wait_for_or(TIMEOUT, || {
            last = rest::get_json(&format!("{}/api/v1/workers", c.url), None);
            let w0_idle = last.1.as_array()?.iter().any(|w| w["name"] == "w0" && w["leases"] == 0);
            w0_idle.then(|| rest::get_json(&job_url(&c, &id), None).1)
        })
        .unwrap_or_else(|| {
            let (_, job) = rest::get_json(&job_url(&c, &id), None);
            panic!("w0 held a lease for {TIMEOUT:?}: workers answered {} {}; the job: {job}", last.0, last.1)
        });
        let ready = job["tiles_done"].as_u64() >= Some(1) && expired(&c);
        if !ready {
            // SAFETY: as above
            unsafe { libc::kill(pid, libc::SIGCONT) };
        }
        ready.then_some(job)
    });
    workers[0].kill();
    let (done, total) = (at_kill["tiles_done"].as_u64().unwrap(), at_kill["tiles_total"].as_u64().unwrap());
    assert!(done * 8 < total * 7, "the job was nearly done before the kill: {at_kill}");
    let done = wait_done(&c, &id, None);
    assert_eq!(done["tiles_done"], done["tiles_total"]);
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, &id)), None, &out);
    assert_same_image(&out, &local_render(dir.path(), &scene("cornell-box"), "pt", 96, 4));
}

#[test]
fn sigterm_drains_a_worker_it_finishes_and_uploads_its_tile() {
    let dir = tempfile::tempdir().unwrap();
    // leases would take a minute to expire: only the drain can deliver the tile in time
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--lease-timeout", "60"]);
    let mut w = Worker::start(&c.url, &dir.path().join("cache"), &["--name", "w0"]);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let (_, job) =
        rest::submit(&c.url, None, ("scene.xml", xml), vec![], json!({"integrator": "pt", "spp": 32, "seed": 1}));
    let id = job["id"].as_str().unwrap().to_string();
    let before = wait_for(TIMEOUT, "a lease", || {
        let before = rest::get_json(&job_url(&c, &id), None).1["tiles_done"].as_u64()?;
        let workers = rest::get_json(&format!("{}/api/v1/workers", c.url), None).1;
        workers.as_array()?.iter().any(|w| w["leases"].as_u64() >= Some(1)).then_some(before)
    });
    // SAFETY: signalling our own child process
    unsafe { libc::kill(w.child.id() as i32, libc::SIGTERM) };
    let status = wait_for(TIMEOUT, "the worker to drain", || w.child.try_wait().unwrap());
    assert!(status.success(), "{status:?}");
    let (_, job) = rest::get_json(&job_url(&c, &id), None);
    assert!(job["tiles_done"].as_u64().unwrap() > before, "the tile in hand was not uploaded: {job}");
    let (_, workers) = rest::get_json(&format!("{}/api/v1/workers", c.url), None);
    assert_eq!(workers[0]["leases"], 0, "the worker left a lease behind: {workers}");
}

/// Kills the coordinator once `kill_after` (but fewer than `kill_before`) tiles are done,
/// restarts it on the same data dir and checks that the job completes with every sample merged
/// once and the local image. `more`: further options of `tessera submit` and `tessera render`;
/// `discarded`: the iterations an EMIS path-tracing start must have discarded.
fn coordinator_killed_mid_job(
    (name, integrator, spp, more): (&str, &str, u32, &[&str]),
    discarded: u64,
    kill_after: u64,
    kill_before: u64,
) {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    // checkpoint after every merge, so that tiles are merged both before and after the crash
    let flags = ["--lease-timeout", "2", "--checkpoint-interval", "0"];
    let mut c = Coordinator::start(&data, "127.0.0.1:0", &flags);
    let _w: Vec<_> = (0..2).map(|_| Worker::start(&c.url, &dir.path().join("cache"), &[])).collect();
    // `tessera submit --wait` follows the job across the crash and downloads the result
    let out = dir.path().join("farm.exr");
    let mut submit = std::process::Command::new(tessera_tests::bin("tessera"))
        .args(["submit", scene(name).to_str().unwrap(), "--server", &c.url, "--integrator", integrator])
        .args(["--spp", &spp.to_string(), "--seed", "8", "--wait", "-o", out.to_str().unwrap()])
        .args(more)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut id = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(submit.stdout.take().unwrap()), &mut id).unwrap();
    let id = id.trim().to_string();
    let before = wait_for(TIMEOUT, "some tiles", || {
        let t = rest::get_json(&job_url(&c, &id), None).1["tiles_done"].as_u64().unwrap_or(0);
        (t >= kill_after).then_some(t)
    });
    assert!(before < kill_before, "the job went too far before the crash ({before} tiles); make it longer");
    c.kill();
    let listen = format!("127.0.0.1:{}", c.port());
    let c = wait_for(Duration::from_secs(20), "port to be free", || {
        std::net::TcpListener::bind(&listen).ok().map(drop)?;
        Some(Coordinator::start(&data, &listen, &flags))
    });
    let (_, resumed) = rest::get_json(&job_url(&c, &id), None);
    assert!(resumed["tiles_done"].as_u64().unwrap() >= before, "accepted tiles were lost: {resumed}");
    let done = wait_done(&c, &id, None);
    // iterations a path-tracing start discarded were rendered (and merged) too
    let updates = done["strategy"]["updates"].as_array().cloned().unwrap_or_default();
    let restart = updates.iter().find(|u| u["restarted"] == true).map_or(0, |u| u["iteration"].as_u64().unwrap());
    assert_eq!(restart, discarded, "the path-tracing start ends where expected: {updates:?}");
    let samples = 256 * 256 * (discarded + spp as u64);
    assert_eq!(done["samples_done"], samples, "every pixel sample merged exactly once: {done}");
    let status = wait_for(TIMEOUT, "tessera submit --wait to finish", || submit.try_wait().unwrap());
    assert!(status.success(), "submit --wait did not survive the restart: {status:?}");
    let local = local_render_with(dir.path(), &scene(name), integrator, spp, 8, more);
    assert_same_image(&out, &local);
    if integrator.starts_with("emis-") {
        // written by `tessera submit --wait` beside the EXR, from a job that crossed the crash
        assert_same_emis_outputs(&out, &local);
    }
    if discarded > 0 {
        let kept_from = tessera_common::film::exr::read_attribute(&out, "tessera/emis_kept_from").unwrap();
        assert_eq!(kept_from, Some(discarded as f64));
    }
}

#[test]
fn coordinator_killed_mid_job_resumes_from_its_data_dir() {
    coordinator_killed_mid_job(("cornell-box", "pt", 24, &[]), 0, 3, 16);
}

/// The EMIS state (merged moments, statistics, guides, strategy) survives the crash too: killed
/// after the updates at 1 and 4, inside the pass that collects moments for the update at 16.
/// The bidirectional pilot: its iterations all record, and are slow enough to crash within.
#[test]
fn coordinator_killed_mid_emis_job_resumes_with_its_moments() {
    coordinator_killed_mid_job(("cornell-box", "emis-vcm", 20, &["--emis-pilot", "bidirectional"]), 0, 6, 16);
}

/// A path-tracing start survives the crash with its restart: on caustic-glass (seed 8) the
/// update after 4 iterations picks a bidirectional strategy and sets the film aside as the
/// kept start (path tracing won narrowly after 1 and 2, both on the one recording of
/// iteration 0); the crash comes inside the pass collecting moments for the update at 32 (tiles
/// 4..12, 12..20, 20..28, 28..32 of eight iterations each at most, after tiles 0..1, 1..2,
/// 2..3 and 3..4), so the restarted film, the full-set moments, the kept start (which the
/// update at 32 weighs into the image) and the first kept iteration come back from the
/// checkpoint.
#[test]
fn coordinator_killed_mid_emis_job_after_a_restart_resumes_with_the_new_film() {
    let more = ["--emis-pilot", "path-tracing", "--emis-updates", "1,2,4,32"];
    coordinator_killed_mid_job(("caustic-glass", "emis-vcm", 40, &more), 4, 5, 8);
}

#[test]
fn tokens_bad_scenes_oversized_uploads_and_cancel_are_refused_or_obeyed() {
    let dir = tempfile::tempdir().unwrap();
    let (ct, wt) = (Some("client-secret"), "worker-secret");
    let c = Coordinator::start(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--client-token", "client-secret", "--worker-token", wt, "--max-upload-mb", "1"],
    );
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let settings = json!({"integrator": "pt", "spp": 1});
    // no token: 401 on REST, UNAUTHENTICATED on gRPC; /healthz and the dashboard page stay open
    let (status, _) = rest::submit(&c.url, None, ("scene.xml", xml.clone()), vec![], settings.clone());
    assert_eq!(status, 401);
    assert_eq!(rest::get(&format!("{}/healthz", c.url), None).0, 200);
    assert_eq!(rest::get(&format!("{}/api/v1/jobs", c.url), None).0, 401);
    // the dashboard page carries no data and stays open; the API it calls does not
    let (status, page) = rest::get(&format!("{}/", c.url), None);
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&page).contains("/api/v1/jobs"), "the dashboard polls the jobs API");
    let (ok, _, err) = tessera(&["status", "--server", &c.url]);
    assert!(!ok && err.contains("Unauthenticated"), "{err}");
    let (ok, _, _) = tessera(&["status", "--server", &c.url, "--token", "client-secret"]);
    assert!(ok);
    // an invalid scene: 400 naming the file and line; the same over gRPC is INVALID_ARGUMENT
    let bad = String::from_utf8(xml.clone()).unwrap().replacen(
        "<bsdf type=\"diffuse\" id=\"white\">",
        "<bsdf type=\"velvet\" id=\"white\">",
        1,
    );
    let line = bad.lines().position(|l| l.contains("velvet")).unwrap() + 1;
    let (status, body) = rest::submit(&c.url, ct, ("scene.xml", bad.clone().into_bytes()), vec![], settings.clone());
    assert_eq!(status, 400, "{body}");
    let message = body["error"].as_str().unwrap();
    assert!(message.contains(&format!("scene.xml:{line}:")) && message.contains("velvet"), "{message}");
    let bad_path = dir.path().join("scene.xml");
    std::fs::write(&bad_path, &bad).unwrap();
    let (ok, _, err) = tessera(&["submit", bad_path.to_str().unwrap(), "--server", &c.url, "--token", "client-secret"]);
    assert!(!ok && err.contains("InvalidArgument") && err.contains(&format!("scene.xml:{line}:")), "{err}");
    // settings naming an unknown field
    let (status, body) = rest::submit(&c.url, ct, ("scene.xml", xml.clone()), vec![], json!({"spq": 3}));
    assert_eq!(status, 400);
    assert!(body["error"].as_str().unwrap().contains("spq"), "{body}");
    // an upload over --max-upload-mb
    let (status, _) = rest::submit(
        &c.url,
        ct,
        ("scene.xml", xml.clone()),
        vec![("big.bin".into(), vec![0u8; 2 << 20])],
        settings.clone(),
    );
    assert_eq!(status, 413);
    // cancel stops dispatch: a worker started afterwards gets nothing; DELETE refuses the
    // job while it is active
    let (status, job) = rest::submit(&c.url, ct, ("scene.xml", xml.clone()), vec![], settings.clone());
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    let (status, body) = rest::delete(&job_url(&c, id), ct);
    assert_eq!(status, 409, "{body}");
    assert!(body["error"].as_str().unwrap().contains("cancel it"), "{body}");
    let (status, cancelled) = rest::post(&format!("{}/cancel", job_url(&c, id)), ct);
    assert_eq!((status, cancelled["state"].as_str()), (200, Some("cancelled")));
    assert_eq!(rest::post(&format!("{}/cancel", job_url(&c, "no-such-job")), ct).0, 404);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &["--token", wt]);
    wait_for(TIMEOUT, "worker to register", || {
        (rest::get_json(&format!("{}/api/v1/workers", c.url), ct).1.as_array().map_or(0, |a| a.len()) == 1)
            .then_some(())
    });
    // a job submitted after it is rendered by that worker, which took nothing of the first
    let (status, second) = rest::submit(&c.url, ct, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{second}");
    let second = wait_done(&c, second["id"].as_str().unwrap(), ct);
    assert!(second["tiles_done"].as_u64() > Some(0), "{second}");
    let (_, job) = rest::get_json(&job_url(&c, id), ct);
    assert_eq!((job["state"].as_str(), job["tiles_done"].as_u64()), (Some("cancelled"), Some(0)), "{job}");
    let (_, metrics) = rest::get(&format!("{}/metrics", c.url), ct);
    assert!(String::from_utf8(metrics).unwrap().contains("tessera_tiles_leased 0"));
    assert_eq!(rest::get(&format!("{}/result.exr", job_url(&c, id)), ct).0, 409);
    assert_eq!(rest::get(&job_url(&c, "no-such-job"), ct).0, 404);
}

/// `DELETE` removes a done job with its outputs (404 afterwards); `--retain-finished` removes
/// another on its own; `tessera delete` removes one over gRPC.
#[test]
fn rest_delete_and_retain_finished_remove_done_jobs() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let c = Coordinator::start(&data, "127.0.0.1:0", &["--retain-finished", "6s"]);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let submit = |seed: u64| {
        let settings = json!({"integrator": "pt", "spp": 1, "seed": seed});
        let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml.clone()), vec![], settings);
        assert_eq!(status, 201, "{job}");
        let id = job["id"].as_str().unwrap().to_string();
        wait_done(&c, &id, None);
        id
    };
    let blobs = || {
        let shards = std::fs::read_dir(data.join("blobs").join("cas")).unwrap();
        shards.flat_map(|s| std::fs::read_dir(s.unwrap().path()).unwrap()).count()
    };
    // one job: its bundle, EXR and PNG
    let deleted = submit(1);
    assert_eq!(blobs(), 3);
    let (status, body) = rest::delete(&job_url(&c, &deleted), None);
    assert_eq!(status, 204, "{body}");
    assert_eq!(rest::get(&job_url(&c, &deleted), None).0, 404);
    assert_eq!(rest::get(&format!("{}/result.exr", job_url(&c, &deleted)), None).0, 404);
    assert_eq!(rest::delete(&job_url(&c, &deleted), None).0, 404);
    assert_eq!(blobs(), 0, "its bundle and outputs are gone");
    // the next one expires by itself six seconds after it finished
    let expiring = submit(2);
    assert_eq!(rest::get(&job_url(&c, &expiring), None).0, 200);
    wait_for(Duration::from_secs(30), "job to expire", || {
        (rest::get(&job_url(&c, &expiring), None).0 == 404).then_some(())
    });
    let (_, jobs) = rest::get_json(&format!("{}/api/v1/jobs", c.url), None);
    assert_eq!(jobs.as_array().map(Vec::len), Some(0), "{jobs}");
    assert_eq!(blobs(), 0);
    // over gRPC
    let by_cli = submit(3);
    let (ok, _, err) = tessera(&["delete", &by_cli, "--server", &c.url]);
    assert!(ok, "{err}");
    assert_eq!(rest::get(&job_url(&c, &by_cli), None).0, 404);
    let (ok, _, err) = tessera(&["delete", &by_cli, "--server", &c.url]);
    assert!(!ok && err.contains("NotFound"), "{err}");
}

#[test]
fn serve_refuses_a_public_address_without_tokens() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let (ok, _, err) = tessera(&["serve", "--listen", "0.0.0.0:0", "--data-dir", data.to_str().unwrap()]);
    assert!(!ok && err.contains("refusing to listen on 0.0.0.0:0") && err.contains("--insecure"), "{err}");
    assert!(err.contains("without TLS (--tls-cert, --tls-key) and tokens"), "{err}");
}

#[test]
fn image_comparison_notices_a_different_seed() {
    let dir = tempfile::tempdir().unwrap();
    let a = local_render(dir.path(), &scene("cornell-box"), "pt", 1, 1);
    let b = local_render(dir.path(), &scene("cornell-box"), "pt", 1, 2);
    assert_same_image(&a, &a);
    assert!(std::panic::catch_unwind(|| assert_same_image(&a, &b)).is_err());
}

mod api;
mod bad_results;
mod bounded_memory;
mod client;
mod connections;
mod control;
mod emis;
mod faults;
mod frames;
mod hostile;
mod logs;
mod scale;
mod tls;
mod workers;
