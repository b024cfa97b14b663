//! TLS and origins with real processes: a coordinator serving `https://` with a certificate
//! made in the test, a worker and the `tessera` command trusting it through `--ca-cert` (gRPC
//! over HTTP/2), REST and the dashboard over HTTP/1.1 on the same port; and browsers' requests
//! from other origins refused, with and without tokens, while the server's own origin (the
//! dashboard) and clients without browser headers pass.

use super::*;
use std::path::PathBuf;
use tessera_tests::rest::Extra;

/// A self-signed certificate for 127.0.0.1 and localhost in `dir`: (cert.pem, key.pem, the
/// certificate's PEM).
fn self_signed(dir: &Path) -> (PathBuf, PathBuf, Vec<u8>) {
    let made = rcgen::generate_simple_self_signed(vec!["127.0.0.1".to_string(), "localhost".to_string()]).unwrap();
    let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
    std::fs::write(&cert, made.cert.pem()).unwrap();
    std::fs::write(&key, made.signing_key.serialize_pem()).unwrap();
    (cert, key, made.cert.pem().into_bytes())
}

#[test]
fn tls_end_to_end_with_a_self_signed_certificate_made_in_the_test() {
    let dir = tempfile::tempdir().unwrap();
    let (cert, key, pem) = self_signed(dir.path());
    let cert_arg = cert.to_str().unwrap();
    let mut c = Coordinator::start(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--tls-cert", cert_arg, "--tls-key", key.to_str().unwrap()],
    );
    assert!(c.url.starts_with("https://127.0.0.1:"), "{}", c.url);
    let cache = dir.path().join("cache");
    let _trusting = Worker::start(&c.url, &cache, &["--ca-cert", cert_arg, "--name", "trusting"]);
    // without the CA the worker cannot verify the coordinator and never registers
    let _untrusting = Worker::start(&c.url, &cache, &["--name", "untrusting"]);
    let out = dir.path().join("farm.exr");
    let box_scene = scene("cornell-box");
    let (ok, stdout, stderr) = submit_and_wait(&c.url, &box_scene, ("pt", 2, 6), &out, &["--ca-cert", cert_arg]);
    assert!(ok, "submit over https failed: {stderr}\nlog: {}", c.log.display());
    assert_same_image(&out, &local_render(dir.path(), &box_scene, "pt", 2, 6));
    let id = stdout.lines().next().unwrap().trim().to_string();

    // REST and the dashboard over https on the same port
    let ca = Extra { headers: &[], ca_pem: Some(&pem) };
    let (status, job) = rest::send(None, ca, |http| http.get(job_url(&c, &id)));
    let job: Value = serde_json::from_slice(&job).unwrap();
    assert_eq!((status, job["state"].as_str()), (200, Some("done")), "{job}");
    let (status, page) = rest::send(None, ca, |http| http.get(format!("{}/", c.url)));
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&page).contains("/api/v1/jobs"), "the dashboard page");
    let (status, workers) = rest::send(None, ca, |http| http.get(format!("{}/api/v1/workers", c.url)));
    let workers: Value = serde_json::from_slice(&workers).unwrap();
    let names: Vec<_> = workers.as_array().unwrap().iter().map(|w| w["name"].as_str().unwrap()).collect();
    assert_eq!((status, names), (200, vec!["trusting"]), "only the worker given the CA registers");

    // the dashboard's origin is https://: it may change jobs, the http:// twin may not
    let xml = std::fs::read(&box_scene).unwrap();
    let settings = json!({"integrator": "pt", "spp": 1});
    let own = Extra { headers: &[("origin", &c.url)], ca_pem: Some(&pem) };
    let plain_origin = c.url.replacen("https://", "http://", 1);
    let downgraded = Extra { headers: &[("origin", &plain_origin)], ca_pem: Some(&pem) };
    let (status, body) =
        rest::submit_with(&c.url, None, downgraded, ("scene.xml", xml.clone()), vec![], settings.clone());
    assert_eq!(status, 403, "{body}");
    let (status, body) = rest::submit_with(&c.url, None, own, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{body}");

    // a client that does not trust the certificate, or speaks plain text to the TLS port, fails
    let (ok, _, err) = tessera(&["status", &id, "--server", &c.url]);
    assert!(!ok && err.contains("cannot connect") && err.contains("certificate"), "{err}");
    let (ok, _, err) = tessera(&["status", &id, "--server", &plain_origin]);
    assert!(!ok, "plain http to the TLS port: {err}");
    let (ok, status, err) = tessera(&["status", &id, "--server", &c.url, "--ca-cert", cert_arg, "--json"]);
    assert!(ok, "{err}");
    assert_eq!(serde_json::from_str::<Value>(&status).unwrap()["state"], "done");

    // SIGTERM still drains and stops the TLS server (the worker's long poll is cut after the
    // drain timeout)
    // SAFETY: signalling our own child process
    unsafe { libc::kill(c.child.id() as i32, libc::SIGTERM) };
    let stopped = wait_for(Duration::from_secs(20), "the coordinator to stop", || c.child.try_wait().unwrap());
    assert!(stopped.success(), "{stopped:?}, log: {}", c.log.display());
}

/// A self-signed certificate marked as a CA, for `names`, as openssl's usual one-liner makes
/// it (`openssl req -x509 -newkey ... -subj /CN=... -addext subjectAltName=...` sets
/// `basicConstraints = CA:TRUE`): (cert.pem, key.pem).
fn self_signed_ca(dir: &Path, names: &[&str]) -> (PathBuf, PathBuf) {
    let key = rcgen::KeyPair::generate().unwrap();
    let mut params = rcgen::CertificateParams::new(names.iter().map(|n| n.to_string()).collect::<Vec<_>>()).unwrap();
    params.is_ca = rcgen::IsCa::Ca(rcgen::BasicConstraints::Unconstrained);
    let made = params.self_signed(&key).unwrap();
    std::fs::create_dir_all(dir).unwrap();
    let (cert, key_path) = (dir.join("cert.pem"), dir.join("key.pem"));
    std::fs::write(&cert, made.pem()).unwrap();
    std::fs::write(&key_path, key.serialize_pem()).unwrap();
    (cert, key_path)
}

/// A certificate the user pinned with --ca-cert is trusted though it is marked as a CA (curl
/// accepts it; the chain check alone refused it with `CaUsedAsEndEntity`): the command and a
/// worker reach the coordinator. Another such certificate, or the pinned one for a name it
/// does not hold, is still refused; an http:// URL gets told to use https://.
#[test]
fn a_pinned_self_signed_ca_certificate_is_trusted_as_curl_trusts_it() {
    let dir = tempfile::tempdir().unwrap();
    let (cert, key) = self_signed_ca(&dir.path().join("server"), &["127.0.0.1", "localhost"]);
    let cert_arg = cert.to_str().unwrap();
    let c = Coordinator::start(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--tls-cert", cert_arg, "--tls-key", key.to_str().unwrap()],
    );
    let status = |url: &str, ca: &str| tessera(&["status", "--server", url, "--ca-cert", ca]);
    let (ok, _, err) = status(&c.url, cert_arg);
    assert!(ok, "the pinned certificate is trusted: {err}");
    let (other, _) = self_signed_ca(&dir.path().join("other"), &["127.0.0.1", "localhost"]);
    let (ok, _, err) = status(&c.url, other.to_str().unwrap());
    assert!(!ok && err.contains("certificate"), "another certificate is not the pin: {err}");
    let (only_localhost, only_key) = self_signed_ca(&dir.path().join("named"), &["localhost"]);
    let named = Coordinator::start(
        &dir.path().join("data2"),
        "127.0.0.1:0",
        &["--tls-cert", only_localhost.to_str().unwrap(), "--tls-key", only_key.to_str().unwrap()],
    );
    let (ok, _, err) = status(&named.url, only_localhost.to_str().unwrap());
    assert!(!ok && err.contains("certificate"), "the pin must still name the server (127.0.0.1): {err}");
    // http:// to this TLS port: the command and a worker say to use https://, and the worker
    // stops (retrying cannot mend the URL)
    let plain = c.url.replacen("https://", "http://", 1);
    let (ok, _, err) = tessera(&["status", "--server", &plain]);
    assert!(!ok && err.contains("speaks TLS: use https://"), "{err}");
    let worker = std::process::Command::new(tessera_tests::bin("tessera-worker"))
        .args(["--coordinator", &plain, "--cache-dir", dir.path().join("plain-cache").to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&worker.stderr);
    assert!(!worker.status.success() && err.contains("speaks TLS: use https://"), "{err}");
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &["--ca-cert", cert_arg]);
    let out = dir.path().join("pinned.exr");
    let (ok, _, err) = submit_and_wait(&c.url, &scene("cornell-box"), ("pt", 2, 6), &out, &["--ca-cert", cert_arg]);
    assert!(ok, "a worker and the command over the pinned certificate: {err}");
}

#[test]
fn cross_origin_pages_cannot_submit_or_cancel_jobs_with_or_without_tokens() {
    let dir = tempfile::tempdir().unwrap();
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let settings = json!({"integrator": "pt", "spp": 1});
    let submit = |c: &Coordinator, token: Option<&str>, extra: Extra| {
        rest::submit_with(&c.url, token, extra, ("scene.xml", xml.clone()), vec![], settings.clone())
    };

    // no tokens: a loopback farm any local web page could reach
    let c = Coordinator::start(&dir.path().join("open"), "127.0.0.1:0", &[]);
    let evil = Extra { headers: &[("origin", "http://evil.example")], ..Extra::default() };
    let (status, body) = submit(&c, None, evil);
    assert_eq!((status, body["code"].as_str()), (403, Some("permission_denied")), "{body}");
    assert!(body["error"].as_str().unwrap().contains("http://evil.example"), "{body}");
    let next_port = format!("http://127.0.0.1:{}", c.port() + 1);
    let other_port = Extra { headers: &[("origin", &next_port)], ..Extra::default() };
    assert_eq!(submit(&c, None, other_port).0, 403, "another port is another origin");
    let cross = Extra { headers: &[("sec-fetch-site", "cross-site")], ..Extra::default() };
    assert_eq!(submit(&c, None, cross).0, 403, "a cross-site fetch without Origin");
    let (_, jobs) = rest::get_json(&format!("{}/api/v1/jobs", c.url), None);
    assert_eq!(jobs, json!([]), "no refused submission made a job");
    // the dashboard's own origin, and clients without browser headers, pass
    let own = Extra { headers: &[("origin", &c.url)], ..Extra::default() };
    let (status, job) = submit(&c, None, own);
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    let cancel = format!("{}/cancel", job_url(&c, id));
    let (status, body) = rest::send(None, evil, |cl| cl.post(&cancel));
    assert_eq!(status, 403, "{}", String::from_utf8_lossy(&body));
    assert_eq!(rest::get_json(&job_url(&c, id), None).1["state"], "queued", "the refused cancel did nothing");
    let (status, body) = rest::send(None, own, |cl| cl.post(&cancel));
    let body: Value = serde_json::from_slice(&body).unwrap_or(Value::Null);
    assert_eq!((status, body["state"].as_str()), (200, Some("cancelled")), "{body}");
    let (status, _) = rest::send(None, evil, |cl| cl.delete(job_url(&c, id)));
    assert_eq!(status, 403, "a foreign page cannot delete an ended job either");
    let (status, _) = rest::send(None, own, |cl| cl.delete(job_url(&c, id)));
    assert_eq!(status, 204);
    assert_eq!(submit(&c, None, Extra::default()).0, 201);

    // tokens: a foreign page is refused even with the right one (and without it, 403 first)
    let token = Some("client-secret");
    let d = Coordinator::start(
        &dir.path().join("tokens"),
        "127.0.0.1:0",
        &["--client-token", "client-secret", "--worker-token", "worker-secret"],
    );
    assert_eq!(submit(&d, token, evil).0, 403);
    assert_eq!(submit(&d, None, evil).0, 403);
    let own = Extra { headers: &[("origin", &d.url)], ..Extra::default() };
    assert_eq!(submit(&d, None, own).0, 401, "the own origin still needs the token");
    assert_eq!(submit(&d, token, own).0, 201);
}
