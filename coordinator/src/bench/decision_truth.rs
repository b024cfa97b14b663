//! `tessera bench decision-truth`: the brute-force truth of the decision-quality tests
//! (`common/tests/emis_decisions.rs`; docs/decisions/0018-decision-quality-tests.md), written
//! as the small JSON file the tests read ([`DecisionTruth`]).
//!
//! Per scene, rendered at `--size` (square; the 256² Mitsuba reference is averaged over
//! 2 × 2 blocks, exact for its box filter):
//!
//! 1. a `vcm` pilot (ν = 1, c = 1, χ = 1) collects every candidate's moments for `--pilot`
//!    iterations; the optimiser's pixel level turns them, with the converged reference as Ī,
//!    into the merge mask every bidirectional candidate below renders with (the image-level
//!    choice is judged with the mask held fixed; the tests check the mask on its own);
//! 2. every image-level candidate of `emis-vcm` (25 (ν, c) and path tracing) renders
//!    `iterations` iterations, one call each, for each of `--seeds` seeds, and its per-pixel
//!    per-iteration variance relative to the reference, pooled over the seeds, is averaged
//!    as relMSE averages (once over every pixel, once without the top 0.1 % as the equal-time
//!    benchmark drops them): the relMSE × iterations it converges to, free of the reference's
//!    own noise and of bias;
//! 3. each candidate is timed (CPU seconds per iteration) the way a final pass renders it,
//!    in the calls of [`final_call`], path tracing by `pt`, on `--timing-threads`
//!    threads (one by default: CPU time then counts no thread waiting at a barrier for a
//!    sibling that another process descheduled); rounds alternate over the candidates and the
//!    least time counts, as the machine's load drifts.
//!
//! Seconds are measured once here and cached, because a test that times renders on a shared
//! machine is not reproducible.

use super::{SceneArgs, cpu_seconds};
use crate::options::scene_name;
use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tessera_common::emis::denoise::DenoiseSettings;
use tessera_common::emis::filter::Image;
use tessera_common::emis::optimize::{ConnectionScope, MergeScope, OptimizerInput, optimize};
use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, calls, final_call, render_iterations};
use tessera_common::film::Film;
use tessera_common::film::compare::{DROPPED_FRACTION, mean_without_top, relmse};
use tessera_common::integrator::PathSettings;
use tessera_common::integrator::path::connections::Connections;
use tessera_common::integrator::path::merge::MergeMask;
use tessera_common::scene::Scene;
use tessera_testing::decision_truth::{CandidateTruth, DecisionTruth, SceneTruth, SeedVariance};

/// Arguments of `tessera bench decision-truth`.
#[derive(clap::Args, Debug, Clone)]
pub struct DecisionTruthArgs {
    /// Scenes and threads.
    #[command(flatten)]
    pub scenes: SceneArgs,
    /// Side of the square image the scenes are rendered at.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Iterations each candidate renders for its variance, per seed.
    #[arg(long, default_value_t = 256)]
    pub iterations: u32,
    /// Seeds each candidate renders its iterations with; every seed's iterations are pooled.
    #[arg(long, default_value_t = 3)]
    pub seeds: u32,
    /// Iterations of the pilot that chooses the merge mask.
    #[arg(long, default_value_t = 64)]
    pub pilot: u32,
    /// Iterations per timing round.
    #[arg(long, default_value_t = 32)]
    pub timed: u32,
    /// Timing rounds over all candidates.
    #[arg(long, default_value_t = 3)]
    pub rounds: u32,
    /// Threads of the timing renders.
    #[arg(long, default_value_t = 1)]
    pub timing_threads: usize,
    /// The merge mask every bidirectional candidate renders with: the pilot's pixel-level
    /// decision (what the tests judge), merging in every pixel (vanilla `vcm`'s χ = 1) or in
    /// none (BDPT), to see what the mask itself gains.
    #[arg(long, value_enum, default_value = "pilot")]
    pub mask: MaskArg,
    /// Only these image-level candidates, as `ν:c` pairs (`0:0` is path tracing); all of
    /// them by default. A partial run is for diagnosis: the tests need every candidate.
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// The JSON file to write.
    #[arg(long, short = 'o', default_value = DEFAULT_OUTPUT)]
    pub output: PathBuf,
}

/// The truth the decision-quality tests read.
const DEFAULT_OUTPUT: &str = "common/tests/data/emis-decision-truth.json";

/// The merge mask of `--mask`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskArg {
    /// The pilot's pixel-level decision, dilated and blurred as the optimiser makes it.
    Pilot,
    /// χ = 1 in every pixel.
    Everywhere,
    /// χ = 0 in every pixel: BDPT.
    Nowhere,
}

/// The (ν, c) pairs of `--only`, each once.
fn parse_only(only: &[String]) -> anyhow::Result<Vec<(f32, u32)>> {
    let mut pairs: Vec<(f32, u32)> = Vec::new();
    for pair in only {
        let (nu, c) = pair.split_once(':').with_context(|| format!("--only {pair}: expected ν:c"))?;
        let parsed = (
            nu.parse().with_context(|| format!("--only {pair}: ν"))?,
            c.parse().with_context(|| format!("--only {pair}: c"))?,
        );
        if !pairs.contains(&parsed) {
            pairs.push(parsed);
        }
    }
    Ok(pairs)
}

/// The first seed of the candidates' variance renders (the next `--seeds` − 1 follow it).
const TRUTH_SEED: u64 = 1000;

/// One scene at the benchmark's size with its reference.
struct Subject {
    name: String,
    scene: Scene,
    settings: PathSettings,
    reference: Vec<[f32; 3]>,
    config: EmisConfig,
}

impl Subject {
    fn load(path: &Path, size: u32) -> anyhow::Result<Subject> {
        let scene = Scene::load(path)?;
        let (w, h) = (scene.camera.width, scene.camera.height);
        if !scene.film.filter.is_box() || w % size != 0 || h != w {
            bail!("{}: needs a square box-filtered film that {size} divides, not {w}×{h}", path.display());
        }
        let reference = tessera_common::film::exr::read_rgb(&path.with_file_name("reference.exr"))?;
        let scene = scene.with_resolution(size, size).context("same proportions")?;
        let reference = downsample(&reference.pixels, w as usize, (w / size) as usize);
        let settings = PathSettings::from_scene(&scene, None);
        Ok(Subject {
            name: scene_name(path),
            scene,
            settings,
            reference,
            config: EmisConfig::own_pilot(EmisMethod::Vcm),
        })
    }

    fn pixels(&self) -> u32 {
        self.scene.camera.width * self.scene.camera.height
    }
}

/// A `side × side` image averaged over `factor × factor` blocks: with a box filter each
/// pixel of the smaller image is exactly the mean of its block.
fn downsample(pixels: &[[f32; 3]], side: usize, factor: usize) -> Vec<[f32; 3]> {
    let small = side / factor;
    let mut out = vec![[0.0f32; 3]; small * small];
    for y in 0..side {
        for x in 0..side {
            let o = &mut out[(y / factor) * small + x / factor];
            for c in 0..3 {
                o[c] += pixels[y * side + x][c] / (factor * factor) as f32;
            }
        }
    }
    out
}

/// The fixed merge mask, and the cost model's image-level cost of each (ν, c) with it, in the
/// optimiser's order of groups.
fn reference_decision(s: &Subject, iterations: u32, pool: &rayon::ThreadPool) -> (Vec<f32>, Vec<(f32, u32, f64)>) {
    let (w, h) = (s.scene.camera.width as usize, s.scene.camera.height as usize);
    let pilot = Strategy::pilot(EmisMethod::Vcm);
    let (_, data) = pool.install(|| {
        render_iterations(&s.scene, s.settings, &s.config, &pilot, 7, 0..iterations, Some(CandidateSet::Full))
    });
    let data = data.expect("invariant: the pilot collects moments");
    let intensity = Image::from_data(w, h, s.reference.iter().map(|p| (p[0] + p[1] + p[2]) / 3.0).collect())
        .box_blur(DenoiseSettings::default().final_box);
    let candidates = s.config.candidates_of(CandidateSet::Full);
    let decision = pool.install(|| {
        optimize(&OptimizerInput {
            restart_share: 0.0,
            incumbent: None,
            candidates: &candidates,
            moments: &data.moments,
            image: &intensity,
            statistics: data.statistics.statistics(s.pixels()),
            constants: s.config.constants,
            filters: s.config.filters,
            merge_scope: MergeScope::PerPixel,
            connection_scope: ConnectionScope::Image,
        })
    });
    let costs = decision.scores.iter().map(|g| (g.nu, g.connections.unwrap_or(0), g.cost)).collect();
    (decision.merge_mask.data, costs)
}

fn strategy(nu: f32, connections: u32, mask: &Arc<Vec<f32>>) -> Strategy {
    if nu == 0.0 {
        return Strategy::path_tracing();
    }
    Strategy { nu, connections: Connections::Fixed(connections), merge: Some(MergeMask::PerPixel(mask.clone())) }
}

/// A candidate's relative variance: every seed's and the pooled figures.
struct Variance {
    pooled: SeedVariance,
    seeds: Vec<SeedVariance>,
    relmse_k: f64,
}

/// Per-iteration variance relative to the reference from `iterations` single-iteration
/// renders for each of `seeds` seeds: each seed's, all of them pooled (every iteration has the
/// same expectation), and relMSE × iterations of the mean image.
fn relative_variance(
    s: &Subject,
    strategy: &Strategy,
    iterations: u32,
    seeds: u32,
    pool: &rayon::ThreadPool,
) -> Variance {
    let n = s.reference.len();
    // per seed: Σx and Σx² per pixel and channel
    let mut sums = vec![vec![[0.0f64; 6]; n]; seeds as usize];
    for (i, sums) in sums.iter_mut().enumerate() {
        let seed = TRUTH_SEED + i as u64;
        for it in 0..iterations {
            let (accum, _) =
                pool.install(|| render_iterations(&s.scene, s.settings, &s.config, strategy, seed, it..it + 1, None));
            let mut film = Film::new(&s.scene.film);
            film.merge_tile(&accum);
            for (acc, p) in sums.iter_mut().zip(film.average()) {
                for c in 0..3 {
                    acc[c] += p[c] as f64;
                    acc[3 + c] += (p[c] as f64).powi(2);
                }
            }
        }
    }
    let variance = |parts: &[Vec<[f64; 6]>]| -> SeedVariance {
        let k = (iterations as usize * parts.len()) as f64;
        let per_pixel: Vec<f64> = s
            .reference
            .iter()
            .enumerate()
            .map(|(j, r)| {
                (0..3)
                    .map(|c| {
                        let (sx, sxx) =
                            parts.iter().fold((0.0, 0.0), |(a, b), part| (a + part[j][c], b + part[j][3 + c]));
                        let var = ((sxx - sx * sx / k) / (k - 1.0)).max(0.0);
                        var / ((r[c] as f64).powi(2) + 1e-4)
                    })
                    .sum::<f64>()
                    / 3.0
            })
            .collect();
        SeedVariance {
            relative_variance: per_pixel.iter().sum::<f64>() / n as f64,
            trimmed_variance: mean_without_top(per_pixel, DROPPED_FRACTION),
        }
    };
    let k = (iterations * seeds) as f64;
    let mean: Vec<[f32; 3]> =
        (0..n).map(|j| std::array::from_fn(|c| (sums.iter().map(|part| part[j][c]).sum::<f64>() / k) as f32)).collect();
    Variance {
        pooled: variance(&sums),
        seeds: sums.chunks(1).map(variance).collect(),
        relmse_k: relmse(&mean, &s.reference, 0.0) * k,
    }
}

/// CPU seconds per iteration of `strategy`, rendered as a final pass renders it.
fn seconds_per_iteration(s: &Subject, strategy: &Strategy, iterations: u32, pool: &rayon::ThreadPool) -> f64 {
    let started = cpu_seconds();
    let pixels = s.scene.camera.width as u64 * s.scene.camera.height as u64;
    for call in calls(0..iterations, |r| final_call(r, strategy.nu, pixels)) {
        pool.install(|| render_iterations(&s.scene, s.settings, &s.config, strategy, 2000, call, None));
    }
    (cpu_seconds() - started) / iterations as f64
}

fn measure_scene(
    s: &Subject,
    args: &DecisionTruthArgs,
    only: &[(f32, u32)],
    pool: &rayon::ThreadPool,
) -> anyhow::Result<SceneTruth> {
    let (mut mask, mut groups) = reference_decision(s, args.pilot, pool);
    match args.mask {
        MaskArg::Pilot => {}
        MaskArg::Everywhere => mask.iter_mut().for_each(|v| *v = 1.0),
        MaskArg::Nowhere => mask.iter_mut().for_each(|v| *v = 0.0),
    }
    if !only.is_empty() {
        groups.retain(|&(nu, c, _)| only.contains(&(nu, c)));
        if groups.len() != only.len() {
            bail!("--only: {} of the {} pairs are not image-level candidates", only.len() - groups.len(), only.len());
        }
    }
    let timing = rayon::ThreadPoolBuilder::new().num_threads(args.timing_threads).build()?;
    let mean_merge_probability = mask.iter().map(|&v| v as f64).sum::<f64>() / mask.len() as f64;
    let mask = Arc::new(mask);
    let mut seconds = vec![f64::INFINITY; groups.len()];
    for _ in 0..args.rounds {
        for (t, &(nu, connections, _)) in seconds.iter_mut().zip(&groups) {
            *t = t.min(seconds_per_iteration(s, &strategy(nu, connections, &mask), args.timed, &timing));
        }
    }
    let candidates = groups
        .iter()
        .zip(&seconds)
        .map(|(&(nu, connections, model_cost), &seconds)| {
            let v = relative_variance(s, &strategy(nu, connections, &mask), args.iterations, args.seeds, pool);
            let c = CandidateTruth {
                nu,
                connections,
                relative_variance: v.pooled.relative_variance,
                trimmed_variance: v.pooled.trimmed_variance,
                seeds: v.seeds,
                relmse_k: v.relmse_k,
                seconds,
                model_cost,
            };
            let per_seed = |f: fn(&SeedVariance) -> f64| {
                c.seeds.iter().map(|v| format!("{:.3e}", f(v))).collect::<Vec<_>>().join(" ")
            };
            println!(
                "| {} | {nu} | {connections} | {:.4e} | {} | {:.4e} | {} | {:.4e} | {:.3} | {:.2} | {:.4e} |",
                s.name,
                c.trimmed_variance,
                per_seed(|v| v.trimmed_variance),
                c.relative_variance,
                per_seed(|v| v.relative_variance),
                c.relmse_k,
                c.seconds * 1e3,
                c.model_cost,
                c.work_normalised()
            );
            c
        })
        .collect();
    Ok(SceneTruth { scene: s.name.clone(), mean_merge_probability, candidates })
}

/// Runs `tessera bench decision-truth`.
pub fn run(args: &DecisionTruthArgs) -> anyhow::Result<()> {
    let pool = args.scenes.pool()?;
    if args.iterations < 2 || args.seeds == 0 {
        bail!("--iterations must be at least 2 and --seeds at least 1, for a variance per seed");
    }
    let only = parse_only(&args.only)?;
    // a diagnostic run would otherwise replace the truth the decision tests read
    let diagnostic = args.mask != MaskArg::Pilot || !only.is_empty();
    if diagnostic && args.output == Path::new(DEFAULT_OUTPUT) {
        bail!("a run with --mask other than pilot or with --only is not the tests' truth: name another file with -o");
    }
    let mut truth = DecisionTruth {
        width: args.size,
        height: args.size,
        iterations: args.iterations,
        seeds: args.seeds,
        timed_iterations: args.timed,
        pilot_iterations: args.pilot,
        command: std::env::args().skip(1).collect::<Vec<_>>().join(" "),
        scenes: Vec::new(),
    };
    println!(
        "| scene | ν | c | trimmed variance | per seed | relative variance | per seed | relMSE × K | ms/iteration | model cost | relMSE × time |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for path in args.scenes.scenes()? {
        let subject = Subject::load(&path, args.size)?;
        let scene = measure_scene(&subject, args, &only, &pool)?;
        if let Some(best) = scene.best() {
            println!(
                "{}: best ν {} c {}, mask mean χ {:.3}",
                scene.scene, best.nu, best.connections, scene.mean_merge_probability
            );
        }
        truth.scenes.push(scene);
    }
    let json = serde_json::to_string_pretty(&truth)?;
    std::fs::write(&args.output, json + "\n").with_context(|| format!("writing {}", args.output.display()))?;
    println!("wrote {}", args.output.display());
    Ok(())
}
