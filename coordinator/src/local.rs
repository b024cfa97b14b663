//! `tessera render`: renders a scene on this machine with no setup, writing an EXR (beauty RGB
//! plus per-pixel sample counts) and an sRGB PNG preview beside it.

use crate::cli::{IntegratorKind, RenderArgs, Switch};
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tessera_common::film::{exr::write_exr, png::write_png};
use tessera_common::integrator::vcm::{MergeConfig, MergeMask};
use tessera_common::integrator::{Bidir, Integrator, LightTracer, PathSettings, PathTracer};
use tessera_common::render::{Budget, RenderOptions, RenderOutput, render};
use tessera_common::scene::Scene;

/// A scene's display name: the file stem, or the folder name for files called `scene.xml`.
pub fn scene_name(path: &Path) -> String {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("render");
    if stem == "scene" {
        if let Some(dir) = path
            .canonicalize()
            .ok()
            .as_deref()
            .and_then(Path::parent)
            .and_then(Path::file_name)
            .and_then(|s| s.to_str())
        {
            return dir.to_string();
        }
    }
    stem.to_string()
}

/// Parses `-D name=value` definitions.
pub fn parse_defines(defines: &[String]) -> anyhow::Result<HashMap<String, String>> {
    defines
        .iter()
        .map(|d| match d.split_once('=') {
            Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
            _ => bail!("invalid -D \"{d}\": expected NAME=VALUE"),
        })
        .collect()
}

/// The integrator parameters of the command line.
#[derive(Clone, Copy, Debug)]
pub struct IntegratorOptions {
    /// `--max-depth`.
    pub max_depth: Option<i64>,
    /// `--light-paths-per-pixel`.
    pub light_paths_per_pixel: f32,
    /// `--connections`.
    pub connections: u32,
    /// `--merge`.
    pub merge: bool,
    /// `--correlation-aware`.
    pub correlation_aware: bool,
}

impl IntegratorOptions {
    /// From `tessera render`'s arguments.
    pub fn from_args(args: &RenderArgs) -> Self {
        IntegratorOptions {
            max_depth: args.max_depth,
            light_paths_per_pixel: args.light_paths_per_pixel,
            connections: args.connections,
            merge: args.merge == Switch::On,
            correlation_aware: args.correlation_aware == Switch::On,
        }
    }
}

impl Default for IntegratorOptions {
    fn default() -> Self {
        IntegratorOptions {
            max_depth: None,
            light_paths_per_pixel: 1.0,
            connections: 1,
            merge: true,
            correlation_aware: true,
        }
    }
}

/// Builds the integrator the arguments ask for.
pub fn make_integrator(
    kind: IntegratorKind,
    scene: &Scene,
    o: &IntegratorOptions,
) -> anyhow::Result<Box<dyn Integrator>> {
    if !(o.light_paths_per_pixel >= 0.0 && o.light_paths_per_pixel.is_finite())
        || (kind == IntegratorKind::Lt && o.light_paths_per_pixel == 0.0)
    {
        bail!(
            "--light-paths-per-pixel must be positive (or 0 for bdpt and vcm: no light paths), got {}",
            o.light_paths_per_pixel
        );
    }
    let max_depth = match o.max_depth {
        None => None,
        Some(-1) => Some(u32::MAX),
        Some(d) if d >= 0 => Some(d.min(u32::MAX as i64) as u32),
        Some(d) => bail!("--max-depth must be -1 (unlimited) or non-negative, got {d}"),
    };
    let settings = PathSettings::from_scene(scene, max_depth);
    let (nu, c) = (o.light_paths_per_pixel, o.connections);
    Ok(match kind {
        IntegratorKind::Pt => Box::new(PathTracer { settings }),
        IntegratorKind::Lt => Box::new(LightTracer { settings, light_paths_per_pixel: nu }),
        IntegratorKind::Bdpt => Box::new(Bidir::bdpt(settings, nu, c)),
        IntegratorKind::Vcm => {
            let mask = MergeMask::Constant(if o.merge { 1.0 } else { 0.0 });
            Box::new(Bidir::vcm(settings, nu, c, MergeConfig { mask, correlation_aware: o.correlation_aware }))
        }
    })
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
    let integrator = make_integrator(args.integrator, &scene, &IntegratorOptions::from_args(args))?;
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
    let out = render(&scene, integrator.as_ref(), &opts, &|done, total| {
        bar.set_length(total);
        bar.set_position(done);
    })?;
    bar.finish_and_clear();
    write_outputs(&output, &scene, integrator.name(), &opts, &out)?;
    let samples = out.film.total_samples();
    let secs = out.elapsed.as_secs_f64();
    if out.film.non_finite > 0 {
        tracing::warn!(count = out.film.non_finite, "non-finite samples were zeroed");
    }
    println!(
        "{}: {} spp ({} samples) in {:.2} s, {:.0} samples/s, peak memory {:.0} MB -> {}",
        integrator.name(),
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

/// Writes the EXR and the PNG preview beside it.
pub fn write_outputs(
    output: &Path,
    scene: &Scene,
    integrator: &str,
    opts: &RenderOptions,
    out: &RenderOutput,
) -> anyhow::Result<()> {
    let rgb = out.film.average();
    let attributes = vec![
        ("tessera/integrator".to_string(), integrator.to_string()),
        ("tessera/spp".to_string(), out.spp.to_string()),
        ("tessera/seed".to_string(), opts.seed.to_string()),
        ("tessera/scene".to_string(), scene.path.display().to_string()),
        ("tessera/render_seconds".to_string(), format!("{:.3}", out.elapsed.as_secs_f64())),
    ];
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    write_exr(output, out.film.width, out.film.height, &rgb, Some(&out.film.count), &attributes)?;
    let png = output.with_extension("png");
    write_png(&png, out.film.width, out.film.height, &rgb)
        .with_context(|| format!("cannot write {}", png.display()))?;
    Ok(())
}
