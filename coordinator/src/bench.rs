//! `tessera bench`: samples per second of an integrator on scenes, optionally side by side
//! with Mitsuba 3 in the same run (through the shared `render_reference.py --bench`, which
//! reports Mitsuba's warm wall time and CPU time for the same scene, resolution, spp and
//! max depth). Both sides report samples per wall-second and per CPU-second; the CPU figures
//! are what to compare on a shared, noisy machine.

use crate::cli::IntegratorKind;
use crate::local::{make_renderer, scene_name};
use anyhow::{Context, bail};
use std::path::PathBuf;
use std::process::Command;
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::Scene;
use tessera_common::settings::RenderSettings;

/// Arguments of `tessera bench`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchArgs {
    /// Scene files [default: every scenes/*/scene.xml].
    pub scenes: Vec<PathBuf>,
    /// Algorithm to measure.
    #[arg(long, value_enum, default_value = "pt")]
    pub integrator: IntegratorKind,
    /// Samples per pixel per run.
    #[arg(long, default_value_t = 16)]
    pub spp: u32,
    /// Render threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Timed runs per scene after one warm-up; the fastest is kept.
    #[arg(long, default_value_t = 2)]
    pub repeats: u32,
    /// Python interpreter with `mitsuba` installed: also time Mitsuba on each scene.
    #[arg(long)]
    pub mitsuba_python: Option<PathBuf>,
    /// Path of render_reference.py.
    #[arg(long, default_value = "../shared/tools/render_reference.py")]
    pub mitsuba_script: PathBuf,
    /// Mitsuba variants to time.
    #[arg(long, value_delimiter = ',', default_value = "scalar_rgb,llvm_ad_rgb")]
    pub mitsuba_variants: Vec<String>,
    /// Print one JSON object per scene instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Equal-time mode: render each scene with each of `--integrators` for this many seconds
    /// (comma-separated durations run one after another) and report relMSE against the
    /// scene's reference.exr, speed-ups and the EMIS targets.
    #[arg(long, value_delimiter = ',')]
    pub equal_time: Vec<f64>,
    /// Equal-time mode: render every cell once per seed; relMSE is the mean over seeds, and
    /// the floor is also reported per seed, so that a verdict shows the run-to-run spread.
    #[arg(long, value_delimiter = ',', default_value = "1")]
    pub seeds: Vec<u64>,
    /// Equal-time mode: the EMIS cost heuristic's constants.
    #[arg(long, value_enum, default_value = "calibrated")]
    pub cost_model: crate::cli::CostModelArg,
    /// Equal-time mode: the EMIS moment filter order.
    #[arg(long, value_enum, default_value = "relative")]
    pub moment_filter: crate::cli::MomentFilterArg,
    /// Equal-time mode: the EMIS outlier rejection.
    #[arg(long, value_enum, default_value = "shared")]
    pub moment_outliers: crate::cli::MomentOutliersArg,
    /// `--equal-time`: the pilots each `emis-*` integrator runs with (each a column).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "bidirectional")]
    pub emis_pilot: Vec<crate::cli::EmisPilotArg>,
    /// Integrators compared in equal-time mode.
    #[arg(long, value_delimiter = ',', default_value = "pt,bdpt,vcm,emis-bdpt,emis-vcm")]
    pub integrators: Vec<IntegratorKind>,
    /// Equal-time mode: also draw the speed-ups as a PNG bar chart (one file per duration,
    /// NAME-20s.png ...).
    #[arg(long)]
    pub chart: Option<PathBuf>,
    /// Measure EMIS overheads: moment accumulation, optimiser and denoiser time, memory.
    #[arg(long)]
    pub emis_overheads: bool,
    /// Ground-truth mode (decision 3): render every candidate of a reduced set for this many
    /// iterations and compare variance-based with moment-based choices.
    #[arg(long)]
    pub ground_truth: Option<u32>,
    /// Pilot iterations of the ground-truth mode.
    #[arg(long, default_value_t = 4)]
    pub ground_truth_pilot: u32,
    /// Calibrate the EMIS cost heuristic (decision 8): time path tracing, light tracing,
    /// connections and merging on every scene (`--spp` iterations each, `--repeats` rounds),
    /// fit the constants and report the predicted costs' errors.
    #[arg(long)]
    pub calibrate_costs: bool,
    /// Measure photon-map build and query rates for this many photons instead.
    #[arg(long)]
    pub photon_map: Option<u32>,
}

/// Process CPU time (user + system) in seconds.
pub fn cpu_seconds() -> f64 {
    // SAFETY: getrusage only writes into the struct we pass
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(usage.ru_utime) + tv(usage.ru_stime)
}

#[derive(serde::Serialize)]
struct Timing {
    samples_per_s: f64,
    samples_per_cpu_s: f64,
}

fn time_tessera(args: &BenchArgs, scene: &Scene) -> anyhow::Result<Timing> {
    let renderer =
        make_renderer(&RenderSettings { integrator: args.integrator.into(), ..RenderSettings::default() }, scene)?;
    let opts =
        RenderOptions { budget: Budget::Samples(args.spp), seed: 1, threads: args.threads.unwrap_or(0), tile_size: 32 };
    let mut best: Option<(f64, f64)> = None;
    for run in 0..=args.repeats {
        let c0 = cpu_seconds();
        let (out, _) = renderer.render(scene, &opts, &|_, _| {})?;
        let (wall, cpu) = (out.elapsed.as_secs_f64(), cpu_seconds() - c0);
        if run > 0 && best.is_none_or(|(w, _)| wall < w) {
            best = Some((wall, cpu));
        }
    }
    let (wall, cpu) = best.context("invariant: at least one timed run")?;
    let n = scene.camera.width as f64 * scene.camera.height as f64 * args.spp as f64;
    Ok(Timing { samples_per_s: n / wall, samples_per_cpu_s: n / cpu.max(1e-9) })
}

fn time_mitsuba(
    args: &BenchArgs,
    python: &PathBuf,
    scene: &PathBuf,
    variant: &str,
    max_depth: Option<u32>,
) -> anyhow::Result<Timing> {
    let mut cmd = Command::new(python);
    cmd.arg(&args.mitsuba_script).arg(scene).args([
        "--variant",
        variant,
        "--spp",
        &args.spp.to_string(),
        "--bench",
        "--repeats",
        &args.repeats.max(1).to_string(),
    ]);
    if let Some(d) = max_depth {
        cmd.args(["--max-depth", &d.to_string()]);
    }
    if let Some(t) = args.threads {
        cmd.args(["--threads", &t.to_string()]);
    }
    let out = cmd.output().with_context(|| format!("cannot run {}", python.display()))?;
    if !out.status.success() {
        bail!(
            "mitsuba {variant} on {} failed: {}",
            scene.display(),
            String::from_utf8_lossy(&out.stderr).lines().last().unwrap_or("")
        );
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let line =
        stdout.lines().rev().find(|l| l.trim_start().starts_with('{')).context("mitsuba printed no JSON line")?;
    let v: serde_json::Value = serde_json::from_str(line)?;
    let get = |k: &str| v.get(k).and_then(|x| x.as_f64()).with_context(|| format!("mitsuba JSON lacks {k}"));
    Ok(Timing { samples_per_s: get("samples_per_s_warm")?, samples_per_cpu_s: get("samples_per_cpu_s_warm")? })
}

fn default_scenes() -> anyhow::Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir("scenes")
        .context("no scenes given and no ./scenes folder")?
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("scene.xml"))
        .filter(|p| p.exists())
        .collect();
    v.sort();
    Ok(v)
}

/// Photon-map build and query rates for `n` photons spread through a unit cube, queried at
/// `n` points with a radius that finds about 10 photons each.
fn photon_map_rates(n: u32) {
    use tessera_common::integrator::path::vertex::PathVertex;
    use tessera_common::integrator::path::photon_map::PhotonMap;
    use tessera_common::sampler::Sampler;
    let point = |seed: u64, i: u32| {
        let mut s = Sampler::for_pixel(seed, i, 0);
        let u = s.next_2d();
        glam::Vec3::new(u.x, u.y, s.next_1d())
    };
    let vertices: Vec<PathVertex> = (0..n).map(|i| PathVertex::surface_at(point(1, i))).collect();
    let all: Vec<u32> = (0..n).collect();
    let radius = (10.0 / (n as f32 * 4.0 / 3.0 * std::f32::consts::PI)).cbrt();
    let t = std::time::Instant::now();
    let map = PhotonMap::build(&vertices, &all, radius);
    let build = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let mut found = 0u64;
    for i in 0..n {
        map.query(point(2, i), radius, |_, _| found += 1);
    }
    let query = t.elapsed().as_secs_f64();
    println!(
        "photon map, {n} photons: build {:.3} s ({:.1} M photons/s); {n} queries of radius {radius:.4} in {:.3} s ({:.2} M queries/s, {:.1} photons found per query, single thread)",
        build,
        n as f64 / build / 1e6,
        query,
        n as f64 / query / 1e6,
        found as f64 / n as f64
    );
}

/// Runs `tessera bench`.
pub fn bench_command(args: &BenchArgs) -> anyhow::Result<()> {
    if let Some(n) = args.photon_map {
        photon_map_rates(n);
        return Ok(());
    }
    let scenes = if args.scenes.is_empty() { default_scenes()? } else { args.scenes.clone() };
    if !args.equal_time.is_empty() {
        return crate::bench_emis::equal_time(args, &scenes, &args.equal_time);
    }
    if let Some(k) = args.ground_truth {
        return crate::ground_truth::ground_truth(args, &scenes, k);
    }
    if args.calibrate_costs {
        return crate::calibrate::calibrate_costs(args, &scenes);
    }
    if args.emis_overheads {
        return crate::bench_emis::overheads(args, &scenes);
    }
    if !args.json {
        let mut header = format!("{:<24} {:>14} {:>14}", "scene", "tessera S/s", "S/cpu-s");
        if args.mitsuba_python.is_some() {
            for v in &args.mitsuba_variants {
                header += &format!(" {:>16} {:>9}", format!("{v} S/cpu-s"), "ratio");
            }
        }
        println!("{header}");
    }
    for path in &scenes {
        let scene = Scene::load(path)?;
        let ours = time_tessera(args, &scene)?;
        let mut mitsuba = Vec::new();
        if let Some(py) = &args.mitsuba_python {
            for v in &args.mitsuba_variants {
                mitsuba.push((v.clone(), time_mitsuba(args, py, path, v, scene.integrator.max_depth)?));
            }
        }
        let name = scene_name(path);
        if args.json {
            let m: serde_json::Map<String, serde_json::Value> =
                mitsuba.iter().map(|(v, t)| (v.clone(), serde_json::json!(t))).collect();
            println!(
                "{}",
                serde_json::json!({"scene": name, "integrator": format!("{:?}", args.integrator).to_lowercase(), "spp": args.spp, "tessera": ours, "mitsuba": m})
            );
        } else {
            let mut row = format!("{:<24} {:>14.0} {:>14.0}", name, ours.samples_per_s, ours.samples_per_cpu_s);
            for (_, t) in &mitsuba {
                row +=
                    &format!(" {:>16.0} {:>8.2}x", t.samples_per_cpu_s, ours.samples_per_cpu_s / t.samples_per_cpu_s);
            }
            println!("{row}");
        }
    }
    Ok(())
}
