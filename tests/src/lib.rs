//! Harness of the farm integration tests: starts the real `tessera` coordinator and
//! `tessera-worker` binaries on loopback ports, runs the CLI, and compares images bit for bit.
//!
//! The binaries come from the same target directory as the test executable. `cargo test
//! --workspace` builds them (the coordinator and worker crates have integration tests, which
//! makes cargo build their binaries); alone, run
//! `cargo build -p tessera-coordinator -p tessera-worker` first.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub mod hostile;

/// A binary of the workspace, from the target directory this test runs in.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe.parent().and_then(Path::parent).expect("target/<profile>/deps");
    let path = dir.join(name);
    assert!(
        path.exists(),
        "{} is missing: run `cargo build -p tessera-coordinator -p tessera-worker` (or `cargo test --workspace`)",
        path.display()
    );
    path
}

/// A scene of the repository.
pub fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name).join("scene.xml")
}

/// A running coordinator, killed on drop.
pub struct Coordinator {
    /// The process.
    pub child: Child,
    /// `http://127.0.0.1:PORT`, or `https://` when it serves TLS.
    pub url: String,
    /// Its log file (stderr).
    pub log: PathBuf,
}

impl Coordinator {
    /// Starts `tessera serve` on `listen` (e.g. `127.0.0.1:0`) with `data_dir` and extra flags.
    pub fn start(data_dir: &Path, listen: &str, extra: &[&str]) -> Coordinator {
        Coordinator::start_with(data_dir, listen, extra, |_| {})
    }

    /// [`Coordinator::start`] with the command adjusted by `configure` first (limits, env).
    pub fn start_with(
        data_dir: &Path,
        listen: &str,
        extra: &[&str],
        configure: impl FnOnce(&mut Command),
    ) -> Coordinator {
        Coordinator::start_bin(&bin("tessera"), data_dir, listen, extra, configure)
    }

    /// [`Coordinator::start_with`] of the `tessera` binary at `binary`.
    pub fn start_bin(
        binary: &Path,
        data_dir: &Path,
        listen: &str,
        extra: &[&str],
        configure: impl FnOnce(&mut Command),
    ) -> Coordinator {
        static STARTS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = STARTS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let log = data_dir.with_extension(format!("coordinator-{n}.log"));
        let mut command = Command::new(binary);
        command
            .args(["serve", "--listen", listen, "--data-dir"])
            .arg(data_dir)
            .args(extra)
            .env("RUST_LOG", "tessera_coordinator=debug,warn")
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(&log).expect("log file"));
        configure(&mut command);
        let mut child = command.spawn().expect("start tessera serve");
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("stdout")).read_line(&mut line).expect("read address");
        let url = line
            .trim()
            .rsplit(' ')
            .next()
            .filter(|u| u.starts_with("http://") || u.starts_with("https://"))
            .unwrap_or_else(|| {
                panic!(
                    "no address from tessera serve ({line:?}), log: {}",
                    std::fs::read_to_string(&log).unwrap_or_default()
                )
            })
            .to_string();
        Coordinator { child, url, log }
    }

    /// The port it listens on.
    pub fn port(&self) -> u16 {
        self.url.rsplit(':').next().and_then(|p| p.parse().ok()).expect("port in url")
    }

    /// SIGKILL.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A running worker, killed on drop.
pub struct Worker {
    /// The process.
    pub child: Child,
}

impl Worker {
    /// Starts `tessera-worker` against `url` with one thread and `extra` flags.
    pub fn start(url: &str, cache: &Path, extra: &[&str]) -> Worker {
        Worker::start_bin(&bin("tessera-worker"), url, cache, extra)
    }

    /// [`Worker::start`] of the `tessera-worker` binary at `binary`.
    pub fn start_bin(binary: &Path, url: &str, cache: &Path, extra: &[&str]) -> Worker {
        let child = Command::new(binary)
            .args(["--coordinator", url, "--threads", "1", "--cache-dir"])
            .arg(cache)
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start tessera-worker");
        Worker { child }
    }

    /// SIGKILL.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A coordinator on a free loopback port with its data in `dir/data`, and `workers` workers
/// sharing `dir/cache` (stopped when dropped, workers first).
pub fn farm(dir: &Path, workers: usize) -> (Coordinator, Vec<Worker>) {
    let c = Coordinator::start(&dir.join("data"), "127.0.0.1:0", &[]);
    let w = (0..workers).map(|_| Worker::start(&c.url, &dir.join("cache"), &[])).collect();
    (c, w)
}

/// `tessera submit SCENE --server URL --integrator I --spp N --seed S --wait -o OUT EXTRA...`:
/// a farm render written to `out`; returns (success, stdout, stderr).
pub fn submit_and_wait(
    url: &str,
    scene: &Path,
    (integrator, spp, seed): (&str, u32, u64),
    out: &Path,
    extra: &[&str],
) -> (bool, String, String) {
    let (spp, seed) = (spp.to_string(), seed.to_string());
    let mut args = vec!["submit", scene.to_str().unwrap(), "--server", url, "--integrator", integrator];
    args.extend(["--spp", &spp, "--seed", &seed, "--wait", "-o", out.to_str().unwrap()]);
    args.extend(extra);
    tessera(&args)
}

/// Runs `tessera ARGS` and returns (success, stdout, stderr).
pub fn tessera(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(bin("tessera")).args(args).output().expect("run tessera");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Renders locally with `tessera render` and returns the EXR path.
pub fn local_render(dir: &Path, scene: &Path, integrator: &str, spp: u32, seed: u64) -> PathBuf {
    local_render_with(dir, scene, integrator, spp, seed, &[])
}

/// [`local_render`] with more options for `tessera render`.
pub fn local_render_with(dir: &Path, scene: &Path, integrator: &str, spp: u32, seed: u64, more: &[&str]) -> PathBuf {
    let out = dir.join(format!("local-{integrator}-{spp}-{seed}.exr"));
    let (spp, seed) = (spp.to_string(), seed.to_string());
    let mut args = vec![
        "render",
        scene.to_str().expect("utf-8 path"),
        "--integrator",
        integrator,
        "--spp",
        &spp,
        "--seed",
        &seed,
        "--threads",
        "1",
        "-o",
        out.to_str().expect("utf-8 path"),
    ];
    args.extend_from_slice(more);
    let (ok, _, err) = tessera(&args);
    assert!(ok, "local render failed: {err}");
    out
}

/// Asserts two EXRs have bit-identical RGB and sample counts.
pub fn assert_same_image(farm: &Path, local: &Path) {
    use tessera_common::film::exr::{read_rgb, read_sample_counts};
    let (a, b) = (read_rgb(farm).expect("farm exr"), read_rgb(local).expect("local exr"));
    assert_eq!((a.width, a.height), (b.width, b.height));
    let differing = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| x.to_bits() != y.to_bits()))
        .count();
    assert_eq!(differing, 0, "{differing} pixels differ between {} and {}", farm.display(), local.display());
    assert_eq!(read_sample_counts(farm).expect("farm counts"), read_sample_counts(local).expect("local counts"));
}

/// Asserts that the EMIS outputs beside two EXRs (`NAME.strategy.png`, `NAME.emis.json`)
/// agree: the strategy PNGs byte for byte, the reports as JSON except each update's
/// `denoise_ms` and `optimize_ms`, which time the run (every other number is computed from the
/// same merged moments, so it is equal).
pub fn assert_same_emis_outputs(farm: &Path, local: &Path) {
    let read = |p: &Path| std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let (a, b) = (farm.with_extension("strategy.png"), local.with_extension("strategy.png"));
    assert!(read(&a) == read(&b), "{} and {} differ", a.display(), b.display());
    let report = |exr: &Path| {
        let path = exr.with_extension("emis.json");
        let mut report: serde_json::Value = serde_json::from_slice(&read(&path)).expect("a JSON report");
        let updates = report["updates"].as_array_mut().unwrap_or_else(|| panic!("no updates in {}", path.display()));
        for update in updates {
            let update = update.as_object_mut().expect("an update is an object");
            for timing in ["denoise_ms", "optimize_ms"] {
                assert!(update.remove(timing).is_some_and(|t| t.is_number()), "{timing} in {}", path.display());
            }
        }
        report
    };
    assert_eq!(report(farm), report(local), "the EMIS reports differ");
}

/// Polls `f` every 50 ms until it returns `Some`, panicking after `timeout`.
pub fn wait_for<T>(timeout: Duration, what: &str, f: impl FnMut() -> Option<T>) -> T {
    wait_for_or(timeout, f).unwrap_or_else(|| panic!("timed out waiting for {what}"))
}

/// Polls `f` every 50 ms until it returns `Some`; `None` after `timeout`.
pub fn wait_for_or<T>(timeout: Duration, mut f: impl FnMut() -> Option<T>) -> Option<T> {
    let start = Instant::now();
    loop {
        if let Some(v) = f() {
            return Some(v);
        }
        if start.elapsed() >= timeout {
            return None;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Blocking helpers over reqwest for the REST API.
pub mod rest {
    use reqwest::multipart::{Form, Part};
    use reqwest::{Method, RequestBuilder};

    /// What a request carries beyond its URL and token: headers (a browser's `Origin`), and
    /// the PEM certificate an `https://` server's certificate chains to.
    #[derive(Clone, Copy, Default)]
    pub struct Extra<'a> {
        /// Extra headers.
        pub headers: &'a [(&'a str, &'a str)],
        /// The CA to trust (only it) for `https://` URLs.
        pub ca_pem: Option<&'a [u8]>,
    }

    fn rt() -> tokio::runtime::Runtime {
        tokio::runtime::Builder::new_current_thread().enable_all().build().expect("runtime")
    }

    /// A client for plain URLs, or for https:// ones whose certificate chains to `ca_pem`
    /// (HTTP/1.1: the gRPC tests cover HTTP/2).
    pub fn client(ca_pem: Option<&[u8]>) -> reqwest::Client {
        // reqwest is built without a crypto provider of its own (its default, aws-lc-rs, needs
        // cmake); an error means one is installed already
        let _ = rustls::crypto::ring::default_provider().install_default();
        let Some(pem) = ca_pem else { return reqwest::Client::new() };
        use rustls_pki_types::pem::PemObject;
        let mut roots = rustls::RootCertStore::empty();
        for cert in rustls_pki_types::CertificateDer::pem_slice_iter(pem) {
            roots.add(cert.expect("CA PEM")).expect("CA certificate");
        }
        let provider = std::sync::Arc::new(rustls::crypto::ring::default_provider());
        let mut config = rustls::ClientConfig::builder_with_provider(provider)
            .with_safe_default_protocol_versions()
            .expect("TLS versions")
            .with_root_certificates(roots)
            .with_no_client_auth();
        config.alpn_protocols = vec![b"http/1.1".to_vec()];
        reqwest::Client::builder().tls_backend_preconfigured(config).build().expect("https client")
    }

    /// Sends a request built by `build` from a client for `extra`, with the token and headers;
    /// returns (status, body bytes).
    pub fn send(
        token: Option<&str>,
        extra: Extra,
        build: impl FnOnce(&reqwest::Client) -> RequestBuilder,
    ) -> (u16, Vec<u8>) {
        rt().block_on(async {
            let mut req = build(&client(extra.ca_pem));
            if let Some(t) = token {
                req = req.bearer_auth(t);
            }
            for (name, value) in extra.headers {
                req = req.header(*name, *value);
            }
            let r = req.send().await.unwrap_or_else(|e| panic!("request failed: {e:?}"));
            (r.status().as_u16(), r.bytes().await.expect("body").to_vec())
        })
    }

    /// [`send`] that answers status 0 when the server cannot be reached or does not answer
    /// within two minutes (a coordinator that died), instead of panicking.
    pub fn try_send(extra: Extra, build: impl FnOnce(&reqwest::Client) -> RequestBuilder) -> (u16, Vec<u8>) {
        rt().block_on(async {
            let mut req = build(&client(extra.ca_pem)).timeout(std::time::Duration::from_secs(120));
            for (name, value) in extra.headers {
                req = req.header(*name, *value);
            }
            match req.send().await {
                Ok(r) => (r.status().as_u16(), r.bytes().await.map(|b| b.to_vec()).unwrap_or_default()),
                Err(_) => (0, Vec::new()),
            }
        })
    }

    /// GET that answers status 0 when the server is gone.
    pub fn try_get(url: &str) -> (u16, Vec<u8>) {
        try_send(Extra::default(), |c| c.get(url))
    }

    /// GET JSON that answers status 0 when the server is gone.
    pub fn try_get_json(url: &str) -> (u16, serde_json::Value) {
        json(try_get(url))
    }

    /// POST without a body that answers status 0 when the server is gone.
    pub fn try_post(url: &str) -> (u16, serde_json::Value) {
        json(try_send(Extra::default(), |c| c.request(Method::POST, url)))
    }

    /// DELETE that answers status 0 when the server is gone.
    pub fn try_delete(url: &str) -> (u16, serde_json::Value) {
        json(try_send(Extra::default(), |c| c.request(Method::DELETE, url)))
    }

    /// [`submit`] that answers status 0 when the server is gone.
    pub fn try_submit(
        base: &str,
        scene: (&str, Vec<u8>),
        assets: Vec<(String, Vec<u8>)>,
        settings: serde_json::Value,
    ) -> (u16, serde_json::Value) {
        try_submit_with(base, Extra::default(), scene, assets, settings)
    }

    /// [`try_submit`] with `extra`.
    pub fn try_submit_with(
        base: &str,
        extra: Extra,
        scene: (&str, Vec<u8>),
        assets: Vec<(String, Vec<u8>)>,
        settings: serde_json::Value,
    ) -> (u16, serde_json::Value) {
        let form = form(scene, assets, settings);
        json(try_send(extra, |c| c.post(format!("{base}/api/v1/jobs")).multipart(form)))
    }

    fn form(scene: (&str, Vec<u8>), assets: Vec<(String, Vec<u8>)>, settings: serde_json::Value) -> Form {
        let mut form = Form::new()
            .part("scene", Part::bytes(scene.1).file_name(scene.0.to_string()))
            .text("settings", settings.to_string());
        for (path, bytes) in assets {
            form = form.part("asset", Part::bytes(bytes).file_name(path));
        }
        form
    }

    fn json(status_body: (u16, Vec<u8>)) -> (u16, serde_json::Value) {
        (status_body.0, serde_json::from_slice(&status_body.1).unwrap_or(serde_json::Value::Null))
    }

    /// GET, returning (status, body bytes).
    pub fn get(url: &str, token: Option<&str>) -> (u16, Vec<u8>) {
        send(token, Extra::default(), |c| c.get(url))
    }

    /// GET JSON.
    pub fn get_json(url: &str, token: Option<&str>) -> (u16, serde_json::Value) {
        json(get(url, token))
    }

    /// DELETE JSON.
    pub fn delete(url: &str, token: Option<&str>) -> (u16, serde_json::Value) {
        delete_with(url, token, Extra::default())
    }

    /// DELETE JSON with `extra`.
    pub fn delete_with(url: &str, token: Option<&str>, extra: Extra) -> (u16, serde_json::Value) {
        json(send(token, extra, |c| c.request(Method::DELETE, url)))
    }

    /// POST without a body, returning JSON.
    pub fn post(url: &str, token: Option<&str>) -> (u16, serde_json::Value) {
        json(send(token, Extra::default(), |c| c.request(Method::POST, url)))
    }

    /// POST /api/v1/jobs with a scene, assets `(path, bytes)` and settings JSON.
    pub fn submit(
        base: &str,
        token: Option<&str>,
        scene: (&str, Vec<u8>),
        assets: Vec<(String, Vec<u8>)>,
        settings: serde_json::Value,
    ) -> (u16, serde_json::Value) {
        submit_with(base, token, Extra::default(), scene, assets, settings)
    }

    /// [`submit`] with `extra`.
    pub fn submit_with(
        base: &str,
        token: Option<&str>,
        extra: Extra,
        scene: (&str, Vec<u8>),
        assets: Vec<(String, Vec<u8>)>,
        settings: serde_json::Value,
    ) -> (u16, serde_json::Value) {
        let form = form(scene, assets, settings);
        json(send(token, extra, |c| c.post(format!("{base}/api/v1/jobs")).multipart(form)))
    }
}
