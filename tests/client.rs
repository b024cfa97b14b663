//! The `tessera` client on a real farm: re-attaching to a job by a prefix of its id after the
//! submitting command died, listing by state, and the exit codes scripts tell failures by.

use super::*;
use std::io::BufRead;
use std::process::{Command, Stdio};
use tessera_tests::bin;

fn code(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(bin("tessera")).args(args).output().unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// `submit --wait` is killed once the job is in; `wait PREFIX` re-attaches and writes the
/// image, `download PREFIX` writes it again, and both equal a local render.
#[test]
fn wait_and_download_by_prefix_after_the_submitting_client_died() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _workers) = farm(dir.path(), 1);
    let cornell = scene("cornell-box");
    let mut submit = Command::new(bin("tessera"))
        .args(["submit", cornell.to_str().unwrap(), "--server", &c.url, "--integrator", "pt"])
        .args(["--spp", "16", "--seed", "9", "--wait", "-o", "/nonexistent/never.exr"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut id = String::new();
    std::io::BufReader::new(submit.stdout.take().unwrap()).read_line(&mut id).unwrap();
    submit.kill().unwrap();
    submit.wait().unwrap();
    let prefix = &id.trim()[..8];
    let out = dir.path().join("waited.exr");
    let (ok, _, err) = tessera(&["wait", prefix, "--server", &c.url, "-o", out.to_str().unwrap()]);
    assert!(ok, "{err}");
    let local = local_render(dir.path(), &cornell, "pt", 16, 9);
    assert_same_image(&out, &local);
    let again = dir.path().join("again.png");
    let (ok, _, err) = tessera(&["download", prefix, "--server", &c.url, "-o", again.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert_same_image(&dir.path().join("again.exr"), &local);
    assert!(again.exists());
}

/// Not found 3, invalid input 2, unauthorised 4, unreachable 5, a cancelled job 6; `list
/// --state` shows the jobs of that state only.
#[test]
fn client_failures_have_distinct_exit_codes() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--client-token", "client-secret-0123", "--worker-token", "worker-secret-0123"],
    );
    let server = ["--server", c.url.as_str(), "--token", "client-secret-0123"];
    fn with<'a>(args: &[&'a str], server: &[&'a str]) -> Vec<&'a str> {
        [args, server].concat()
    }
    assert_eq!(code(&with(&["status", "no-such-job"], &server)).0, Some(3));
    assert_eq!(code(&with(&["list", "--state", "sleeping"], &server)).0, Some(2));
    assert_eq!(code(&["list", "--server", &c.url, "--token", "wrong"]).0, Some(4));
    assert_eq!(code(&["list", "--server", "http://127.0.0.1:1"]).0, Some(5));
    let cornell = scene("cornell-box");
    let (ok, id, err) = tessera(&with(&["submit", cornell.to_str().unwrap(), "--spp", "1"], &server));
    assert!(ok, "{err}");
    let id = id.trim();
    assert!(tessera(&with(&["cancel", id], &server)).0);
    let (exit, err) = code(&with(&["wait", id], &server));
    assert_eq!(exit, Some(6), "{err}");
    assert!(err.contains("cancelled"), "{err}");
    let (_, listed, _) = tessera(&with(&["list", "--state", "cancelled"], &server));
    assert!(listed.contains(id), "{listed}");
    let (_, listed, _) = tessera(&with(&["list", "--state", "done"], &server));
    assert!(!listed.contains(id), "{listed}");
}
