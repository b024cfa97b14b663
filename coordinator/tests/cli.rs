//! Runs the real `tessera` binary: a render writes an EXR and a PNG, bad input gives a one-line
//! error and a non-zero exit.

use std::path::{Path, PathBuf};
use std::process::Command;

fn tessera() -> Command {
    Command::new(env!("CARGO_BIN_EXE_tessera"))
}

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name).join("scene.xml")
}

#[test]
fn render_writes_exr_and_png_with_the_requested_samples() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("box.exr");
    let run = tessera()
        .args(["render"])
        .arg(scene("cornell-box"))
        .args(["--spp", "2", "--seed", "3", "--threads", "2", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("2 spp") && stdout.contains("samples/s"), "{stdout}");
    let img = tessera_common::film::exr::read_rgb(&out).unwrap();
    assert_eq!((img.width, img.height), (256, 256));
    let counts = tessera_common::film::exr::read_sample_counts(&out).unwrap();
    assert!(counts.iter().all(|&c| c == 2));
    assert!(dir.path().join("box.png").exists());
}

/// `-o NAME.png` names the preview: the EXR goes beside it as NAME.exr (it was written to
/// NAME.png and then overwritten by the PNG).
#[test]
fn a_png_output_name_keeps_the_exr_beside_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = tessera()
        .args(["render"])
        .arg(scene("cornell-box"))
        .args(["--spp", "1", "-o"])
        .arg(dir.path().join("shot.png"))
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let img = tessera_common::film::exr::read_rgb(&dir.path().join("shot.exr")).unwrap();
    assert_eq!((img.width, img.height), (256, 256));
    let png = std::fs::read(dir.path().join("shot.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
}

#[test]
fn default_output_is_named_after_the_scene_folder() {
    let dir = tempfile::tempdir().unwrap();
    let run = tessera()
        .current_dir(dir.path())
        .args(["render"])
        .arg(scene("veach-mis"))
        .args(["--spp", "1"])
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    assert!(dir.path().join("veach-mis.exr").exists() && dir.path().join("veach-mis.png").exists());
}

/// Invalid input exits with 2 (`cli/exit.rs`).
#[test]
fn bad_scene_gives_one_line_and_exit_code_two() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.xml");
    std::fs::write(&bad, "<scene version=\"3.0.0\">\n  <shape type=\"teapot\"/>\n</scene>\n").unwrap();
    let run = tessera().args(["render"]).arg(&bad).output().unwrap();
    assert_eq!(run.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(stderr.starts_with("error: ") && stderr.contains("bad.xml:2:3") && stderr.contains("teapot"), "{stderr}");
}

#[test]
fn bad_arguments_fail_cleanly() {
    let run = tessera().args(["render"]).arg(scene("cornell-box")).args(["--spp", "0"]).output().unwrap();
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("--spp must be at least 1"));
    let run = tessera().args(["render", "/nonexistent/scene.xml"]).output().unwrap();
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("/nonexistent/scene.xml"));
    let run =
        tessera().args(["render"]).arg(scene("cornell-box")).args(["--spp", "1", "--time", "1"]).output().unwrap();
    assert!(!run.status.success(), "--spp and --time exclude each other");
}

#[test]
fn time_budget_renders_at_least_one_pass() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.exr");
    let run = tessera()
        .args(["render"])
        .arg(scene("glossy-interreflection"))
        .args(["--time", "0.5", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let counts = tessera_common::film::exr::read_sample_counts(&out).unwrap();
    assert!(counts[0] >= 1 && counts.iter().all(|&c| c == counts[0]), "every pixel has the same sample count");
}

/// `emis-vcm` (the default path-tracing start) writes the image, the EMIS layers and
/// attributes, the strategy map and a report
/// whose updates happened at the configured iterations. (A sample budget, not a time budget:
/// how many iterations fit in a time depends on the machine's load.)
#[test]
fn emis_vcm_writes_its_layers_strategy_map_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("glass.exr");
    let run = tessera()
        .args(["render"])
        .arg(scene("caustic-glass"))
        .args(["--integrator", "emis-vcm", "--spp", "3", "--emis-updates", "1,2", "--threads", "2", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let mask = tessera_common::film::exr::read_layer(&out, "merge_mask").unwrap();
    assert_eq!(mask.len(), 256 * 256);
    assert!(mask.iter().all(|&v| (0.0..=1.0).contains(&v)));
    let relative = tessera_common::film::exr::read_layer(&out, "relative_moment").unwrap();
    assert!(relative.iter().all(|v| !v.is_nan()));
    let nu = tessera_common::film::exr::read_attribute(&out, "tessera/emis_nu").unwrap().expect("ν attribute");
    assert!([0.0, 0.25, 0.5, 0.75, 1.0, 2.0].contains(&(nu as f32)), "ν = {nu}");
    assert!(tessera_common::film::exr::read_attribute(&out, "tessera/emis_connections").unwrap().is_some());
    assert!(dir.path().join("glass.strategy.png").exists() && dir.path().join("glass.png").exists());
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("glass.emis.json")).unwrap()).unwrap();
    let updates = report["updates"].as_array().unwrap();
    assert_eq!(updates.iter().map(|u| u["iteration"].as_u64().unwrap()).collect::<Vec<_>>(), vec![1, 2]);
    // the default path-tracing start decides from the reduced set (ν ∈ {0.5, 1} × c ∈ {0, 1}
    // × merging on or off, and path tracing) until light paths win, then from the full set
    // (25 (ν, c) pairs and path tracing)
    assert_eq!(updates[0]["reduced"].as_bool(), Some(true));
    for u in updates {
        let expected = if u["reduced"].as_bool().unwrap() { 9 } else { 26 };
        assert_eq!(u["candidates"].as_array().unwrap().len(), expected, "{u}");
    }
    assert_eq!(report["final"]["nu"].as_f64().unwrap() as f32, nu as f32);
}

/// `tessera serve` settings: flag > `TESSERA_*` variable > `--config` file > default, as
/// `--print-config` shows them, tokens redacted; the variables are set on the child only.
#[test]
fn serve_settings_come_from_flags_then_variables_then_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("serve.toml");
    std::fs::write(
        &file,
        "listen = \"127.0.0.1:9001\"\nlease-timeout = 5\nmax-job-tiles = 77\nclient-token = \"file-secret\"\nlog-format = \"json\"\n",
    )
    .unwrap();
    let run = tessera()
        .args(["serve", "--print-config", "--config"])
        .arg(&file)
        .args(["--listen", "127.0.0.1:9003"])
        .env("TESSERA_LISTEN", "127.0.0.1:9002")
        .env("TESSERA_LEASE_TIMEOUT", "9")
        .env("TESSERA_WORKER_TOKEN", "env-secret")
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let text = String::from_utf8_lossy(&run.stdout);
    for line in [
        "listen = \"127.0.0.1:9003\"  # flag",
        "lease-timeout = 9.0  # env TESSERA_LEASE_TIMEOUT",
        "max-job-tiles = 77  # file, line 3",
        "worker-token = \"<redacted>\"  # env TESSERA_WORKER_TOKEN",
        "client-token = \"<redacted>\"  # file, line 4",
        "log-format = \"json\"  # file, line 5",
        "data-dir = \"tessera-data\"  # default",
    ] {
        assert!(text.lines().any(|l| l == line), "no {line:?} in\n{text}");
    }
    assert!(!text.contains("secret"), "a token is shown:\n{text}");
    // an unknown key is an error naming the key, the file and the line
    std::fs::write(&file, "listen = \"127.0.0.1:0\"\nworker_token = \"x\"\n").unwrap();
    let run = tessera().args(["serve", "--config"]).arg(&file).output().unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "{err}");
    assert!(err.contains("serve.toml, line 2: unknown key `worker_token` (did you mean `worker-token`?"), "{err}");
}
