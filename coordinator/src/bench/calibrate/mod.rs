//! `tessera bench calibrate-costs`: the timing runs of docs/emis.md §2 on our renderer. On each
//! scene it times the configurations of [`calibration_configurations`] through the
//! bidirectional engine, and path tracing through the `pt` integrator, interleaved and the
//! fastest of `--repeats` kept; turns the times into costs per pixel in camera-vertex units
//! (time ÷ the bidirectional engine's time at ν = 0 × L̄c); fits the heuristic's constants to
//! all scenes at once ([`fit`]; path tracing's constant is the
//! geometric mean of its time ratios); and reports each configuration's error with the
//! reference and the fitted constants against the ±30 % the authors report for theirs. Beside
//! them, the constants each scene's own pilot measures (`--cost-model measured`), and every
//! set's error after the one scale per scene that costs in other units need (decisions depend
//! on cost ratios only).

mod fit;

use super::SceneArgs;
use crate::options::scene_name;
use fit::{CostSample, calibration_configurations, fit_constants};
use std::time::Instant;
use tessera_common::emis::candidate::Candidate;
use tessera_common::emis::cost::{CostConstants, pixel_cost};
use tessera_common::emis::measured::measured_constants;
use tessera_common::emis::{CandidateSet, EmisConfig, EmisMethod, Strategy, render_iterations};
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::path::connections::Connections;
use tessera_common::integrator::path::merge::MergeMask;
use tessera_common::integrator::{Integrator, PathSettings, TileRequest};
use tessera_common::scene::Scene;

/// Arguments of `tessera bench calibrate-costs`.
#[derive(clap::Args, Debug, Clone)]
pub struct CalibrateArgs {
    /// Scenes and threads.
    #[command(flatten)]
    pub scenes: SceneArgs,
    /// Iterations per timed run of each configuration.
    #[arg(long, default_value_t = 16)]
    pub spp: u32,
    /// Timed rounds after one warm-up; the fastest of each configuration is kept.
    #[arg(long, default_value_t = 2)]
    pub repeats: u32,
}

fn label(c: &Candidate) -> String {
    match (c.nu, c.merge) {
        (nu, _) if nu == 0.0 => "pt".into(),
        (nu, false) => format!("nu={nu} c={}", c.connections),
        (nu, true) => format!("nu={nu} c={} merge", c.connections),
    }
}

fn predicted(k: &CostConstants, s: &CostSample) -> f64 {
    let chi = if s.candidate.merge { 1.0 } else { 0.0 };
    pixel_cost(k, &s.statistics, &s.candidate, chi, s.candidate.merge, s.pixels)
}

/// Times every configuration on one scene; returns the samples with measured costs, the
/// `pt` integrator's time over the unit configuration's (the bidirectional engine at ν = 0)
/// and the constants the pilot measures.
fn measure_scene(
    scene: &Scene,
    iterations: u32,
    repeats: u32,
    pool: &rayon::ThreadPool,
) -> (Vec<CostSample>, f64, Option<CostConstants>) {
    let (w, h) = (scene.camera.width, scene.camera.height);
    let pixels = w * h;
    let settings = PathSettings::from_scene(scene, None);
    let mut config = EmisConfig::own_pilot(EmisMethod::Vcm);
    // the pilot times path tracing's probe too, for the constants it measures
    config.measured_costs = true;
    // the statistics of the pilot (two iterations), as the optimiser would see them
    let (_, pilot) = pool.install(|| {
        render_iterations(
            scene,
            settings,
            &config,
            &Strategy::pilot(EmisMethod::Vcm),
            1,
            0..2,
            Some(CandidateSet::Full),
        )
    });
    let sums = pilot.expect("invariant: collected").statistics;
    let statistics = sums.statistics(pixels);
    let per_job = measured_constants(&sums.times, &CostConstants::calibrated());
    let configs = calibration_configurations();
    let integrators: Vec<_> = configs
        .iter()
        .map(|c| {
            let merge = c.merge.then_some(MergeMask::Constant(1.0));
            Strategy { nu: c.nu, connections: Connections::Fixed(c.connections), merge }.integrator(settings, true)
        })
        .collect();
    let mut best = vec![f64::INFINITY; configs.len()];
    let mut best_pt = f64::INFINITY;
    // one warm-up round, then `repeats` timed rounds, configurations interleaved so that a
    // change in machine load hits them alike
    for round in 0..=repeats {
        for (i, integrator) in integrators.iter().enumerate() {
            let samples = 2 + round * iterations..2 + (round + 1) * iterations;
            let request = TileRequest::new(Rect::full(w, h), samples, 7);
            let t = Instant::now();
            pool.install(|| integrator.render_tile(scene, &request, &mut TileAccum::new(request.rect, &scene.film)));
            if round > 0 {
                best[i] = best[i].min(t.elapsed().as_secs_f64());
            }
        }
        // path tracing as a final pass renders it: the `pt` integrator, rows in parallel
        let samples = 2 + round * iterations..2 + (round + 1) * iterations;
        let t = Instant::now();
        pool.install(|| render_iterations(scene, settings, &config, &Strategy::path_tracing(), 7, samples, None));
        if round > 0 {
            best_pt = best_pt.min(t.elapsed().as_secs_f64());
        }
    }
    // the unit configuration stays the unit; the path-tracing sample is the `pt` integrator
    let samples = configs
        .iter()
        .zip(&best)
        .map(|(c, &t)| CostSample {
            statistics,
            candidate: *c,
            pixels,
            measured: if c.is_path_tracing() { best_pt } else { t } / best[0] * statistics.camera_vertices,
        })
        .collect();
    (samples, best_pt / best[0], per_job)
}

/// The rms of log(predicted / measured) after the one scale per scene that fits best (the
/// mean log ratio of the scene's configurations), over every configuration.
fn scale_free_rms(scenes: &[String], logs: &[f64]) -> f64 {
    let mut sq = 0.0;
    for name in scenes.iter().collect::<std::collections::BTreeSet<_>>() {
        let of: Vec<f64> = scenes.iter().zip(logs).filter(|(s, _)| *s == name).map(|(_, &l)| l).collect();
        let mean = of.iter().sum::<f64>() / of.len() as f64;
        sq += of.iter().map(|l| (l - mean).powi(2)).sum::<f64>();
    }
    (sq / logs.len().max(1) as f64).sqrt()
}

/// Runs `tessera bench calibrate-costs`.
pub fn run(args: &CalibrateArgs) -> anyhow::Result<()> {
    let scenes = args.scenes.scenes()?;
    let pool = args.scenes.pool()?;
    let iterations = args.spp.max(1);
    let mut all = Vec::new();
    let mut names = Vec::new();
    let mut pt_ratios = Vec::new();
    let mut per_job = Vec::new();
    for path in &scenes {
        let scene = Scene::load(path)?;
        let (samples, pt_ratio, measured) = measure_scene(&scene, iterations, args.repeats.max(1), &pool);
        match &measured {
            Some(k) => {
                eprintln!("{}: measured by its pilot: {}", scene_name(path), describe(k, &CostConstants::calibrated()))
            }
            None => eprintln!("{}: its pilot timed too little to measure constants", scene_name(path)),
        }
        per_job.extend(std::iter::repeat_n(measured.unwrap_or_else(CostConstants::calibrated), samples.len()));
        let s = samples[0].statistics;
        eprintln!(
            "{}: L̄c {:.2}, L̄l {:.2}, φ {:.3e}; pt / (ν = 0) time {:.3}",
            scene_name(path),
            s.camera_vertices,
            s.light_vertices,
            s.photons_per_query_per_path,
            pt_ratio
        );
        pt_ratios.push(pt_ratio);
        names.extend(std::iter::repeat_n(scene_name(path), samples.len()));
        all.extend(samples);
    }
    let default = CostConstants::reference();
    // path tracing's constant: the geometric mean of its measured time ratios
    let path_tracing = (pt_ratios.iter().map(|r: &f64| r.ln()).sum::<f64>() / pt_ratios.len().max(1) as f64).exp();
    let fitted = fit_constants(&all, path_tracing)
        .ok_or_else(|| anyhow::anyhow!("the measurements do not determine the constants"))?;
    println!(
        "{:<18} {:<18} {:>9} {:>9} {:>7} {:>9} {:>7} {:>9}",
        "scene", "config", "measured", "reference", "err", "fitted", "err", "per job"
    );
    let (mut worst_default, mut worst_fitted, mut sq_default, mut sq_fitted) = (0.0f64, 0.0f64, 0.0, 0.0);
    let mut logs: [Vec<f64>; 4] = Default::default();
    for ((name, s), job) in names.iter().zip(&all).zip(&per_job) {
        let (d, f, j) = (predicted(&default, s), predicted(&fitted, s), predicted(job, s));
        let calibrated = predicted(&CostConstants::calibrated(), s);
        for (log, p) in logs.iter_mut().zip([d, f, calibrated, j]) {
            log.push((p / s.measured).ln());
        }
        let (ed, ef) = (d / s.measured - 1.0, f / s.measured - 1.0);
        (worst_default, worst_fitted) = (worst_default.max(ed.abs()), worst_fitted.max(ef.abs()));
        (sq_default, sq_fitted) = (sq_default + ed * ed, sq_fitted + ef * ef);
        println!(
            "{:<18} {:<18} {:>9.2} {:>9.2} {:>+6.0}% {:>9.2} {:>+6.0}% {:>9.2}",
            name,
            label(&s.candidate),
            s.measured,
            d,
            ed * 100.0,
            f,
            ef * 100.0,
            j
        );
    }
    let [d, f, c, j] = logs.map(|l| (scale_free_rms(&names, &l).exp() - 1.0) * 100.0);
    println!(
        "error after one scale per scene (rms of log ratios, as %): reference {d:.0}%, fitted {f:.0}%, \
         calibrated (the default) {c:.0}%, measured per job by each scene's pilot {j:.0}%"
    );
    let n = all.len().max(1) as f64;
    println!(
        "relative error of the predicted cost: reference constants rms {:.0}% max {:.0}%; fitted rms {:.0}% max {:.0}% (the authors report ±30% for theirs)",
        (sq_default / n).sqrt() * 100.0,
        worst_default * 100.0,
        (sq_fitted / n).sqrt() * 100.0,
        worst_fitted * 100.0
    );
    println!("fitted constants (reference in brackets): {}", describe(&fitted, &default));
    Ok(())
}

fn describe(k: &CostConstants, r: &CostConstants) -> String {
    [
        ("light_vertex", k.light_vertex, r.light_vertex),
        ("light_vertex_walk", k.light_vertex_walk, r.light_vertex_walk),
        ("connection", k.connection, r.connection),
        ("connection_walk", k.connection_walk, r.connection_walk),
        ("build", k.build, r.build),
        ("query", k.query, r.query),
        ("photon_shading", k.photon_shading, r.photon_shading),
        ("path_tracing", k.path_tracing, r.path_tracing),
    ]
    .iter()
    .map(|(name, v, reference)| format!("{name} {v:.3} ({reference:.3})"))
    .collect::<Vec<_>>()
    .join(", ")
}
