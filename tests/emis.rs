//! EMIS jobs on the farm. Four equal `tessera render` bit for bit: the bidirectional pilot
//! with its per-pixel merge mask, a path-tracing start that a restart sets aside, one that keeps
//! path tracing to the end, and per-pixel connection counts; the decisions, strategy PNG and
//! report survive a coordinator restart. A fifth measures costs per job on the workers.

use super::{download, job_url, wait_done};
use serde_json::json;
use std::time::Duration;
use tessera_tests::{
    Coordinator, assert_same_emis_outputs, assert_same_image, farm, local_render_with, rest, scene, wait_for,
};

/// EMIS on the farm: a pilot pass, updates after iterations 1 and 4 run by the coordinator on
/// the merged moments, final passes with the chosen strategy (its merge mask fetched by the
/// workers as a blob) — and the same image, bit for bit, the same decisions, strategy PNG and
/// report as locally. After a coordinator restart the job shows the same decisions (read back
/// from its stored report) and serves the same files. The bidirectional pilot, whose update
/// chooses a per-pixel merge mask.
#[test]
fn rest_submit_emis_vcm_equals_local_render_with_the_same_decisions() {
    use tessera_common::film::exr::{read_attribute, read_layer};
    let dir = tempfile::tempdir().unwrap();
    let (mut c, _w) = farm(dir.path(), 2);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    // updates after 1 and 4: the first keeps the pilot's ν 1, c 1 (path tracing is cheaper but
    // not better by the margin, decision 0046), so iterations 2 to 4 are one pilot call; the
    // second picks path tracing, whose 10 final iterations are two calls (8 + 2) on both sides
    let settings = json!({"integrator": "emis-vcm", "spp": 14, "seed": 4, "emis_pilot": "bidirectional"});
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    assert_eq!((job["state"].as_str(), job["tiles_total"].as_u64()), (Some("queued"), Some(1)), "the pilot: {job}");
    let id = job["id"].as_str().unwrap();
    let done = wait_done(&c, id, None);
    assert_eq!(done["tiles_total"], 4, "{done}");
    let updates = done["strategy"]["updates"].as_array().expect("EMIS decisions in the status");
    assert_eq!(updates.iter().map(|u| u["iteration"].as_u64().unwrap()).collect::<Vec<_>>(), [1, 4]);
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, id)), None, &out);
    let own = ["--emis-pilot", "bidirectional"];
    let local = local_render_with(dir.path(), &scene("cornell-box"), "emis-vcm", 14, 4, &own);
    assert_same_image(&out, &local);
    let (farm_mask, local_mask) = (read_layer(&out, "merge_mask").unwrap(), read_layer(&local, "merge_mask").unwrap());
    assert!(farm_mask.iter().zip(&local_mask).all(|(a, b)| a.to_bits() == b.to_bits()), "same merge mask");
    for key in ["tessera/emis_nu", "tessera/emis_connections", "tessera/emis_updates"] {
        assert_eq!(read_attribute(&out, key).unwrap(), read_attribute(&local, key).unwrap(), "{key}");
    }
    assert_eq!(read_attribute(&out, "tessera/emis_updates").unwrap(), Some(2.0));
    let files = ["strategy.png", "emis.json"].map(|name| {
        let (status, bytes) = rest::get(&format!("{}/{name}", job_url(&c, id)), None);
        assert_eq!(status, 200, "{name}: {}", String::from_utf8_lossy(&bytes));
        std::fs::write(out.with_extension(name), &bytes).unwrap();
        bytes
    });
    assert_same_emis_outputs(&out, &local);
    c.kill();
    let listen = format!("127.0.0.1:{}", c.port());
    let c = wait_for(Duration::from_secs(20), "port to be free", || {
        std::net::TcpListener::bind(&listen).ok().map(drop)?;
        Some(Coordinator::start(&dir.path().join("data"), &listen, &[]))
    });
    let (status, after) = rest::get_json(&job_url(&c, id), None);
    assert_eq!((status, after["state"].as_str()), (200, Some("done")), "{after}");
    assert_eq!(after["strategy"], done["strategy"], "the decisions after the restart");
    for (name, bytes) in ["strategy.png", "emis.json"].iter().zip(&files) {
        assert!(rest::get(&format!("{}/{name}", job_url(&c, id)), None) == (200, bytes.clone()), "{name}");
    }
}

/// The path-tracing start on the farm. On caustic-glass (seed 4) the updates after 1 and 2
/// keep path tracing (pt passes: iterations 1 and 3 return no moments), the one after 4 picks a
/// bidirectional strategy: the coordinator sets its film aside in the EMIS state and renders
/// the budget's 6 iterations, 4..10, into a new one; the update after 8 weighs the start, which
/// rejoins the image. The image, its sample counts, the start's weight and the decisions equal
/// a local render's, bit for bit. The start's updates use the guided Ī: with the pilot image
/// alone path tracing stays there at every seed (decisions 0028 and 0029).
#[test]
fn rest_submit_emis_with_a_path_tracing_start_sets_it_aside_like_a_local_render() {
    use tessera_common::film::exr::{read_attribute, read_sample_counts};
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 2);
    let xml = std::fs::read(scene("caustic-glass")).unwrap();
    let gem = std::fs::read(scene("caustic-glass").with_file_name("gem.obj")).unwrap();
    let settings = json!({
        "integrator": "emis-vcm", "spp": 6, "seed": 4,
        "emis_pilot": "path-tracing", "emis_updates": [1, 2, 4, 8],
    });
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![("gem.obj".into(), gem)], settings);
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    let done = wait_done(&c, id, None);
    let updates = done["strategy"]["updates"].as_array().expect("EMIS decisions in the status");
    let summary: Vec<_> = updates
        .iter()
        .map(|u| (u["iteration"].as_u64().unwrap(), u["reduced"].as_bool().unwrap(), u["restarted"].as_bool().unwrap()))
        .collect();
    assert_eq!(summary, [(1, true, false), (2, true, false), (4, true, true), (8, false, false)], "{updates:?}");
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, id)), None, &out);
    let more = ["--emis-pilot", "path-tracing", "--emis-updates", "1,2,4,8"];
    let local = local_render_with(dir.path(), &scene("caustic-glass"), "emis-vcm", 6, 4, &more);
    assert_same_image(&out, &local);
    assert!(read_sample_counts(&out).unwrap().iter().all(|&n| n == 6), "the counts of the new film");
    assert_eq!(read_attribute(&out, "tessera/emis_kept_from").unwrap(), Some(4.0));
    let weight = read_attribute(&out, "tessera/emis_start_weight").unwrap();
    assert!(weight.is_some_and(|k| k > 0.0), "the update after 8 weighs the start: {weight:?}");
    for key in [
        "tessera/emis_nu",
        "tessera/emis_connections",
        "tessera/emis_updates",
        "tessera/emis_kept_from",
        "tessera/emis_start_weight",
    ] {
        assert_eq!(read_attribute(&out, key).unwrap(), read_attribute(&local, key).unwrap(), "{key}");
    }
}

/// Per-pixel connection counts on the farm: after the update at iteration 1 a bidirectional
/// strategy renders with an expected count per pixel, which the workers fetch as a blob and
/// round at each camera vertex as a local render does: the same image bit for bit, the same
/// connection layer and report. The bidirectional pilot, whose first update already chooses
/// from the full set.
#[test]
fn rest_submit_emis_with_per_pixel_connections_equals_local_render() {
    use tessera_common::film::exr::{read_attribute, read_layer};
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 2);
    let xml = std::fs::read(scene("indirect-room")).unwrap();
    let settings = json!({
        "integrator": "emis-bdpt", "spp": 12, "seed": 3, "emis_updates": [1, 4],
        "emis_connections": "per-pixel", "emis_pilot": "bidirectional",
    });
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    let done = wait_done(&c, id, None);
    let strategy = &done["strategy"];
    assert!(strategy["nu"].as_f64().unwrap() > 0.0, "a bidirectional strategy: {strategy}");
    assert!(strategy["mean_connections"].as_f64().is_some(), "per-pixel connections: {strategy}");
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, id)), None, &out);
    for name in ["strategy.png", "emis.json"] {
        let (status, bytes) = rest::get(&format!("{}/{name}", job_url(&c, id)), None);
        assert_eq!(status, 200, "{name}: {}", String::from_utf8_lossy(&bytes));
        std::fs::write(out.with_extension(name), &bytes).unwrap();
    }
    let more = ["--emis-updates", "1,4", "--emis-experiment", "connections=per-pixel", "--emis-pilot", "bidirectional"];
    let local = local_render_with(dir.path(), &scene("indirect-room"), "emis-bdpt", 12, 3, &more);
    assert_same_image(&out, &local);
    let (farm_c, local_c) = (read_layer(&out, "connections").unwrap(), read_layer(&local, "connections").unwrap());
    assert!(farm_c.iter().zip(&local_c).all(|(a, b)| a.to_bits() == b.to_bits()), "same connection mask");
    assert!(farm_c.iter().any(|&c| c > 0.0), "connections somewhere");
    let key = "tessera/emis_mean_connections";
    assert_eq!(read_attribute(&out, key).unwrap(), read_attribute(&local, key).unwrap());
    assert_same_emis_outputs(&out, &local);
}

/// Path tracing kept to the end on the farm: it wins the updates at 1 and 4 clearly and
/// settles at 4 (no update at 16, no more recordings); the 196 iterations left are cut into
/// calls of a sixteenth of what is left (12, 12, ... then 8s), as `tessera render` cuts
/// them, and the image is the same bit for bit.
#[test]
fn rest_submit_emis_keeping_path_tracing_renders_the_local_calls() {
    use tessera_common::film::exr::read_attribute;
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 2);
    let xml = std::fs::read(scene("glossy-interreflection")).unwrap();
    let settings = json!({"integrator": "emis-vcm", "spp": 200, "seed": 5, "emis_updates": [1, 4, 16]});
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    let done = wait_done(&c, id, None);
    let updates = done["strategy"]["updates"].as_array().expect("EMIS decisions in the status");
    assert!(updates.iter().all(|u| u["restarted"] == false), "path tracing kept: {updates:?}");
    let settled: Vec<_> = updates.iter().map(|u| (u["iteration"].as_u64(), u["settled"] == true)).collect();
    assert_eq!(settled, [(Some(1), false), (Some(4), true)], "settled at 4: {updates:?}");
    assert_eq!(done["strategy"]["nu"].as_f64(), Some(0.0), "{}", done["strategy"]);
    let calls = tessera_common::emis::calls(4..200, |r| tessera_common::emis::final_call(r, 0.0, 256 * 256));
    assert_eq!(calls[0], 4..16);
    // the pilot, the collecting calls 1..2, 2..3 (a recording) and 3..4, then the final calls
    assert_eq!(done["tiles_total"].as_u64(), Some(4 + calls.len() as u64), "{done}");
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, id)), None, &out);
    let more = ["--emis-updates", "1,4,16"];
    let local = local_render_with(dir.path(), &scene("glossy-interreflection"), "emis-vcm", 200, 5, &more);
    assert_same_image(&out, &local);
    assert_eq!(read_attribute(&out, "tessera/emis_nu").unwrap(), Some(0.0));
}

/// Costs measured per job on the farm: the bidirectional pilot's first call, rendered by a
/// worker, times its light vertices, connections and path tracing beside it, and the
/// coordinator's first update fits the constants from those times. The report shows constants
/// measured there, not the calibrated ones (the image is not compared with a local render:
/// timed decisions depend on the machine). A path-tracing start would measure path tracing
/// only: its probe's light paths are neither splatted nor timed.
#[test]
fn rest_submit_emis_with_measured_costs_reports_the_workers_constants() {
    use tessera_common::emis::cost::CostConstants;
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 2);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let settings = json!({"integrator": "emis-vcm", "spp": 6, "seed": 2, "cost_model": "measured",
        "emis_pilot": "bidirectional"});
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    wait_done(&c, id, None);
    let (status, report) = rest::get_json(&format!("{}/emis.json", job_url(&c, id)), None);
    assert_eq!(status, 200, "{report}");
    let first = &report["updates"][0];
    assert_eq!(first["iteration"].as_u64(), Some(1), "{report}");
    let k = &first["measured_constants"];
    let calibrated = CostConstants::calibrated();
    assert_eq!(k["camera_vertex"].as_f64(), Some(1.0), "measured in camera vertices: {k}");
    let pt = k["path_tracing"].as_f64().expect("path tracing timed by the worker");
    assert!(pt > 0.05 && pt < 5.0 && pt != calibrated.path_tracing, "path tracing {pt}: {k}");
    let light = k["light_vertex"].as_f64().expect("light vertices timed by the worker");
    assert!(light > 0.0 && light != calibrated.light_vertex, "light vertex {light}: {k}");
    let connection = k["connection"].as_f64().expect("connections timed by the worker");
    assert!(connection > 0.0 && connection != calibrated.connection, "connection {connection}: {k}");
}
