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

#[test]
fn bad_scene_gives_one_line_and_exit_code_one() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.xml");
    std::fs::write(&bad, "<scene version=\"3.0.0\">\n  <shape type=\"teapot\"/>\n</scene>\n").unwrap();
    let run = tessera().args(["render"]).arg(&bad).output().unwrap();
    assert_eq!(run.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(stderr.trim_end().lines().count(), 1, "{stderr}");
    assert!(stderr.starts_with("error: ") && stderr.contains("bad.xml:2:3") && stderr.contains("teapot"), "{stderr}");
}

#[test]
fn bad_arguments_fail_cleanly() {
    let run = tessera().args(["render"]).arg(scene("cornell-box")).args(["--spp", "0"]).output().unwrap();
    assert_eq!(run.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&run.stderr).contains("--spp must be at least 1"));
    let run = tessera().args(["render", "/nonexistent/scene.xml"]).output().unwrap();
    assert_eq!(run.status.code(), Some(1));
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
