//! `tessera bench overheads --path-tracing`: what an iteration that records moments costs
//! while path tracing is the strategy (the path-tracing start's pilot, then every fourth
//! iteration and from `emis::SPARSE_FROM` every eighth, `emis::collects_moments`), against
//! the `pt` iteration it replaces; and what `pt`'s iterations cost as EMIS renders them, in
//! calls of [`FINAL_ITERATIONS_PER_CALL`] and of [`FINAL_PT_ITERATIONS_MAX`] (the range of
//! `emis::final_call`), against one pass of `tessera render --integrator pt`.

use super::{SceneArgs, cpu_seconds};
use crate::options::scene_name;
use std::time::Instant;
use tessera_common::emis::{
    CandidateSet, EmisConfig, EmisMethod, FINAL_ITERATIONS_PER_CALL, FINAL_PT_ITERATIONS_MAX, Strategy,
    collects_moments, render_iterations,
};
use tessera_common::film::{Film, Rect, TileAccum};
use tessera_common::integrator::{Integrator, PathSettings, PathTracer, TileRequest};
use tessera_common::render::{Budget, RenderOptions, render};
use tessera_common::scene::Scene;

/// The runs of one round, in order: `pt`; the VCM engine with χ = 0 and no observer; the
/// same recording the reduced set's moments; recording the full set's.
const RUNS: [&str; 4] = ["pt", "engine", "+ reduced", "+ full"];

/// Wall and CPU seconds of each run of [`RUNS`] on one iteration.
fn round(scene: &Scene, config: &EmisConfig, iteration: u32) -> [(f64, f64); 4] {
    let settings = PathSettings::from_scene(scene, None);
    let start = Strategy::path_tracing_start(config.method);
    let iterations = iteration..iteration + 1;
    let mut out = [(0.0, 0.0); 4];
    for (i, slot) in out.iter_mut().enumerate() {
        let (t, c) = (Instant::now(), cpu_seconds());
        match i {
            0 => {
                let pt = Strategy::path_tracing();
                std::hint::black_box(render_iterations(scene, settings, config, &pt, 1, iterations.clone(), None));
            }
            1 => {
                let rect = Rect::full(scene.camera.width, scene.camera.height);
                let mut accum = TileAccum::new(rect, &scene.film);
                let request = TileRequest::new(rect, iterations.clone(), 1);
                start.integrator(settings, config.correlation_aware).render_tile(scene, &request, &mut accum);
                std::hint::black_box(accum);
            }
            _ => {
                let set = if i == 2 { CandidateSet::Reduced } else { CandidateSet::Full };
                let run = render_iterations(scene, settings, config, &start, 1, iterations.clone(), Some(set));
                assert!(run.1.is_some(), "invariant: iteration {iteration} records under path tracing");
                std::hint::black_box(run);
            }
        }
        *slot = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    }
    out
}

/// The `r`-th iteration after the pilot that records moments under path tracing.
fn recording(r: u32) -> u32 {
    (1..).filter(|&i| collects_moments(0.0, &(i..i + 1))).nth(r as usize).expect("invariant: recordings never end")
}

/// Iterations of one round of [`final_round`].
const FINAL_ROUND: u32 = 2 * FINAL_PT_ITERATIONS_MAX;

/// The calls of [`final_round`]: eight iterations (a bidirectional strategy's, and the
/// fewest path tracing gets), [`FINAL_PT_ITERATIONS_MAX`] (path tracing's most).
const FINAL_CALLS: [u32; 2] = [FINAL_ITERATIONS_PER_CALL, FINAL_PT_ITERATIONS_MAX];

/// Wall and CPU seconds of [`FINAL_ROUND`] `pt` iterations from `first` on: in EMIS's calls
/// of each size of [`FINAL_CALLS`] (merged into a film as `render_emis` does), then as one
/// pass of `tessera render` (its 32² tiles, on a pool of `threads`).
fn final_round(scene: &Scene, config: &EmisConfig, first: u32, threads: usize) -> [(f64, f64); 3] {
    let settings = PathSettings::from_scene(scene, None);
    let pt = Strategy::path_tracing();
    let mut out = [(0.0, 0.0); 3];
    for (slot, per_call) in out.iter_mut().zip(FINAL_CALLS) {
        let (t, c) = (Instant::now(), cpu_seconds());
        let mut film = Film::new(&scene.film);
        for call in (first..first + FINAL_ROUND).step_by(per_call as usize) {
            let (accum, _) = render_iterations(scene, settings, config, &pt, 1, call..call + per_call, None);
            film.merge_tile(&accum);
        }
        std::hint::black_box(film);
        *slot = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    }
    let (t, c) = (Instant::now(), cpu_seconds());
    let opts = RenderOptions { budget: Budget::Samples(FINAL_ROUND), seed: 1, threads, tile_size: 32 };
    let out_pt = render(scene, &PathTracer { settings }, &opts, &|_, _| {}).expect("a pool of the bench's threads");
    std::hint::black_box(out_pt);
    out[2] = (t.elapsed().as_secs_f64(), cpu_seconds() - c);
    out
}

/// Prints one row per scene: `pt`'s fastest iteration and, as medians over `repeats` rounds of
/// ratios within a round, each other run against it (wall / CPU).
pub fn table(args: &SceneArgs, repeats: u32, pool: &rayon::ThreadPool) -> anyhow::Result<()> {
    println!(
        "recording moments under path tracing (emis-vcm), {repeats} rounds of one recording iteration each (2, 6, 10, 14, 22, ...): `pt`'s fastest iteration, then medians over rounds of each run's time over `pt`'s in the same round (wall / CPU): the VCM engine with χ = 0 alone, recording the reduced set (the path-tracing start; the first {} iterations also sum the guides), recording the full set (a bidirectional pilot after pt won):",
        tessera_common::emis::GUIDE_ITERATIONS
    );
    println!("| scene | pt ms/it | {} | {} | {} |", RUNS[1], RUNS[2], RUNS[3]);
    println!("|---|---|---|---|---|");
    let config = EmisConfig::own_pilot(EmisMethod::Vcm);
    for path in &args.scenes()? {
        let scene = Scene::load(path)?;
        let rounds: Vec<[(f64, f64); 4]> =
            (0..repeats).map(|r| pool.install(|| round(&scene, &config, recording(r)))).collect();
        let best = rounds.iter().map(|r| r[0].0).fold(f64::INFINITY, f64::min);
        let median = |run: usize, cpu: bool| {
            let mut v: Vec<f64> =
                rounds.iter().map(|r| if cpu { r[run].1 / r[0].1 } else { r[run].0 / r[0].0 }).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let cells: Vec<String> =
            (1..4).map(|run| format!("{:.2}× / {:.2}×", median(run, false), median(run, true))).collect();
        println!("| {} | {:.0} | {} |", scene_name(path), best * 1e3, cells.join(" | "));
    }
    println!(
        "\n`pt`'s iterations in EMIS's calls of {} and of {} (16² tiles, merged call by call) against one pass of `tessera render --integrator pt` (32² tiles), {FINAL_ROUND} iterations each, {repeats} rounds; medians of the ratio within a round (wall / CPU):",
        FINAL_CALLS[0], FINAL_CALLS[1]
    );
    println!(
        "| scene | pt pass ms/it | calls of {} / pt pass | calls of {} / pt pass |",
        FINAL_CALLS[0], FINAL_CALLS[1]
    );
    println!("|---|---|---|---|");
    let threads = pool.current_num_threads();
    for path in &args.scenes()? {
        let scene = Scene::load(path)?;
        let rounds: Vec<[(f64, f64); 3]> = (0..repeats)
            .map(|r| pool.install(|| final_round(&scene, &config, 1000 + r * FINAL_ROUND, threads)))
            .collect();
        let best = rounds.iter().map(|r| r[2].0).fold(f64::INFINITY, f64::min) / FINAL_ROUND as f64;
        let median = |run: usize, cpu: bool| {
            let mut v: Vec<f64> =
                rounds.iter().map(|r| if cpu { r[run].1 / r[2].1 } else { r[run].0 / r[2].0 }).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        println!(
            "| {} | {:.1} | {:.3}× / {:.3}× | {:.3}× / {:.3}× |",
            scene_name(path),
            best * 1e3,
            median(0, false),
            median(0, true),
            median(1, false),
            median(1, true)
        );
    }
    Ok(())
}
