//! Scaling: the wall time of one pt job rendered by real `tessera-worker` processes, one
//! configuration after another on one coordinator: one worker with one thread, two workers
//! with one thread each, one worker with two threads. Workers connect through the counting
//! proxy, so each run also reports the bytes that crossed the wire per pixel per pass.

use super::serve::{ServeProcess, proc_cpu_seconds, temp_dir};
use super::wire::CountingProxy;
use super::{FarmArgs, job_client, wait_done};
use anyhow::{Context, bail};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tessera_common::settings::{IntegratorName, RenderSettings};
use tessera_proto::v1 as pb;

/// One configuration's run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ScalingRun {
    /// e.g. "2 workers x 1 thread".
    pub config: String,
    /// Submit to done.
    pub wall_s: f64,
    /// Speed-up over the first configuration.
    pub speedup: f64,
    /// Workers' user + system CPU seconds.
    pub worker_cpu_s: f64,
    /// The coordinator's CPU seconds during the job.
    pub coordinator_cpu_s: f64,
    /// Bytes from workers to the coordinator.
    pub bytes_up: u64,
    /// Bytes from the coordinator to workers.
    pub bytes_down: u64,
}

fn worker_bin(args: &FarmArgs) -> anyhow::Result<PathBuf> {
    let path = match &args.worker_bin {
        Some(p) => p.clone(),
        None => std::env::current_exe()?.with_file_name("tessera-worker"),
    };
    if !path.exists() {
        bail!("{} not found: build it (cargo build --release -p tessera-worker) or pass --worker-bin", path.display());
    }
    Ok(path)
}

fn start_worker(bin: &PathBuf, url: &str, threads: u32, name: &str) -> anyhow::Result<(Child, tempfile::TempDir)> {
    let cache = temp_dir("tessera-bench-worker")?;
    let child = Command::new(bin)
        .args(["--coordinator", url, "--threads", &threads.to_string(), "--name", name, "--cache-dir"])
        .arg(cache.path())
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .with_context(|| format!("cannot start {}", bin.display()))?;
    Ok((child, cache))
}

/// Runs the three configurations one after another and prints them.
pub fn scaling_command(args: &FarmArgs) -> anyhow::Result<()> {
    let bin = worker_bin(args)?;
    let times = super::calibrate::measure(&args.scene)?;
    let pixels = times.width as f64 * times.height as f64;
    let spp = args
        .scaling_spp
        .unwrap_or_else(|| (args.scaling_seconds * times.samples_per_s / pixels).round().max(1.0) as u32);
    let bundle = tessera_common::bundle::pack(&args.scene, &Default::default())?;
    let settings =
        RenderSettings { integrator: IntegratorName::Pt, spp: Some(spp), seed: Some(1), ..Default::default() };
    let configs: [(&str, &[u32]); 3] =
        [("1 worker x 1 thread", &[1]), ("2 workers x 1 thread", &[1, 1]), ("1 worker x 2 threads", &[2])];
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let runs = runtime.block_on(async {
        let serve = ServeProcess::start(None)?;
        let proxy = CountingProxy::start(&serve.url).await?;
        let mut jobs = job_client(&serve.url).await?;
        let mut runs: Vec<ScalingRun> = Vec::new();
        for (config, threads) in configs {
            let (up0, down0) = proxy.bytes();
            let cpu0 = serve.cpu_seconds()?;
            let t0 = Instant::now();
            let req = pb::SubmitJobRequest {
                settings: Some(tessera_link::convert::settings_to_pb(&settings)),
                bundle: Some(tessera_link::bundle::to_pb(&bundle)),
                priority: 0,
                name: format!("scaling {config}"),
                ..Default::default()
            };
            let id = jobs.submit_job(req).await?.into_inner().id;
            let mut workers = Vec::new();
            for (i, &t) in threads.iter().enumerate() {
                workers.push(start_worker(&bin, &proxy.url, t, &format!("bench-{i}"))?);
            }
            let done = wait_done(&mut jobs, std::slice::from_ref(&id), Duration::from_millis(50)).await;
            let wall_s = t0.elapsed().as_secs_f64();
            let coordinator_cpu_s = serve.cpu_seconds()? - cpu0;
            let mut worker_cpu_s = 0.0;
            for (mut child, cache) in workers {
                worker_cpu_s += proc_cpu_seconds(child.id()).unwrap_or(f64::NAN);
                let _ = child.kill();
                let _ = child.wait();
                drop(cache);
            }
            done?;
            let (up, down) = proxy.bytes();
            let speedup = runs.first().map_or(1.0, |r| r.wall_s / wall_s);
            runs.push(ScalingRun {
                config: config.into(),
                wall_s,
                speedup,
                worker_cpu_s,
                coordinator_cpu_s,
                bytes_up: up - up0,
                bytes_down: down - down0,
            });
        }
        anyhow::Ok(runs)
    })?;
    println!(
        "scaling: {} {}x{} pt at {spp} spp ({} tiles of 64x64), real tessera-worker processes, one after another",
        times.scene,
        times.width,
        times.height,
        times.width.div_ceil(64) * times.height.div_ceil(64)
    );
    for r in &runs {
        println!(
            "{:<22} wall {:>7.2} s  speed-up {:>5.2}x  worker cpu {:>7.2} s  coordinator cpu {:>5.2} s  wire up {:>7.2} B/px down {:>7.2} B/px",
            r.config,
            r.wall_s,
            r.speedup,
            r.worker_cpu_s,
            r.coordinator_cpu_s,
            r.bytes_up as f64 / pixels,
            r.bytes_down as f64 / pixels,
        );
        if args.json {
            println!("{}", serde_json::json!(r));
        }
    }
    Ok(())
}
