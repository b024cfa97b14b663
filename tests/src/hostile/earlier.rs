//! The cases of issue 19 (decision 0015's first version), kept in the suite so that they stay
//! refused: files outside the bundle, a huge film, parameters that expand geometrically, a
//! million nodes, billions of planned tiles, a page of another origin.

use super::inputs::{self, HEAD};
use super::procs::{Bins, settle};
use super::{Case, Report, answer, timed};
use crate::rest;
use serde_json::json;
use std::path::Path;
use std::time::Duration;

const CLASS: &str = "earlier (issue 19)";

pub(super) fn all() -> Vec<Case> {
    vec![
        Case {
            name: "mesh-dev-zero",
            class: CLASS,
            run: |b, d| {
                one(
                    b,
                    d,
                    "mesh-dev-zero",
                    &inputs::scene(&inputs::mesh_shape("obj", "/dev/zero")),
                    pt(),
                    "absolute path",
                )
            },
        },
        Case {
            name: "mesh-outside",
            class: CLASS,
            run: |b, d| {
                one(
                    b,
                    d,
                    "mesh-outside",
                    &inputs::scene(&inputs::mesh_shape("ply", "../../../etc/passwd")),
                    pt(),
                    "outside",
                )
            },
        },
        Case { name: "film-65535", class: CLASS, run: film },
        Case { name: "chained-defaults", class: CLASS, run: chained },
        Case { name: "million-nodes", class: CLASS, run: nodes },
        Case {
            name: "vcm-4e9-spp",
            class: CLASS,
            run: |b, d| {
                one(
                    b,
                    d,
                    "vcm-4e9-spp",
                    &inputs::scene(""),
                    json!({"integrator": "vcm", "spp": 4_000_000_000u64}),
                    "tiles",
                )
            },
        },
        Case { name: "cross-origin-form", class: CLASS, run: cross_origin },
    ]
}

fn pt() -> serde_json::Value {
    json!({"integrator": "pt", "spp": 1})
}

/// One submission of `scene` with `settings`, wanted refused with `needle` in its message.
fn one(bins: &Bins, dir: &Path, case: &'static str, scene: &[u8], settings: serde_json::Value, needle: &str) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let ((status, body), seconds) = timed(|| rest::try_submit(&c.url, ("scene.xml", scene.to_vec()), vec![], settings));
    let passed = status == 400 && body["error"].as_str().is_some_and(|e| e.contains(needle));
    Report {
        case,
        class: CLASS,
        answer: answer(status, &body),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed,
    }
}

fn film(bins: &Bins, dir: &Path) -> Report {
    let scene = String::from_utf8_lossy(&inputs::scene("")).replace("value=\"64\"", "value=\"65535\"");
    one(bins, dir, "film-65535", scene.as_bytes(), pt(), "--max-pixels")
}

/// Ten `<default>`s, each repeating the previous one ten times: 10¹⁰ bytes.
fn chained(bins: &Bins, dir: &Path) -> Report {
    let mut defaults = String::from("<default name=\"p0\" value=\"xxxxxxxxxx\"/>\n");
    for i in 1..10 {
        defaults += &format!("<default name=\"p{i}\" value=\"{}\"/>\n", format!("$p{}", i - 1).repeat(10));
    }
    let scene = format!(
        "{}<shape type=\"sphere\" id=\"$p9\"/>\n</scene>\n",
        HEAD.replacen("<sensor", &format!("{defaults}<sensor"), 1)
    );
    one(bins, dir, "chained-defaults", scene.as_bytes(), pt(), "grows past")
}

/// 16 MB of XML: a million and one elements.
fn nodes(bins: &Bins, dir: &Path) -> Report {
    let scene = inputs::scene(&"<a/>".repeat(1_000_001));
    one(bins, dir, "million-nodes", &scene, pt(), "XML nodes")
}

/// A page on another origin posting a form.
fn cross_origin(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let headers = [("origin", "http://evil.example")];
    let extra = rest::Extra { headers: &headers, ca_pem: None };
    let ((status, body), seconds) =
        timed(|| rest::try_submit_with(&c.url, extra, ("scene.xml", inputs::scene("")), vec![], pt()));
    Report {
        case: "cross-origin-form",
        class: CLASS,
        answer: answer(status, &body),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed: status == 403,
    }
}
