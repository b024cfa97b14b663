//! `tessera bench ground-truth K` (docs/emis.md, checklist 15 and D3): do the pilot's
//! moments choose what the true variances would choose?
//!
//! Per scene: a `vcm` pilot (ν = 1, c = 1, χ = 1, correlation-aware; `--pilot`
//! iterations) runs the moment estimator. Then every candidate of a reduced set (ν ∈ {0.25, 1, 2} × c ∈ {0, 1, 4} × merging
//! off / everywhere, plus path tracing: 19) renders K iterations itself, timed the way a final
//! pass renders it (path tracing by the `pt` integrator).
//!
//! The truth is the candidate's relMSE against the reference × K, times its measured CPU time
//! per iteration: the work-normalised error an equal-time render sees. It is taken with no
//! pixel dropped; the table also shows it with the top 0.1 % of pixel errors dropped, as the
//! equal-time benchmark measures, which at small K hides rare large errors (caustics seen by
//! path tracing) that a long render does not drop. Predictions are image-level relative
//! moments the way the optimiser forms them (relative to the reference, then box radius 3,
//! outliers above the 99.9 % quantile zeroed; with
//! `--moment-outliers shared`, the shared part's outliers first, as [`OutlierStage`] says, the
//! shared part being the minimum over the reduced set; with `each`, each candidate's own),
//! times the cost model of `--cost-model`: from the candidate's own samples (Σ y², "measured")
//! and from the pilot.
//!
//! Reported per prediction: the candidate it chooses and its **regret**, the true work-normalised
//! error of that choice over the best candidate's (1 = perfect), plus how well its predictions
//! correlate with the truth over all candidates (Spearman ρ). Each scene also ends with one
//! `json:` line holding every figure, for analyses beyond the table.

use super::{SceneArgs, cpu_seconds, geometric_mean};
use crate::options::scene_name;
use std::path::Path;
use tessera_common::emis::candidate::Candidate;
use tessera_common::emis::cost::{CostModel, StatisticsSums, pixel_cost};
use tessera_common::emis::estimator::MomentEstimator;
use tessera_common::emis::filter::Image;
use tessera_common::emis::moments::MomentBuffer;
use tessera_common::emis::optimize::{OutlierStage, filter_moments, remove_each_outliers, remove_shared_outliers};
use tessera_common::emis::{EmisConfig, EmisMethod, Strategy, render_iterations};
use tessera_common::film::compare::{DROPPED_FRACTION, relmse};
use tessera_common::film::{Film, Rect, TileAccum};
use tessera_common::integrator::path::connections::Connections;
use tessera_common::integrator::path::merge::MergeMask;
use tessera_common::integrator::{Integrator, PathSettings, TileRequest};
use tessera_common::scene::Scene;

/// Arguments of `tessera bench ground-truth`.
#[derive(clap::Args, Debug, Clone)]
pub struct GroundTruthArgs {
    /// Iterations each candidate renders.
    pub iterations: u32,
    /// Scenes and threads.
    #[command(flatten)]
    pub scenes: SceneArgs,
    /// Iterations of the pilot.
    #[arg(long, default_value_t = 4)]
    pub pilot: u32,
    /// The cost heuristic's constants.
    #[arg(long, value_enum, default_value = "calibrated")]
    pub cost_model: CostModel,
    /// The outlier rejection of the predicted moments.
    #[arg(long, value_enum, default_value = "shared")]
    pub moment_outliers: OutlierStage,
}

fn reduced_candidates() -> Vec<Candidate> {
    let mut v = Vec::new();
    for nu in [0.25f32, 1.0, 2.0] {
        for connections in [0u32, 1, 4] {
            for merge in [false, true] {
                v.push(Candidate { nu, connections, merge });
            }
        }
    }
    v.push(Candidate::PATH_TRACING);
    v
}

/// Image-level relative figure of a per-pixel moment, as the optimiser forms it: / (ref² +
/// 1e-4), then box 3, outliers above the 99.9 % quantile zeroed, mean over pixels with a
/// non-zero reference.
fn relative_mean(w: usize, h: usize, per_pixel: Vec<f32>, reference: &[f32]) -> f64 {
    let norm: Vec<f32> = reference.iter().map(|&r| r * r + 1e-4).collect();
    let filtered = filter_moments(&Image::from_data(w, h, per_pixel), &norm, 3);
    let basis: Vec<f32> = filtered.data.iter().zip(&norm).map(|(&m, &n)| m / n).collect();
    let basis = Image::from_data(w, h, basis);
    let threshold = basis.histogram_quantile(0.999);
    (0..w * h)
        .filter(|&p| reference[p] > 0.0)
        .map(|p| {
            let m = filtered.data[p];
            if basis.data[p] > threshold && m.is_finite() { 0.0 } else { (m / norm[p]) as f64 }
        })
        .sum::<f64>()
        / (w * h) as f64
}

fn moments_of(buffer: &MomentBuffer, candidate: usize) -> Vec<f32> {
    (0..buffer.width * buffer.height).map(|p| buffer.moment(p, candidate) as f32).collect()
}

/// Spearman rank correlation (ties broken by order).
fn spearman(a: &[f64], b: &[f64]) -> f64 {
    let rank = |v: &[f64]| {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
        let mut r = vec![0.0; v.len()];
        for (k, &i) in idx.iter().enumerate() {
            r[i] = k as f64;
        }
        r
    };
    let (ra, rb) = (rank(a), rank(b));
    let n = a.len() as f64;
    let d2: f64 = ra.iter().zip(&rb).map(|(x, y)| (x - y).powi(2)).sum();
    1.0 - 6.0 * d2 / (n * (n * n - 1.0))
}

fn strategy_of(c: &Candidate) -> Strategy {
    Strategy {
        nu: c.nu,
        connections: Connections::Fixed(c.connections),
        merge: Some(MergeMask::Constant(if c.merge { 1.0 } else { 0.0 })),
    }
}

/// One scene with its reference, as the measurements need it.
struct Subject {
    scene: Scene,
    reference: Vec<[f32; 3]>,
    /// The reference's mean of R, G, B per pixel.
    ref_mean: Vec<f32>,
    settings: PathSettings,
    config: EmisConfig,
}

impl Subject {
    fn load(path: &Path) -> anyhow::Result<Subject> {
        let scene = Scene::load(path)?;
        let reference = tessera_common::film::exr::read_rgb(&path.with_file_name("reference.exr"))?.pixels;
        let ref_mean = reference.iter().map(|p| (p[0] + p[1] + p[2]) / 3.0).collect();
        let settings = PathSettings::from_scene(&scene, None);
        Ok(Subject { scene, reference, ref_mean, settings, config: EmisConfig::own_pilot(EmisMethod::Vcm) })
    }

    fn size(&self) -> (usize, usize) {
        (self.scene.camera.width as usize, self.scene.camera.height as usize)
    }
}

/// The `vcm` pilot's moment buffer and path statistics.
fn pilot_moments(
    s: &Subject,
    candidates: &[Candidate],
    iterations: u32,
    pool: &rayon::ThreadPool,
) -> (MomentBuffer, StatisticsSums) {
    let (w, h) = (s.scene.camera.width, s.scene.camera.height);
    let full = Rect::full(w, h);
    let estimator = MomentEstimator::new(w, h, candidates);
    let pilot = Strategy::pilot(EmisMethod::Vcm).integrator(s.settings, s.config.correlation_aware);
    pool.install(|| {
        pilot.with_observer(&estimator).render_tile(
            &s.scene,
            &TileRequest::new(full, 0..iterations, 7),
            &mut TileAccum::new(full, &s.scene.film),
        )
    });
    estimator.snapshot()
}

/// Every candidate rendered on its own: unscaled relMSE × K (all pixels, and with the top
/// 0.1 % dropped), the relative moment of its own samples, CPU seconds per iteration.
#[derive(Default)]
struct Measured {
    error: Vec<f64>,
    error_dropped: Vec<f64>,
    own_moment: Vec<f64>,
    seconds: Vec<f64>,
}

fn measure_candidates(s: &Subject, candidates: &[Candidate], k: u32, pool: &rayon::ThreadPool) -> Measured {
    let (w, h) = s.size();
    let full = Rect::full(w as u32, h as u32);
    let mut m = Measured::default();
    for c in candidates {
        let own = MomentEstimator::new(w as u32, h as u32, std::slice::from_ref(c));
        let request = TileRequest::new(full, 1000..1000 + k, 11);
        let integrator = strategy_of(c).integrator(s.settings, s.config.correlation_aware);
        pool.install(|| {
            integrator.with_observer(&own).render_tile(&s.scene, &request, &mut TileAccum::new(full, &s.scene.film))
        });
        // The image and the time come from a second render without the moment observer: the
        // same samples, timed the way an equal-time render spends them.
        let started = cpu_seconds();
        let (accum, _) = pool.install(|| {
            render_iterations(&s.scene, s.settings, &s.config, &strategy_of(c), request.seed, request.samples, None)
        });
        m.seconds.push((cpu_seconds() - started) / k as f64);
        let mut film = Film::new(&s.scene.film);
        film.merge_tile(&accum);
        let image = film.average();
        m.error.push(relmse(&image, &s.reference, 0.0) * k as f64);
        m.error_dropped.push(relmse(&image, &s.reference, DROPPED_FRACTION) * k as f64);
        let own_moments = moments_of(&own.snapshot().0, 0);
        m.own_moment.push(relative_mean(w, h, own_moments, &s.ref_mean));
    }
    m
}

/// The image-level relative moment × cost each candidate gets from a pilot's moments, with the
/// outlier rule `outliers`.
fn predict(s: &Subject, moments: &MomentBuffer, costs: &[f64], outliers: OutlierStage) -> Vec<f64> {
    let (w, h) = s.size();
    let mut planes: Vec<Image> = (0..costs.len()).map(|c| Image::from_data(w, h, moments_of(moments, c))).collect();
    let norm: Vec<f32> = s.ref_mean.iter().map(|&r| r * r + 1e-4).collect();
    match outliers {
        OutlierStage::Shared => remove_shared_outliers(&mut planes, &norm, 0.999),
        OutlierStage::Each => remove_each_outliers(&mut planes, &norm, 0.999),
    }
    planes.into_iter().enumerate().map(|(c, plane)| relative_mean(w, h, plane.data, &s.ref_mean) * costs[c]).collect()
}

fn name_of(c: &Candidate) -> String {
    if c.is_path_tracing() {
        "pt".to_string()
    } else {
        format!("nu {} c {}{}", c.nu, c.connections, if c.merge { " merge" } else { "" })
    }
}

fn argmin(v: &[f64]) -> usize {
    (0..v.len()).min_by(|&a, &b| v[a].total_cmp(&v[b])).unwrap_or(0)
}

/// Regrets collected over the scenes, for the closing geometric means.
struct Regrets {
    /// The candidates' own measured moments.
    direct: Vec<f64>,
    /// The pilot's predictions.
    pilot: Vec<f64>,
}

/// The table of one scene, each prediction's choice and regret, and one JSON line with every
/// figure.
fn report_scene(
    name: &str,
    candidates: &[Candidate],
    costs: &[f64],
    m: &Measured,
    predicted: &[f64],
    regrets: &mut Regrets,
    json: serde_json::Value,
) {
    let times_cost = |v: &[f64]| -> Vec<f64> { v.iter().zip(costs).map(|(x, c)| x * c).collect() };
    let (variance, variance_dropped, direct) =
        (times_cost(&m.error), times_cost(&m.error_dropped), times_cost(&m.own_moment));
    // Equal-time truth: relMSE × K × measured CPU seconds per iteration, in units of the cost
    // model's (its cost per unit is fitted over the candidates, so only the ranking and the
    // model's relative errors show).
    let unit = m.seconds.iter().zip(costs).map(|(s, c)| s / c).sum::<f64>() / candidates.len() as f64;
    let timed: Vec<f64> = m.error.iter().zip(&m.seconds).map(|(e, s)| e * s / unit).collect();
    let timed_best = timed.iter().copied().fold(f64::INFINITY, f64::min);
    println!("\n### {name}: truth's choice {} ", name_of(&candidates[argmin(&timed)]));
    println!(
        "| candidate | cost | measured cost | relMSE × K × cost | relMSE × K × measured cost | same, top 0.1 % dropped | measured moment × cost | pilot-predicted × cost |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for (i, c) in candidates.iter().enumerate() {
        println!(
            "| {} | {:.2} | {:.2} | {:.4e} | {:.4e} | {:.4e} | {:.4e} | {:.4e} |",
            name_of(c),
            costs[i],
            m.seconds[i] / unit,
            variance[i],
            timed[i],
            variance_dropped[i],
            direct[i],
            predicted[i]
        );
    }
    let verdict = |label: String, predicted: &[f64], into: &mut Vec<f64>| {
        let choice = argmin(predicted);
        into.push(timed[choice] / timed_best);
        println!(
            "{label}: choose {} (regret {:.2}x, spearman {:.2})",
            name_of(&candidates[choice]),
            timed[choice] / timed_best,
            spearman(predicted, &timed)
        );
    };
    verdict("pilot moments".into(), predicted, &mut regrets.pilot);
    verdict("measured second moments".into(), &direct, &mut regrets.direct);
    println!("json: {json}");
}

/// Runs `tessera bench ground-truth`: the comparison on every scene with `iterations` per
/// candidate.
pub fn run(args: &GroundTruthArgs) -> anyhow::Result<()> {
    let scenes = args.scenes.scenes()?;
    let (k, pool) = (args.iterations, args.scenes.pool()?);
    let candidates = reduced_candidates();
    let outliers = args.moment_outliers;
    let constants = args.cost_model.constants();
    println!(
        "ground truth: pilot {} vcm iterations; {} candidates × {k} iterations each",
        args.pilot,
        candidates.len()
    );
    let mut regrets = Regrets { direct: Vec::new(), pilot: Vec::new() };
    for path in &scenes {
        let s = Subject::load(path)?;
        let pixels = s.scene.camera.width * s.scene.camera.height;
        let (moments, statistics) = pilot_moments(&s, &candidates, args.pilot, &pool);
        let statistics = statistics.statistics(pixels);
        let costs: Vec<f64> = candidates
            .iter()
            .map(|c| pixel_cost(&constants, &statistics, c, c.merge as u8 as f64, c.merge, pixels))
            .collect();
        let measured = measure_candidates(&s, &candidates, k, &pool);
        let predicted = predict(&s, &moments, &costs, outliers);
        // everything as one JSON line, for analyses beyond the table
        let rows: Vec<serde_json::Value> = candidates
            .iter()
            .enumerate()
            .map(|(i, c)| {
                serde_json::json!({
                    "nu": c.nu, "connections": c.connections, "merge": c.merge,
                    "cost": costs[i], "seconds": measured.seconds[i],
                    "relmse_k": measured.error[i], "relmse_k_dropped": measured.error_dropped[i],
                    "measured_moment": measured.own_moment[i], "predicted_moment": predicted[i] / costs[i],
                })
            })
            .collect();
        let json = serde_json::json!({"scene": scene_name(path), "k": k, "pilot": args.pilot,
            "statistics": statistics, "candidates": rows});
        report_scene(&scene_name(path), &candidates, &costs, &measured, &predicted, &mut regrets, json);
    }
    println!("\n### geometric-mean regret over {} scenes", scenes.len());
    println!("measured second moments: {:.3}x", geometric_mean(&regrets.direct));
    println!("pilot moments: {:.3}x", geometric_mean(&regrets.pilot));
    Ok(())
}
