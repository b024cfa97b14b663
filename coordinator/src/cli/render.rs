//! `tessera render`: renders a scene on this machine with no setup, writing an EXR (beauty RGB
//! plus per-pixel sample counts) and an sRGB PNG preview beside it (see [`crate::output`]).

use crate::options::{IntegratorArgs, IntegratorKind, make_renderer, parse_defines, scene_name};
use crate::output::{Outputs, Provenance};
use anyhow::bail;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Duration;
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::Scene;
use tessera_common::settings::RenderSettings;

/// Arguments of `tessera render`.
#[derive(clap::Args, Debug, Clone)]
pub struct RenderArgs {
    /// The Mitsuba 3 scene file (XML, format 3.0.0).
    pub scene: PathBuf,
    /// Output EXR [default: the scene's name in the working directory, e.g. cornell-box.exr].
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Rendering algorithm.
    #[arg(long, value_enum, default_value = "pt")]
    pub integrator: IntegratorKind,
    /// Samples per pixel; iterations for lt, bdpt and vcm [default: the scene's sampler sample_count].
    #[arg(long, conflicts_with = "time")]
    pub spp: Option<u32>,
    /// Render for this many seconds instead of a fixed sample count.
    #[arg(long)]
    pub time: Option<f64>,
    /// Seed of all random numbers; the same seed gives the same image [default: the scene's, or 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Render threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Path length, sample counts, merging and EMIS options.
    #[command(flatten)]
    pub mis: IntegratorArgs,
    /// Set a scene parameter ($name), overriding its <default>: -D name=value.
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    pub define: Vec<String>,
}

/// The settings `tessera render`'s arguments ask for (spp, seed and time stay with the
/// command: they are resolved against the scene there).
pub fn settings_from_args(args: &RenderArgs) -> RenderSettings {
    let mut settings = RenderSettings { integrator: args.integrator.into(), ..RenderSettings::default() };
    args.mis.apply(&mut settings);
    settings
}

/// Runs `tessera render`.
pub fn render_command(args: &RenderArgs) -> anyhow::Result<()> {
    let defines = parse_defines(&args.define)?;
    if let Some(t) = args.time {
        if !(t > 0.0 && t.is_finite()) {
            bail!("--time must be a positive number of seconds, got {t}");
        }
    }
    if args.spp == Some(0) {
        bail!("--spp must be at least 1");
    }
    if args.threads == Some(0) {
        bail!("--threads must be at least 1");
    }
    let scene = Scene::load_with(&args.scene, &defines)?;
    let renderer = make_renderer(&settings_from_args(args), &scene)?;
    let output = args.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.exr", scene_name(&args.scene))));
    let budget = match args.time {
        Some(t) => Budget::Time(Duration::from_secs_f64(t)),
        None => Budget::Samples(args.spp.unwrap_or(scene.spp)),
    };
    let opts = RenderOptions {
        budget,
        seed: args.seed.unwrap_or(scene.seed),
        threads: args.threads.unwrap_or(0),
        tile_size: 32,
    };
    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {percent:>3}% eta {eta}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let (out, emis) = renderer.render(&scene, &opts, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })?;
    bar.finish_and_clear();
    let provenance = Provenance {
        integrator: renderer.name().to_string(),
        spp: out.spp,
        seed: opts.seed,
        scene: scene.path.display().to_string(),
        extra: vec![("render_seconds".into(), format!("{:.3}", out.elapsed.as_secs_f64()))],
    };
    Outputs::new(&out.film, &provenance, emis.as_ref()).write_all(&output, renderer.name(), out.spp)?;
    let samples = out.film.total_samples();
    let secs = out.elapsed.as_secs_f64();
    if out.film.non_finite > 0 {
        tracing::warn!(count = out.film.non_finite, "non-finite samples were zeroed");
    }
    println!(
        "{}: {} spp ({} samples) in {:.2} s, {:.0} samples/s, peak memory {:.0} MB -> {}",
        renderer.name(),
        out.spp,
        samples,
        secs,
        samples as f64 / secs.max(1e-9),
        peak_rss_bytes() as f64 / 1e6,
        output.display()
    );
    Ok(())
}

/// Peak resident set size of this process so far (Linux reports `ru_maxrss` in KiB).
pub fn peak_rss_bytes() -> u64 {
    // SAFETY: getrusage only writes into the struct we pass
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    usage.ru_maxrss.max(0) as u64 * 1024
}
