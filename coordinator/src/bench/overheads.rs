//! `tessera bench overheads`: what EMIS costs beyond its integrator. Moment accumulation as a
//! fraction of a pilot iteration's time (pilot iterations with and without the estimator,
//! interleaved), the updates a render runs (denoiser and optimiser; a path-tracing start's,
//! a bidirectional strategy's, and with the guided Ī) at 256² and 1920×1080 on synthetic
//! inputs, and the memory of the moment buffers. With `--path-tracing`: what recording moments costs
//! while path tracing is the strategy, against `pt` itself.

use super::{SceneArgs, cpu_seconds};
use crate::options::scene_name;
use std::time::Instant;
use tessera_common::emis::cost::PathStatistics;
use tessera_common::emis::denoise::{Guides, ImageEstimate, denoised_intensity};
use tessera_common::emis::filter::Image;
use tessera_common::emis::moments::MomentBuffer;
use tessera_common::emis::optimize::{MergeScope, OptimizerInput, optimize};
use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, GUIDE_ITERATIONS, Strategy, render_iterations};
use tessera_common::integrator::PathSettings;
use tessera_common::sampler::Sampler;
use tessera_common::scene::Scene;

/// Arguments of `tessera bench overheads`.
#[derive(clap::Args, Debug, Clone)]
pub struct OverheadsArgs {
    /// Scenes and threads.
    #[command(flatten)]
    pub scenes: SceneArgs,
    /// Rounds of the accumulation measurement (medians over them) and optimiser runs (the
    /// fastest kept).
    #[arg(long, default_value_t = 2)]
    pub repeats: u32,
    /// Only the optimiser and denoiser runs, no pilot renders (for profiling the update).
    #[arg(long)]
    pub update_only: bool,
    /// Instead of the pilot's accumulation: an iteration recording moments under path
    /// tracing (the VCM engine with χ = 0, with the reduced and the full candidate set)
    /// against `pt`'s iteration and the engine's without moments; and `pt`'s iterations in
    /// EMIS's calls against one `pt` pass.
    #[arg(long, conflicts_with = "update_only")]
    pub path_tracing: bool,
}

/// What [`accumulation_overhead`] measured for one pilot.
struct Overhead {
    /// Fastest round's wall time per iteration: without moments, with moments and guides, with
    /// moments alone.
    best: [f64; 3],
    /// Medians over rounds of the two overheads (with guides, alone), as ratios of wall time.
    wall: [f64; 2],
    /// The same as ratios of process CPU time (user + system): time the host's other load
    /// takes from this process does not count, its own work does.
    cpu: [f64; 2],
}

/// Pilot iteration time without moment accumulation, with it in the first
/// [`GUIDE_ITERATIONS`] (which also sum the denoiser's guides where the guided Ī needs them),
/// and with it after them: the calls a render makes ([`render_iterations`] without and with
/// collection), so the estimator's buffer and its hand-over are counted. Each overhead is the median over
/// `repeats` rounds of a ratio of runs made back to back within one round (robust to the
/// host's load changing between rounds, which separate fastest times are not).
fn accumulation_overhead(scene: &Scene, method: EmisMethod, iterations: u32, repeats: u32) -> Overhead {
    // the guided Ī, so that the first iterations record the guides (the default Ī does not)
    let config = EmisConfig { denoise: ImageEstimate::Guided.settings(), ..EmisConfig::own_pilot(method) };
    let settings = PathSettings::from_scene(scene, None);
    let strategy = Strategy::pilot(method);
    let mut best = [f64::INFINITY; 3];
    let (mut wall, mut cpu) = ([Vec::new(), Vec::new()], [Vec::new(), Vec::new()]);
    for r in 0..repeats {
        let (mut round_wall, mut round_cpu) = ([0.0; 3], [0.0; 3]);
        // the same iterations' samples for the plain and the guided run; the unguided run's
        // come after the guided iterations (a different sample, the same expected work)
        let guided = (r * iterations) % GUIDE_ITERATIONS;
        let guided = guided..(guided + iterations).min(GUIDE_ITERATIONS);
        let unguided = GUIDE_ITERATIONS + r * iterations..GUIDE_ITERATIONS + (r + 1) * iterations;
        for (i, (samples, collect)) in
            [(guided.clone(), None), (guided, Some(CandidateSet::Full)), (unguided, Some(CandidateSet::Full))]
                .into_iter()
                .enumerate()
        {
            let (t, c) = (Instant::now(), cpu_seconds());
            let n = samples.len() as f64;
            std::hint::black_box(render_iterations(scene, settings, &config, &strategy, 1, samples, collect));
            round_wall[i] = t.elapsed().as_secs_f64() / n;
            round_cpu[i] = (cpu_seconds() - c) / n;
            best[i] = best[i].min(round_wall[i]);
        }
        for k in 0..2 {
            wall[k].push(round_wall[k + 1] / round_wall[0]);
            cpu[k].push(round_cpu[k + 1] / round_cpu[0]);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let [w0, w1] = &mut wall;
    let [c0, c1] = &mut cpu;
    Overhead { best, wall: [median(w0), median(w1)], cpu: [median(c0), median(c1)] }
}

/// The updates a render runs, each timed on synthetic inputs: which candidates it chooses
/// from and the Ī it makes the moments relative to.
#[derive(Clone, Copy)]
enum UpdateKind {
    /// A path-tracing start's update (the default pilot): the reduced set, the guided Ī.
    PathTracingStart,
    /// Every update after a restart, and the bidirectional pilot's: the full set, the default Ī.
    Bidirectional,
    /// The full set with the guided Ī (`--emis-image denoised`): the dearest update.
    BidirectionalGuided,
}

impl UpdateKind {
    const ALL: [UpdateKind; 3] = [Self::PathTracingStart, Self::Bidirectional, Self::BidirectionalGuided];

    fn label(self) -> &'static str {
        match self {
            Self::PathTracingStart => "path-tracing start (reduced set, guided Ī)",
            Self::Bidirectional => "bidirectional (full set, default Ī)",
            Self::BidirectionalGuided => "bidirectional, --emis-image denoised (full set, guided Ī)",
        }
    }
}

/// One denoiser and one optimiser run of the VCM update `kind` on synthetic inputs of
/// `w × h`: (optimiser seconds, denoiser seconds, candidates, moment bytes).
fn update_time(w: u32, h: u32, kind: UpdateKind) -> (f64, f64, usize, usize) {
    let config = EmisConfig::own_pilot(EmisMethod::Vcm);
    let set = match kind {
        UpdateKind::PathTracingStart => CandidateSet::Reduced,
        UpdateKind::Bidirectional | UpdateKind::BidirectionalGuided => CandidateSet::Full,
    };
    let denoise = match kind {
        UpdateKind::BidirectionalGuided => &ImageEstimate::Guided.settings(),
        _ => config.denoise_of(set),
    };
    let candidates = config.candidates_of(set);
    let mut moments = MomentBuffer::new(w, h, candidates.len());
    for (i, v) in moments.sums.iter_mut().enumerate() {
        *v = Sampler::for_pixel(9, i as u32, 0).next_1d() + 0.01;
    }
    moments.iterations = 1;
    let n = (w * h) as usize;
    let color: Vec<[f32; 3]> = (0..n).map(|i| [Sampler::for_pixel(3, i as u32, 0).next_1d(); 3]).collect();
    let albedo = vec![[0.5f32; 3]; n];
    let normal: Vec<[f32; 3]> = (0..n).map(|i| if i % 7 == 0 { [1.0, 0.0, 0.0] } else { [0.0, 0.0, 1.0] }).collect();
    let depth = vec![1.0f32; n];
    let t = Instant::now();
    let image = denoised_intensity(
        w as usize,
        h as usize,
        &color,
        &Guides { albedo: &albedo, normal: &normal, depth: &depth },
        denoise,
    );
    let denoise_s = t.elapsed().as_secs_f64();
    let reduced = set == CandidateSet::Reduced;
    let t = Instant::now();
    let decision = optimize(&OptimizerInput {
        // a restart after the first of 64 iterations, as a path-tracing start's first update
        restart_share: if reduced { 1.0 / 64.0 } else { 0.0 },
        incumbent: None,
        candidates: &candidates,
        moments: &moments,
        image: &Image::from_data(w as usize, h as usize, image.data),
        statistics: PathStatistics::default(),
        constants: config.constants,
        filters: config.filters,
        merge_scope: if reduced { MergeScope::Global } else { MergeScope::PerPixel },
        connection_scope: config.connection_scope,
    });
    std::hint::black_box(decision);
    (t.elapsed().as_secs_f64(), denoise_s, candidates.len(), moments.sums.len() * 4)
}

/// Runs `tessera bench overheads`.
pub fn run(args: &OverheadsArgs) -> anyhow::Result<()> {
    let pool = args.scenes.pool()?;
    if args.path_tracing {
        return super::pt_recording::table(&args.scenes, args.repeats.max(1), &pool);
    }
    if !args.update_only {
        accumulation_table(args, &pool)?;
    }
    println!(
        "\nEMIS updates (VCM candidates, synthetic moments): denoiser of the pilot image, then optimiser, best of {} runs:",
        args.repeats.max(1)
    );
    for (w, h) in [(256u32, 256u32), (1920, 1080)] {
        for kind in UpdateKind::ALL {
            let runs: Vec<_> = (0..args.repeats.max(1)).map(|_| pool.install(|| update_time(w, h, kind))).collect();
            let best = |f: &dyn Fn(&(f64, f64, usize, usize)) -> f64| runs.iter().map(f).fold(f64::INFINITY, f64::min);
            let (update, opt, den) = (best(&|r| r.0 + r.1), best(&|r| r.0), best(&|r| r.1));
            let (candidates, bytes) = (runs[0].2, runs[0].3);
            println!(
                "{w}x{h}, {}: update {:.1} ms (optimiser {:.1} ms, denoiser {:.1} ms); {candidates} candidates, moment buffer {:.1} MB (the optimiser holds a filtered copy of the same size)",
                kind.label(),
                update * 1e3,
                opt * 1e3,
                den * 1e3,
                bytes as f64 / 1e6,
            );
        }
    }
    Ok(())
}

/// The moment accumulation table: one row per scene.
fn accumulation_table(args: &OverheadsArgs, pool: &rayon::ThreadPool) -> anyhow::Result<()> {
    let scenes = args.scenes.scenes()?;
    println!(
        "moment accumulation (51 VCM / 26 BDPT candidates), {} rounds of 2 iterations: time per pilot iteration (fastest round) without moments, with moments and the denoiser's guides (the first {GUIDE_ITERATIONS} iterations), with moments alone (the later ones); overheads are medians over rounds of ratios within a round, of wall time and of process CPU time:",
        args.repeats.max(1)
    );
    println!(
        "| scene | vcm pilot ms/it | + moments, guides | + moments | overhead, guides (wall / CPU) | overhead, moments (wall / CPU) | bdpt pilot ms/it | + moments, guides | + moments | overhead, guides (wall / CPU) | overhead, moments (wall / CPU) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let percent = |ratio: f64| (ratio - 1.0) * 100.0;
    for path in &scenes {
        let scene = Scene::load(path)?;
        let mut cells = Vec::new();
        for method in [EmisMethod::Vcm, EmisMethod::Bdpt] {
            let o = pool.install(|| accumulation_overhead(&scene, method, 2, args.repeats.max(1)));
            cells.push(format!(
                "{:.0} | {:.0} | {:.0} | {:.0} % / {:.0} % | {:.0} % / {:.0} %",
                o.best[0] * 1e3,
                o.best[1] * 1e3,
                o.best[2] * 1e3,
                percent(o.wall[0]),
                percent(o.cpu[0]),
                percent(o.wall[1]),
                percent(o.cpu[1])
            ));
        }
        println!("| {} | {} |", scene_name(path), cells.join(" | "));
    }
    Ok(())
}
