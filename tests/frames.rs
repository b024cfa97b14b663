//! Jobs of many frames on a real farm: a camera move (the frame number rotates the camera) on
//! three workers equals the local render of each frame bit for bit, with the seed fixed or
//! varying per frame; one scene file per frame; a frame whose scene does not load fails alone,
//! and a cancelled frame is retried alone; EMIS frames that start from the frame before's
//! decision equal the local warm chain.

use super::*;
use std::path::PathBuf;

/// cornell-box with the camera turned by `$frame` degrees about the vertical axis.
fn camera_move(dir: &Path) -> PathBuf {
    let xml = std::fs::read_to_string(scene("cornell-box")).unwrap();
    let lookat = r#"<lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/>"#;
    assert!(xml.contains(lookat));
    let xml = xml.replacen(lookat, &format!(r#"{lookat}<rotate y="1" angle="$frame"/>"#), 1);
    let xml =
        xml.replacen(r#"<scene version="3.0.0">"#, r#"<scene version="3.0.0"><default name="frame" value="0"/>"#, 1);
    let path = dir.join("move.xml");
    std::fs::write(&path, xml).unwrap();
    path
}

/// `tessera submit SCENE` of `pt` at (spp, seed) with `more` flags; its output (the job id).
fn submit(c: &Coordinator, scene: &str, (spp, seed): (u32, u64), more: &[&str]) -> String {
    let (spp, seed) = (spp.to_string(), seed.to_string());
    let mut args = vec!["submit", scene, "--server", &c.url, "--integrator", "pt", "--spp", &spp, "--seed", &seed];
    args.extend(more);
    let (ok, out, err) = tessera(&args);
    assert!(ok, "{err}");
    out
}

fn local_frame(dir: &Path, scene: &Path, frame: u32, seed: u64) -> PathBuf {
    let define = format!("frame={frame}");
    let out = dir.join(format!("local-{frame}-{seed}.exr"));
    let (ok, _, err) = tessera(&[
        "render",
        scene.to_str().unwrap(),
        "--integrator",
        "pt",
        "--spp",
        "2",
        "--seed",
        &seed.to_string(),
        "-D",
        &define,
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    out
}

/// 12 frames of a camera move on three workers, each equal to `tessera render -D frame=N`.
#[test]
fn a_camera_move_on_three_workers_equals_twelve_local_renders() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _workers) = farm(dir.path(), 3);
    let scene = camera_move(dir.path());
    let out = dir.path().join("out/move.####.exr");
    submit(&c, scene.to_str().unwrap(), (2, 5), &["--frames", "1-12", "--wait", "-o", out.to_str().unwrap()]);
    for n in 1..=12 {
        let farm = dir.path().join(format!("out/move.{n:04}.exr"));
        assert_same_image(&farm, &local_frame(dir.path(), &scene, n, 5));
        assert!(farm.with_extension("png").exists());
    }
    let (_, jobs) = rest::get_json(&format!("{}/api/v1/jobs", c.url), None);
    let job = &jobs.as_array().unwrap()[0];
    assert_eq!((job["state"].as_str(), job["frames_total"].as_u64()), (Some("done"), Some(12)), "{job}");
    assert_eq!(jobs.as_array().unwrap().len(), 1, "one job, its frames inside it");
    // all of them as one archive: the same files
    let (status, tar) = rest::get(&format!("{}/frames.tar", job_url(&c, job["id"].as_str().unwrap())), None);
    assert_eq!(status, 200);
    let mut archive = tar::Archive::new(tar.as_slice());
    let mut names = Vec::new();
    for entry in archive.entries().unwrap() {
        let mut entry = entry.unwrap();
        let name = entry.path().unwrap().display().to_string();
        let mut bytes = Vec::new();
        std::io::Read::read_to_end(&mut entry, &mut bytes).unwrap();
        let farm = std::fs::read(dir.path().join("out").join(&name)).unwrap();
        assert!(bytes == farm, "{name} differs from the one downloaded alone");
        names.push(name);
    }
    assert_eq!(names.len(), 24);
    assert_eq!((names[0].as_str(), names[23].as_str()), ("move.0001.exr", "move.0012.png"));
}

/// One file per frame and a seed per frame: frame N equals the local render of its own file
/// with seed S + N. A frame whose scene does not load on the coordinator fails alone; a frame
/// cancelled alone is requeued alone and finishes.
#[test]
fn per_frame_files_seed_per_frame_and_frames_that_fail_or_are_retried_alone() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _workers) = farm(dir.path(), 2);
    let base = std::fs::read_to_string(camera_move(dir.path())).unwrap();
    for n in 1..=4 {
        let mut xml = base.replace("$frame", &(n * 10).to_string());
        if n == 3 {
            // over the coordinator's film limit: this frame's scene is refused, the file packs
            xml = xml
                .replace(r#"name="width" value="256""#, r#"name="width" value="20000""#)
                .replace(r#"name="height" value="256""#, r#"name="height" value="20000""#);
        }
        std::fs::write(dir.path().join(format!("shot.{n:02}.xml")), xml).unwrap();
    }
    let pattern = dir.path().join("shot.##.xml");
    let id = submit(&c, pattern.to_str().unwrap(), (2, 7), &["--frames", "1-4", "--seed-per-frame"]);
    let id = id.trim().to_string();
    let job = wait_for(TIMEOUT, "the frames to end", || {
        let (_, job) = rest::get_json(&job_url(&c, &id), None);
        ["done", "failed"].contains(&job["state"].as_str()?).then_some(job)
    });
    assert_eq!(job["state"], "failed", "{job}");
    let frames = job["frames"].as_array().unwrap();
    let states: Vec<_> = frames.iter().map(|f| f["state"].as_str().unwrap()).collect();
    assert_eq!(states, ["done", "done", "failed", "done"], "{job}");
    assert!(frames[2]["error"].as_str().unwrap().contains("limit"), "{job}");
    for (i, n) in [(0, 1u32), (1, 2), (3, 4)] {
        let frame_id = frames[i]["job_id"].as_str().unwrap();
        let farm = dir.path().join(format!("farm-{n}.exr"));
        let (status, bytes) = rest::get(&format!("{}/result.exr", job_url(&c, frame_id)), None);
        assert_eq!(status, 200);
        std::fs::write(&farm, bytes).unwrap();
        let own = dir.path().join(format!("shot.{n:02}.xml"));
        assert_same_image(&farm, &local_render(dir.path(), &own, "pt", 2, 7 + u64::from(n)));
    }
    // the refused frame cannot be mended by a requeue; a cancelled one is retried alone
    let refused = frames[2]["job_id"].as_str().unwrap();
    let (status, _) = rest::post(&format!("{}/requeue", job_url(&c, refused)), None);
    assert_eq!(status, 409);
    let again = submit(&c, pattern.to_str().unwrap(), (256, 7), &["--frames", "1-2"]);
    let again = again.trim();
    let first = wait_for(TIMEOUT, "the first frame", || {
        let (_, job) = rest::get_json(&job_url(&c, again), None);
        job["frames"][0]["job_id"].as_str().map(str::to_string)
    });
    control_cancel_and_requeue(&c, &first);
    let done = wait_for(TIMEOUT, "the requeued frame's job", || {
        let (_, job) = rest::get_json(&job_url(&c, again), None);
        (job["state"] == "done").then_some(job)
    });
    assert_eq!(done["frames"][0]["state"], "done", "{done}");
}

fn control_cancel_and_requeue(c: &Coordinator, frame: &str) {
    let (status, _) = rest::post(&format!("{}/cancel", job_url(c, frame)), None);
    assert_eq!(status, 200);
    let (status, body) = rest::post(&format!("{}/requeue", job_url(c, frame)), None);
    assert_eq!(status, 200, "{body}");
}

/// `--warm-start` on emis-vcm: caustic-glass with its camera turning. Frame 1 starts with path
/// tracing and restarts into a bidirectional strategy; frames 2 and 3 start from the decision
/// of the frame before, so nothing restarts. On three workers each frame equals the local
/// chain `tessera render --frames 1-3 --warm-start` bit for bit (image, counts, decisions), and
/// differs from its cold render.
#[test]
fn warm_started_emis_frames_equal_the_local_warm_chain() {
    use tessera_common::film::exr::read_attribute;
    let dir = tempfile::tempdir().unwrap();
    let (c, _workers) = farm(dir.path(), 3);
    let original = scene("caustic-glass");
    std::fs::copy(original.with_file_name("gem.obj"), dir.path().join("gem.obj")).unwrap();
    let xml = std::fs::read_to_string(&original).unwrap();
    let lookat = r#"<lookat origin="0, 3.5, 8.5" target="0.4, 0.8, 0" up="0, 1, 0"/>"#;
    assert!(xml.contains(lookat));
    let xml = xml.replacen(lookat, &format!(r#"{lookat}<rotate y="1" angle="$frame"/>"#), 1).replacen(
        r#"<scene version="3.0.0">"#,
        r#"<scene version="3.0.0"><default name="frame" value="0"/>"#,
        1,
    );
    let moving = dir.path().join("glass.xml");
    std::fs::write(&moving, xml).unwrap();
    let moving = moving.to_str().unwrap();
    let emis = ["--integrator", "emis-vcm", "--spp", "6", "--seed", "4", "--emis-updates", "1,2,4,8"];
    let farm_out = dir.path().join("farm/glass.####.exr");
    let mut args = vec!["submit", moving, "--server", &c.url, "--frames", "1-3", "--warm-start", "--wait", "-o"];
    args.push(farm_out.to_str().unwrap());
    args.extend(emis);
    let (ok, _, err) = tessera(&args);
    assert!(ok, "{err}");
    let render = |out: &str, more: &[&str]| {
        let mut args = vec!["render", moving, "--threads", "2", "--frames", "1-3", "-o", out];
        args.extend(emis.iter().chain(more));
        let (ok, _, err) = tessera(&args);
        assert!(ok, "{err}");
    };
    let (warm, cold) = (dir.path().join("warm/glass.####.exr"), dir.path().join("cold/glass.####.exr"));
    render(warm.to_str().unwrap(), &["--warm-start"]);
    render(cold.to_str().unwrap(), &[]);
    let frame = |pattern: &Path, n: u32| pattern.with_file_name(format!("glass.{n:04}.exr"));
    let kept_from = |path: &Path| read_attribute(path, "tessera/emis_kept_from").unwrap();
    for n in 1..=3 {
        let (farm, local) = (frame(&farm_out, n), frame(&warm, n));
        assert_same_image(&farm, &local);
        for key in ["tessera/emis_nu", "tessera/emis_connections", "tessera/emis_updates", "tessera/emis_kept_from"] {
            assert_eq!(read_attribute(&farm, key).unwrap(), read_attribute(&local, key).unwrap(), "frame {n}: {key}");
        }
        let read = |p: &Path| tessera_common::film::exr::read_rgb(p).unwrap().pixels;
        if n == 1 {
            assert!(kept_from(&local).unwrap() > 0.0, "the first frame starts with path tracing and restarts");
            assert_same_image(&local, &frame(&cold, n));
        } else {
            assert_eq!(kept_from(&local), Some(0.0), "frame {n} starts warm: nothing restarts");
            let nu = read_attribute(&local, "tessera/emis_nu").unwrap().unwrap();
            assert!(nu > 0.0, "frame {n} keeps a bidirectional strategy");
            assert!(read(&local) != read(&frame(&cold, n)), "frame {n} warm differs from cold");
        }
    }
}
