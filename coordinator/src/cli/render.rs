//! `tessera render`: renders a scene (or its `--frames`, one after another) on this machine
//! with no setup, writing an EXR (beauty RGB plus per-pixel sample counts) and an sRGB PNG
//! preview beside it (see [`crate::output`]).

use crate::options::{JobArgs, make_renderer};
use crate::output::{OutputPaths, Outputs, Provenance};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::time::Duration;
use tessera_common::emis::Strategy;
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::{LoadOptions, Scene, SceneLimits};
use tessera_common::settings::{Renderer, WorkLimits};
use tessera_common::texture::TextureLimits;

/// Arguments of `tessera render`.
#[derive(clap::Args, Debug, Clone)]
pub struct RenderArgs {
    /// The Mitsuba 3 scene file (XML, format 3.0.0).
    pub scene: PathBuf,
    /// Output EXR, with a PNG beside it (a NAME.png names the PNG, and the EXR goes to
    /// NAME.exr) [default: the scene's name in the working directory, e.g. cornell-box.exr].
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Integrator, samples or time, seed, options and scene parameters.
    #[command(flatten)]
    pub job: JobArgs,
    /// Render threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
    /// Memory the scene's decoded textures and environment maps may take, in MiB; a scene
    /// needing more fails to load with an error naming the image [default: 1024 per image,
    /// 4096 in all].
    #[arg(long, value_name = "MIB")]
    pub texture_budget: Option<u64>,
    /// Frames, rendered one after another.
    #[command(flatten)]
    pub frames: super::frames::FrameArgs,
}

/// Runs `tessera render`: one image, or each of `--frames` in order (with `--warm-start`,
/// an EMIS frame starting from the one before's final strategy).
pub fn render_command(args: &RenderArgs) -> anyhow::Result<()> {
    let settings = args.job.settings()?;
    if args.threads == Some(0) {
        return Err(crate::options::InvalidInput("--threads must be at least 1".into()).into());
    }
    let frames = args.frames.numbers()?;
    if args.frames.warm_start && settings.integrator.emis_method().is_none() {
        let message = format!("--warm-start needs an emis-* integrator, not {}", settings.integrator);
        return Err(crate::options::InvalidInput(message).into());
    }
    let output = args.output.clone().unwrap_or_else(|| super::frames::default_output(&args.scene, frames.is_some()));
    let Some(frames) = frames else {
        render_one(args, &args.scene, &settings, &OutputPaths::new(&output), None)?;
        return Ok(());
    };
    let pattern = args.scene.to_string_lossy();
    let rule = args.frames.rule(&pattern);
    let mut warm = None;
    for number in frames {
        let (scene, settings) = rule.frame(&settings, number);
        let out = OutputPaths::new(&super::frames::frame_path(&output, number));
        let decision = render_one(args, std::path::Path::new(&scene), &settings, &out, warm.take())?;
        warm = decision.filter(|_| args.frames.warm_start);
    }
    Ok(())
}

/// Renders `scene` with `settings` to `output`, an EMIS render starting from `warm` if given;
/// returns an EMIS render's final strategy.
fn render_one(
    args: &RenderArgs,
    scene: &std::path::Path,
    settings: &tessera_common::settings::RenderSettings,
    output: &OutputPaths,
    warm: Option<Strategy>,
) -> anyhow::Result<Option<Strategy>> {
    let textures = args.texture_budget.map_or_else(TextureLimits::default, |mib| TextureLimits::total(mib << 20));
    // the user's own scene on the user's own machine: as many triangles and as much memory
    // per tile as it takes, but no setting that overflows or asks for absurd work
    let limits = SceneLimits { textures, max_triangles: u64::MAX };
    let scene = Scene::load_options(scene, &LoadOptions { defines: settings.define_map(), limits, confine_to: None })?;
    let work = WorkLimits { max_tile_bytes: u64::MAX, ..WorkLimits::default() };
    settings.resolved(&scene).check_work(scene.camera.width, scene.camera.height, &work)?;
    let mut renderer = make_renderer(settings, &scene)?;
    if let Renderer::Emis(config, _) = &mut renderer {
        config.warm_start = warm;
    }
    let budget = match settings.time_s {
        Some(t) => Budget::Time(Duration::from_secs_f64(t)),
        None => Budget::Samples(settings.spp.unwrap_or(scene.spp)),
    };
    let opts = RenderOptions {
        budget,
        seed: settings.seed.unwrap_or(scene.seed),
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
    Outputs::new(&out.film, &provenance, emis.as_ref()).write_all(output, renderer.name(), out.spp)?;
    let samples = out.film.total_samples();
    let secs = out.elapsed.as_secs_f64();
    if out.film.non_finite > 0 {
        tracing::warn!(count = out.film.non_finite, "non-finite samples were zeroed");
    }
    println!(
        "{}: {} spp ({} samples) in {:.2} s, {:.0} samples/s, peak memory {:.0} MB (decoded textures {:.1} MB) -> {}",
        renderer.name(),
        out.spp,
        samples,
        secs,
        samples as f64 / secs.max(1e-9),
        peak_rss_bytes() as f64 / 1e6,
        scene.texture_bytes as f64 / 1e6,
        output.exr.display()
    );
    Ok(emis.map(|e| e.strategy))
}

/// Peak resident set size of this process so far: `VmHWM` of `/proc/self/status`, which starts
/// afresh at `exec`. `ru_maxrss` does not on Linux, so under `cargo run` it reported cargo's
/// own peak; it stays the fallback where `/proc` is missing (in KiB on Linux).
pub fn peak_rss_bytes() -> u64 {
    let hwm = std::fs::read_to_string("/proc/self/status").ok().and_then(|status| {
        let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
        line.trim().strip_suffix("kB")?.trim().parse::<u64>().ok()
    });
    if let Some(kib) = hwm {
        return kib * 1024;
    }
    // SAFETY: getrusage only writes into the struct we pass
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    usage.ru_maxrss.max(0) as u64 * 1024
}

#[cfg(test)]
mod tests {
    /// The peak follows this process's own memory: touching 256 MB raises it by as much.
    #[test]
    fn peak_memory_rises_with_touched_memory() {
        let before = super::peak_rss_bytes();
        assert!(before > 0);
        let block = vec![1u8; 256 << 20];
        std::hint::black_box(&block);
        let after = super::peak_rss_bytes();
        assert!(after >= before + (250 << 20), "{before} -> {after}");
    }
}
