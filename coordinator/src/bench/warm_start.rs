//! `tessera bench warm-start 4 scenes/caustic-glass/camera-move.xml`: what `--warm-start` saves
//! at equal time on a camera move. Every frame of `--frames` (the scene's `frame` parameter set
//! to N) renders for the same wall time with `--integrator`, once started cold and once from
//! the decision the warm chain's frame before ended on, one right after the other (which goes
//! first alternates per frame, so that a drifting host slows both alike). Each is scored by
//! relMSE against the frame's reference (top 0.1 % of pixel errors dropped, × elapsed / budget
//! as `equal-time` scores). References are rendered first by `--reference` for
//! `--reference-seconds` with another seed and kept in `--references` (NAME.NNNN.exr), so a
//! second run reuses them. Prints a line per frame and the geometric mean of cold / warm
//! (above 1: the warm start is better).

use super::geometric_mean;
use crate::options::{make_renderer, scene_name};
use std::path::{Path, PathBuf};
use std::time::Duration;
use tessera_common::emis::{EmisState, Strategy};
use tessera_common::film::compare::{DROPPED_FRACTION, relmse};
use tessera_common::film::exr::{ExrExtras, read_rgb, write_exr};
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::{LoadOptions, Scene};
use tessera_common::settings::{IntegratorName, RenderSettings, Renderer};
use tessera_link::frames::FrameRule;

/// Arguments of `tessera bench warm-start`.
#[derive(clap::Args, Debug, Clone)]
pub struct WarmStartArgs {
    /// Seconds per render.
    pub seconds: f64,
    /// The scene; its `frame` parameter moves it.
    pub scene: PathBuf,
    /// The frames.
    #[arg(long, default_value = "1-24")]
    pub frames: String,
    /// The integrator compared cold and warm.
    #[arg(long, default_value = "emis-vcm")]
    pub integrator: IntegratorName,
    /// The integrator of the references.
    #[arg(long, default_value = "vcm")]
    pub reference: IntegratorName,
    /// Seconds per reference.
    #[arg(long, default_value_t = 60.0)]
    pub reference_seconds: f64,
    /// Where references are kept.
    #[arg(long, default_value = "references")]
    pub references: PathBuf,
    /// Seed of the compared renders (the references use another).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Render threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
}

/// One timed render's score.
struct Scored {
    relmse: f64,
    iterations: u32,
    state: Option<EmisState>,
}

/// Runs `tessera bench warm-start`.
pub fn run(args: &WarmStartArgs) -> anyhow::Result<()> {
    let frames = tessera_link::frames::parse(&args.frames).map_err(anyhow::Error::msg)?;
    std::fs::create_dir_all(&args.references)?;
    let pattern = args.scene.to_string_lossy();
    let rule = FrameRule { scene: &pattern, param: "frame", seed_per_frame: false };
    let base = RenderSettings { integrator: args.integrator, seed: Some(args.seed), ..Default::default() };
    println!("{} s per render, {} frames of {}", args.seconds, frames.len(), args.scene.display());
    println!("frame  relMSE cold  relMSE warm  cold/warm  iterations cold/warm  warm started from");
    let (mut warm, mut ratios) = (None::<Strategy>, Vec::new());
    for (i, &n) in frames.iter().enumerate() {
        let (path, settings) = rule.frame(&base, n);
        let options = LoadOptions { defines: settings.define_map(), ..Default::default() };
        let scene = Scene::load_options(Path::new(&path), &options)?;
        let reference = reference(args, &scene, &settings, n)?;
        let started_from = warm.as_ref().map_or_else(|| "cold".to_string(), |s| format!("nu {}", s.nu));
        let (mut cold, mut hot) = (None, None);
        let order = if i % 2 == 0 { [false, true] } else { [true, false] };
        for warmed in order {
            let start = if warmed { warm.clone() } else { None };
            let scored = timed(args, &scene, &settings, start, &reference)?;
            *(if warmed { &mut hot } else { &mut cold }) = Some(scored);
        }
        let (cold, hot) = (cold.expect("rendered"), hot.expect("rendered"));
        let ratio = cold.relmse / hot.relmse;
        ratios.push(ratio);
        println!(
            "{n:>5}  {:>11.4e}  {:>11.4e}  {ratio:>9.3}  {:>9}/{:<10}  {started_from}",
            cold.relmse, hot.relmse, cold.iterations, hot.iterations
        );
        warm = hot.state.map(|s| s.strategy);
    }
    let after_first: Vec<f64> = ratios.iter().skip(1).copied().collect();
    println!(
        "geometric mean cold/warm: {:.3} over all {} frames, {:.3} over the {} that start warm",
        geometric_mean(&ratios),
        ratios.len(),
        geometric_mean(&after_first),
        after_first.len()
    );
    Ok(())
}

/// `settings` rendered for `args.seconds`, from `start` if given, scored against `reference`.
fn timed(
    args: &WarmStartArgs,
    scene: &Scene,
    settings: &RenderSettings,
    start: Option<Strategy>,
    reference: &[[f32; 3]],
) -> anyhow::Result<Scored> {
    let mut renderer = make_renderer(settings, scene)?;
    if let Renderer::Emis(config, _) = &mut renderer {
        config.warm_start = start;
    }
    let opts = RenderOptions {
        budget: Budget::Time(Duration::from_secs_f64(args.seconds)),
        seed: args.seed,
        threads: args.threads.unwrap_or(0),
        tile_size: 32,
    };
    let (out, state) = renderer.render(scene, &opts, &|_, _| {})?;
    let image = state.as_ref().map_or_else(|| out.film.average(), |e| e.image(&out.film));
    // error × time is what equal time compares; relMSE falls as 1 / time
    let relmse = relmse(&image, reference, DROPPED_FRACTION) * out.elapsed.as_secs_f64() / args.seconds;
    Ok(Scored { relmse, iterations: out.spp, state })
}

/// Frame `n`'s reference: read from `--references`, or rendered and kept there.
fn reference(args: &WarmStartArgs, scene: &Scene, settings: &RenderSettings, n: u32) -> anyhow::Result<Vec<[f32; 3]>> {
    let name = format!("{}-{}.{n:04}.exr", scene_name(&args.scene), args.reference);
    let path = args.references.join(name);
    if path.exists() {
        return Ok(read_rgb(&path)?.pixels);
    }
    let settings = RenderSettings { integrator: args.reference, ..settings.clone() };
    let renderer = make_renderer(&settings, scene)?;
    let opts = RenderOptions {
        budget: Budget::Time(Duration::from_secs_f64(args.reference_seconds)),
        seed: args.seed.wrapping_add(1_000_003),
        threads: args.threads.unwrap_or(0),
        tile_size: 32,
    };
    let (out, _) = renderer.render(scene, &opts, &|_, _| {})?;
    let image = out.film.average();
    write_exr(&path, out.film.width, out.film.height, &image, &ExrExtras::default())?;
    Ok(image)
}
