//! `tessera render`: renders a scene on this machine with no setup, writing an EXR (beauty RGB
//! plus per-pixel sample counts) and an sRGB PNG preview beside it.

use crate::cli::RenderArgs;
use anyhow::{Context, anyhow, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tessera_common::film::exr::{Attribute, ExrExtras, write_exr};
use tessera_common::film::png::write_png;
use tessera_common::emis::EmisState;
use tessera_common::render::{Budget, RenderOptions, RenderOutput};
use tessera_common::scene::Scene;
use tessera_common::settings::{RenderSettings, Renderer, SettingsError};

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

/// The settings `tessera render`'s arguments ask for (spp, seed and time stay with the
/// command: they are resolved against the scene there).
pub fn settings_from_args(args: &RenderArgs) -> RenderSettings {
    let mut settings = RenderSettings { integrator: args.integrator.into(), ..RenderSettings::default() };
    args.mis.apply(&mut settings);
    settings
}

/// Builds the renderer of `settings` (the rules shared with the farm), naming the command-line
/// flag of a bad value.
pub fn make_renderer(settings: &RenderSettings, scene: &Scene) -> anyhow::Result<Renderer> {
    settings.make_renderer(scene).map_err(|e| match e {
        SettingsError::Invalid { field, message } => anyhow!("--{} {message}", field.replace('_', "-")),
        other => anyhow!(other),
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
    write_outputs(&output, &scene, renderer.name(), &opts, &out, emis.as_ref())?;
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

/// Writes the EXR and the PNG preview beside it; for EMIS also the merge-mask and
/// relative-moment layers, ν and c as attributes, a strategy PNG and the JSON report.
pub fn write_outputs(
    output: &Path,
    scene: &Scene,
    integrator: &str,
    opts: &RenderOptions,
    out: &RenderOutput,
    emis: Option<&EmisState>,
) -> anyhow::Result<()> {
    let rgb = out.film.average();
    let text = |k: &str, v: String| (format!("tessera/{k}"), Attribute::Text(v));
    let mut extras = ExrExtras {
        counts: Some(&out.film.count),
        layers: Vec::new(),
        attributes: vec![
            text("integrator", integrator.to_string()),
            text("spp", out.spp.to_string()),
            text("seed", opts.seed.to_string()),
            text("scene", scene.path.display().to_string()),
            text("render_seconds", format!("{:.3}", out.elapsed.as_secs_f64())),
        ],
    };
    let mask = emis.map(|e| e.merge_mask());
    if let (Some(e), Some(mask)) = (emis, &mask) {
        add_emis_extras(e, mask, &mut extras);
    }
    if let Some(dir) = output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    }
    write_exr(output, out.film.width, out.film.height, &rgb, &extras)?;
    let png = output.with_extension("png");
    write_png(&png, out.film.width, out.film.height, &rgb)
        .with_context(|| format!("cannot write {}", png.display()))?;
    if let (Some(e), Some(mask)) = (emis, &mask) {
        let strategy = output.with_extension("strategy.png");
        write_png(&strategy, out.film.width, out.film.height, &strategy_map(&rgb, mask))
            .with_context(|| format!("cannot write {}", strategy.display()))?;
        let report = output.with_extension("emis.json");
        let json = serde_json::json!({
            "integrator": integrator,
            "iterations": out.spp,
            "kept_from": e.kept_from,
            "final": { "nu": e.strategy.nu, "connections": e.strategy.connections },
            "candidates": e.candidates,
            "updates": e.reports,
        });
        std::fs::write(&report, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("cannot write {}", report.display()))?;
    }
    Ok(())
}

/// Adds what EMIS decided to an EXR: ν, c, the update count and the first kept iteration as
/// attributes, the merge mask
/// (`mask`, from [`EmisState::merge_mask`]) and the relative moment as layers.
pub fn add_emis_extras<'a>(e: &'a EmisState, mask: &'a [f32], extras: &mut ExrExtras<'a>) {
    extras.attributes.push(("tessera/emis_nu".into(), Attribute::Float(e.strategy.nu)));
    extras.attributes.push(("tessera/emis_connections".into(), Attribute::Int(e.strategy.connections as i32)));
    extras.attributes.push(("tessera/emis_updates".into(), Attribute::Int(e.updates_done as i32)));
    // a path-tracing start's discarded iterations: the image holds iterations kept_from.. only
    extras.attributes.push(("tessera/emis_kept_from".into(), Attribute::Int(e.kept_from as i32)));
    extras.layers.push(("merge_mask", mask));
    if let Some(relative) = &e.relative_moment {
        extras.layers.push(("relative_moment", &relative.data));
    }
}

/// The strategy as a picture: the image's luminance in grey, tinted orange by the merge
/// probability χ (ν and c are image-wide and in the EXR attributes and the report).
fn strategy_map(rgb: &[[f32; 3]], mask: &[f32]) -> Vec<[f32; 3]> {
    const ORANGE: [f32; 3] = [1.0, 0.35, 0.0];
    rgb.iter()
        .zip(mask)
        .map(|(c, &chi)| {
            let grey = (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]).clamp(0.0, 1.0) * 0.6 + 0.05;
            let t = 0.7 * chi.clamp(0.0, 1.0);
            [0, 1, 2].map(|k| grey * (1.0 - t) + ORANGE[k] * t)
        })
        .collect()
}
