//! `tessera bench speed`: samples per second of an integrator on scenes, optionally side by
//! side with Mitsuba 3 in the same run (through the shared `render_reference.py --bench`, which
//! reports Mitsuba's warm wall time and CPU time for the same scene, resolution, spp and max
//! depth). Both sides report samples per wall-second and per CPU-second; the CPU figures are
//! what to compare on a shared, noisy machine.

use super::{SceneArgs, cpu_seconds};
use crate::options::{make_renderer, scene_name};
use anyhow::{Context, bail};
use std::path::PathBuf;
use std::process::Command;
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::Scene;
use tessera_common::settings::{IntegratorName, RenderSettings};

/// Arguments of `tessera bench speed`.
#[derive(clap::Args, Debug, Clone)]
pub struct SpeedArgs {
    /// Scenes and threads.
    #[command(flatten)]
    pub scenes: SceneArgs,
    /// Algorithm to measure.
    #[arg(long, value_enum, default_value = "pt")]
    pub integrator: IntegratorName,
    /// Samples per pixel per run.
    #[arg(long, default_value_t = 16)]
    pub spp: u32,
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
}

#[derive(serde::Serialize)]
struct Timing {
    samples_per_s: f64,
    samples_per_cpu_s: f64,
}

fn time_tessera(args: &SpeedArgs, scene: &Scene) -> anyhow::Result<Timing> {
    let renderer = make_renderer(&RenderSettings { integrator: args.integrator, ..RenderSettings::default() }, scene)?;
    let opts = RenderOptions {
        budget: Budget::Samples(args.spp),
        seed: 1,
        threads: args.scenes.threads.unwrap_or(0),
        tile_size: 32,
    };
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
    args: &SpeedArgs,
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
    if let Some(t) = args.scenes.threads {
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

/// Runs `tessera bench speed`.
pub fn run(args: &SpeedArgs) -> anyhow::Result<()> {
    let scenes = args.scenes.scenes()?;
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
                serde_json::json!({"scene": name, "integrator": args.integrator.as_str(), "spp": args.spp, "tessera": ours, "mitsuba": m})
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
