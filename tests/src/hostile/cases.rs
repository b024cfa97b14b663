//! The cases a client sends: scenes, files and settings that asked for far more than they
//! weigh, and requests that cost time out of proportion.

use super::inputs::{self, HEAD};
use super::procs::{Bins, peak, settle};
use super::{Case, PATIENCE, Report, answer, timed};
use crate::rest;
use serde_json::json;
use std::path::Path;
use std::time::Duration;

pub(super) fn all() -> Vec<Case> {
    vec![
        Case { name: "nested-elements", class: "one request stops the coordinator", run: nested },
        Case { name: "time-budget-1e8", class: "one request stops the coordinator", run: time_budget },
        Case { name: "light-paths-1e6", class: "one job stops every worker", run: light_paths },
        Case { name: "ref-bomb", class: "memory out of proportion", run: ref_bomb },
        Case { name: "mesh-20-shapes", class: "memory out of proportion", run: shared_mesh },
        Case { name: "serialized-bomb", class: "memory out of proportion", run: serialized_bomb },
        Case { name: "ply-one-byte-records", class: "memory out of proportion", run: ply_records },
        Case { name: "exr-flat-8192", class: "memory out of proportion", run: flat_exr },
        Case { name: "png-claims-16384-x3", class: "memory out of proportion", run: png_claims },
        Case { name: "long-bundle-path", class: "memory out of proportion", run: long_path },
        Case { name: "50k-elements", class: "CPU out of proportion", run: many_elements },
        Case { name: "4000-paths", class: "CPU out of proportion", run: many_paths },
        Case { name: "100k-parts", class: "CPU out of proportion", run: many_parts },
        Case { name: "bitmap-named-dot", class: "errors show server paths", run: bitmap_dot },
    ]
}

/// Submits `scene` (as `name`) with `assets` and `settings` to a fresh coordinator, with a
/// worker when `worker`; `then` may act on the job once submitted (its id, if one was made).
fn submit_case(
    bins: &Bins,
    dir: &Path,
    (case, class): (&'static str, &'static str),
    (name, scene, assets): (&str, Vec<u8>, Vec<(String, Vec<u8>)>),
    settings: serde_json::Value,
    worker: bool,
    wanted: impl Fn(u16, &serde_json::Value) -> bool,
) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let mut w = worker.then(|| bins.worker(&c, dir));
    let ((status, body), seconds) = timed(|| rest::try_submit(&c.url, (name, scene), assets, settings));
    let passed = wanted(status, &body);
    // a worker that leases a hostile job fails within seconds, if it fails
    if let (Some(w), true) = (&mut w, status == 201) {
        settle(&mut w.child, Duration::from_secs(8));
    }
    Report {
        case,
        class,
        answer: answer(status, &body),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(200)),
        worker: w.as_mut().map(|w| peak(&mut w.child)),
        passed,
    }
}

/// Refused with 400 and a message holding `needle`.
fn refused(needle: &'static str) -> impl Fn(u16, &serde_json::Value) -> bool {
    move |status, body| status == 400 && body["error"].as_str().is_some_and(|e| e.contains(needle))
}

fn pt() -> serde_json::Value {
    json!({"integrator": "pt", "spp": 1})
}

fn nested(bins: &Bins, dir: &Path) -> Report {
    let scene = ("scene.xml", inputs::nested(600), vec![]);
    submit_case(
        bins,
        dir,
        ("nested-elements", "one request stops the coordinator"),
        scene,
        pt(),
        false,
        refused("nest more than"),
    )
}

fn light_paths(bins: &Bins, dir: &Path) -> Report {
    let settings = json!({"integrator": "lt", "spp": 1, "light_paths_per_pixel": 1e6});
    let scene = ("scene.xml", inputs::scene(""), vec![]);
    let case = ("light-paths-1e6", "one job stops every worker");
    submit_case(bins, dir, case, scene, settings, true, refused("light_paths_per_pixel"))
}

fn ref_bomb(bins: &Bins, dir: &Path) -> Report {
    let scene = ("scene.xml", inputs::ref_bomb(1000), vec![]);
    submit_case(bins, dir, ("ref-bomb", "memory out of proportion"), scene, pt(), false, refused("references expand"))
}

/// 20 shapes naming one 1.4 MB mesh: accepted and rendered within bounded memory.
fn shared_mesh(bins: &Bins, dir: &Path) -> Report {
    let body: String = (0..20).map(|_| inputs::mesh_shape("ply", "grid.ply")).collect();
    let scene = ("scene.xml", inputs::scene(&body), vec![("grid.ply".to_string(), inputs::ply_grid(200))]);
    let case = ("mesh-20-shapes", "memory out of proportion");
    submit_case(bins, dir, case, scene, pt(), true, |status, _| status == 201)
}

fn serialized_bomb(bins: &Bins, dir: &Path) -> Report {
    let file = inputs::serialized_bomb(4_000_000);
    let scene = (
        "scene.xml",
        inputs::scene(&inputs::mesh_shape("serialized", "m.serialized")),
        vec![("m.serialized".into(), file)],
    );
    submit_case(bins, dir, ("serialized-bomb", "memory out of proportion"), scene, pt(), false, refused("inflate"))
}

/// A 4 MB PLY of one-byte records: accepted, in memory proportional to it.
fn ply_records(bins: &Bins, dir: &Path) -> Report {
    let file = inputs::ply_one_byte_records(4 << 20);
    let scene = ("scene.xml", inputs::scene(&inputs::mesh_shape("ply", "m.ply")), vec![("m.ply".into(), file)]);
    let case = ("ply-one-byte-records", "memory out of proportion");
    submit_case(bins, dir, case, scene, pt(), false, |status, _| status == 201)
}

fn flat_exr(bins: &Bins, dir: &Path) -> Report {
    let scene =
        ("scene.xml", inputs::scene(&inputs::textured("flat.exr")), vec![("flat.exr".into(), inputs::flat_exr(8192))]);
    submit_case(bins, dir, ("exr-flat-8192", "memory out of proportion"), scene, pt(), false, refused("times the file"))
}

/// Three concurrent submissions of a tiny PNG claiming 16384² pixels.
fn png_claims(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let url = c.url.clone();
    let (answers, seconds) = timed(|| {
        let threads: Vec<_> = (0..3)
            .map(|_| {
                let url = url.clone();
                std::thread::spawn(move || {
                    let scene = ("scene.xml", inputs::scene(&inputs::textured("big.png")));
                    rest::try_submit(&url, scene, vec![("big.png".into(), inputs::png_claiming(16384))], pt())
                })
            })
            .collect();
        threads.into_iter().map(|t| t.join().expect("submit thread")).collect::<Vec<_>>()
    });
    let passed = answers.iter().all(|(s, b)| refused("claims")(*s, b));
    Report {
        case: "png-claims-16384-x3",
        class: "memory out of proportion",
        answer: answer(answers[0].0, &answers[0].1),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(200)),
        worker: None,
        passed,
    }
}

/// A scene 1000 bytes deep in its bundle with 20 000 elements: every node's location used to
/// hold the whole path.
fn long_path(bins: &Bins, dir: &Path) -> Report {
    let folder = "d".repeat(99) + "/";
    let path = folder.repeat(9) + "scene.xml";
    let body = "<shape type=\"sphere\"><float name=\"radius\" value=\"0.001\"/></shape>\n".repeat(20_000);
    let scene = (path.as_str(), inputs::scene(&body), vec![]);
    submit_case(bins, dir, ("long-bundle-path", "memory out of proportion"), scene, pt(), false, |s, _| s == 201)
}

fn many_elements(bins: &Bins, dir: &Path) -> Report {
    let scene = ("scene.xml", inputs::many_elements(50_000), vec![]);
    let line = HEAD.lines().count() + 50_000;
    let case = ("50k-elements", "CPU out of proportion");
    let report = submit_case(bins, dir, case, scene, pt(), false, move |s, b| {
        s == 400 && b["error"].as_str().is_some_and(|e| e.contains(&format!("scene.xml:{line}:")))
    });
    Report { passed: report.passed && report.seconds < 10.0, ..report }
}

fn many_paths(bins: &Bins, dir: &Path) -> Report {
    let scene = ("scene.xml", inputs::many_paths(4000), vec![]);
    let report = submit_case(bins, dir, ("4000-paths", "CPU out of proportion"), scene, pt(), false, refused("<path>"));
    Report { passed: report.passed && report.seconds < 10.0, ..report }
}

/// 100 000 one-byte parts: refused after the limit, leaving no file behind. The body is made
/// by hand and sent by curl (a client library's form of 100 000 parts is slow itself).
fn many_parts(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let body = inputs::multipart(100_000);
    let ((status, body), seconds) = timed(|| raw_post(&format!("{}/api/v1/jobs", c.url), &body, dir));
    let leftover = walk_count(&dir.join("data/scenes"));
    let passed = status == 400 && leftover == 0 && seconds < 30.0;
    Report {
        case: "100k-parts",
        class: "CPU out of proportion",
        answer: format!("{}; {leftover} files left", answer(status, &body)),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(200)),
        worker: None,
        passed,
    }
}

/// POSTs a multipart `body` (boundary [`inputs::BOUNDARY`]) with curl, which reads the answer
/// while it sends; returns the status and JSON answer (status 0 if none came in two minutes).
fn raw_post(url: &str, body: &[u8], dir: &Path) -> (u16, serde_json::Value) {
    let file = dir.join("body");
    let out = dir.join("answer");
    if std::fs::write(&file, body).is_err() {
        return (0, json!(null));
    }
    let status = std::process::Command::new("curl")
        .args(["-s", "--max-time", "120", "-w", "%{http_code}", "-o"])
        .arg(&out)
        .arg("-H")
        .arg(format!("content-type: multipart/form-data; boundary={}", inputs::BOUNDARY))
        .arg("--data-binary")
        .arg(format!("@{}", file.display()))
        .arg(url)
        .output()
        .ok()
        .and_then(|o| String::from_utf8_lossy(&o.stdout).trim().parse().ok())
        .unwrap_or(0);
    let answer = std::fs::read(&out).ok().and_then(|b| serde_json::from_slice(&b).ok());
    (status, answer.unwrap_or(json!(null)))
}

/// Files under `dir`, at any depth.
fn walk_count(dir: &Path) -> usize {
    std::fs::read_dir(dir).map_or(0, |entries| {
        entries.flatten().map(|e| if e.file_type().is_ok_and(|t| t.is_dir()) { walk_count(&e.path()) } else { 1 }).sum()
    })
}

/// A bitmap named `.`: the error must name the user's file, not the coordinator's folder.
fn bitmap_dot(bins: &Bins, dir: &Path) -> Report {
    let scene = ("scene.xml", inputs::scene(&inputs::textured(".")), vec![]);
    let data = dir.join("data").canonicalize().unwrap_or_else(|_| dir.join("data"));
    let hidden = [dir.display().to_string(), data.display().to_string()];
    submit_case(bins, dir, ("bitmap-named-dot", "errors show server paths"), scene, pt(), false, move |s, b| {
        let e = b["error"].as_str().unwrap_or("");
        s == 400 && hidden.iter().all(|h| !e.contains(h.as_str())) && e.contains("scene.xml")
    })
}

/// An `lt` job of a 10⁸ s budget with a worker: the coordinator must plan its passes in
/// bounded memory and keep answering; the job is cancelled at the end.
fn time_budget(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let mut w = bins.worker(&c, dir);
    let settings = json!({"integrator": "lt", "time_s": 1e8});
    let ((status, body), _) = timed(|| rest::try_submit(&c.url, ("scene.xml", inputs::scene("")), vec![], settings));
    let id = body["id"].as_str().unwrap_or("").to_string();
    // a few passes: the first one measures the pace, the second is planned from it
    let (state, seconds) = timed(|| {
        let deadline = std::time::Instant::now() + Duration::from_secs(15);
        let mut last = (0, serde_json::Value::Null);
        while std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(500));
            last = rest::try_get_json(&format!("{}/api/v1/jobs/{id}", c.url));
            if last.0 != 200 || last.1["tiles_done"].as_u64().unwrap_or(0) > 4 {
                break;
            }
        }
        last
    });
    let (code, job) = &state;
    let running = *code == 200 && matches!(job["state"].as_str(), Some("queued" | "pilot" | "final" | "running"));
    let tiles = job["tiles_total"].as_u64().unwrap_or(0);
    let (cancelled, _) = rest::try_post(&format!("{}/api/v1/jobs/{id}/cancel", c.url));
    Report {
        case: "time-budget-1e8",
        class: "one request stops the coordinator",
        answer: format!(
            "{status}; then {code} {} with {tiles} tiles planned; cancel {cancelled}",
            job["state"].as_str().unwrap_or("-")
        ),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(200)),
        worker: Some(peak(&mut w.child)),
        passed: status == 201 && running && cancelled == 200 && tiles < 100_000,
    }
    .with_time_limit(PATIENCE)
}

impl Report {
    /// Fails the case when it took longer than `limit`.
    fn with_time_limit(self, limit: Duration) -> Report {
        let passed = self.passed && self.seconds < limit.as_secs_f64();
        Report { passed, ..self }
    }
}
