//! EMIS benchmarks of `tessera bench`:
//!
//! * `--equal-time 20,60`: every scene rendered by every integrator of `--integrators` for the
//!   same wall time, relMSE against the reference (top 0.1 % of pixel errors dropped), speed-ups
//!   (relMSE_B / relMSE_A), the targets (geometric mean of emis-vcm over vcm and of
//!   emis-bdpt over bdpt, emis-vcm against the better of pt and vcm), and a PNG bar chart;
//! * `--emis-overheads`: moment accumulation as a fraction of pilot iteration time (pilot
//!   iterations with and without the estimator, interleaved), optimiser and denoiser time at
//!   256² and 1920×1080 on synthetic inputs, and the memory of the moment buffers.

use crate::bench::{BenchArgs, cpu_seconds};
use crate::chart::{Group, write_bar_chart};
use crate::cli::IntegratorKind;
use crate::local::{make_renderer, scene_name};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tessera_common::integrator::PathSettings;
use tessera_common::emis::{
    CandidateSet, EmisConfig, EmisMethod, GUIDE_ITERATIONS, PilotStart, Strategy, render_iterations,
};
use tessera_common::emis::cost::PathStatistics;
use tessera_common::emis::denoise::{Guides, denoised_intensity};
use tessera_common::emis::filter::Image;
use tessera_common::emis::moments::MomentBuffer;
use tessera_common::emis::optimize::{MergeScope, OptimizerInput, optimize};
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::sampler::Sampler;
use tessera_common::scene::Scene;
use tessera_common::settings::{IntegratorName, RenderSettings};

/// One integrator's equal-time results on one scene.
struct Cell {
    name: String,
    /// relMSE per seed of `--seeds`.
    relmse: Vec<f64>,
    /// Mean samples per second over the seeds.
    samples_per_s: f64,
}

impl Cell {
    fn mean(&self) -> f64 {
        self.relmse.iter().sum::<f64>() / self.relmse.len().max(1) as f64
    }
}

/// One scene's equal-time results, a cell per column.
type Row = Vec<Cell>;

/// The columns: each integrator of `--integrators`, the `emis-*` ones once per pilot of
/// `--emis-pilot` (a path-tracing start is named `emis-vcm/pt-start`).
fn columns(args: &BenchArgs) -> Vec<(IntegratorKind, PilotStart, String)> {
    let mut out = Vec::new();
    for &kind in &args.integrators {
        if IntegratorName::from(kind).emis_method().is_none() {
            out.push((kind, PilotStart::default(), kind.name().to_string()));
            continue;
        }
        for pilot in args.emis_pilot.iter().map(|&p| PilotStart::from(p)) {
            let name = match pilot {
                PilotStart::Bidirectional => kind.name().to_string(),
                PilotStart::PathTracing => format!("{}/pt-start", kind.name()),
            };
            out.push((kind, pilot, name));
        }
    }
    out
}

fn equal_time_scene(args: &BenchArgs, path: &Path, seconds: f64) -> anyhow::Result<Row> {
    let scene = Scene::load(path)?;
    let reference = tessera_common::film::exr::read_rgb(&path.with_file_name("reference.exr"))?;
    let mut rows = Vec::new();
    for (kind, pilot, name) in columns(args) {
        let renderer = make_renderer(
            &RenderSettings {
                integrator: kind.into(),
                cost_model: args.cost_model.into(),
                moment_filter: args.moment_filter.into(),
                moment_outliers: args.moment_outliers.into(),
                emis_pilot: pilot,
                ..RenderSettings::default()
            },
            &scene,
        )?;
        let mut cell = Cell { name, relmse: Vec::new(), samples_per_s: 0.0 };
        for &seed in &args.seeds {
            let opts = RenderOptions {
                budget: Budget::Time(Duration::from_secs_f64(seconds)),
                seed,
                threads: args.threads.unwrap_or(0),
                tile_size: 32,
            };
            let (out, _) = renderer.render(&scene, &opts, &|_, _| {})?;
            cell.relmse.push(tessera_common::film::compare::relmse(&out.film.average(), &reference.pixels, 0.001));
            cell.samples_per_s += out.film.total_samples() as f64 / out.elapsed.as_secs_f64() / args.seeds.len() as f64;
        }
        rows.push(cell);
    }
    Ok(rows)
}

fn geometric_mean(v: &[f64]) -> f64 {
    (v.iter().map(|x| x.ln()).sum::<f64>() / v.len().max(1) as f64).exp()
}

/// Runs the equal-time comparison for every duration.
pub fn equal_time(args: &BenchArgs, scenes: &[PathBuf], durations: &[f64]) -> anyhow::Result<()> {
    for &seconds in durations {
        println!("\n## equal time {seconds} s ({} threads)\n", args.threads.map_or("all".into(), |t| t.to_string()));
        println!(
            "relMSE against the reference (top 0.1 % dropped; mean over seeds {:?}), speed-up over pt = relMSE(pt) / relMSE, samples/s\n",
            args.seeds
        );
        let names: Vec<String> = columns(args).into_iter().map(|c| c.2).collect();
        println!("| scene | {} |", names.join(" | "));
        println!("|---|{}", "---|".repeat(names.len()));
        let mut table = Vec::new();
        for path in scenes {
            let rows = equal_time_scene(args, path, seconds)?;
            let pt = rows.iter().find(|c| c.name == "pt").map(Cell::mean);
            let cells: Vec<String> = rows
                .iter()
                .map(|c| {
                    let (e, sps) = (c.mean(), c.samples_per_s);
                    match pt {
                        Some(p) => format!("{e:.5} ({:.2}x, {:.2e} S/s)", p / e, sps),
                        None => format!("{e:.5} ({:.2e} S/s)", sps),
                    }
                })
                .collect();
            println!("| {} | {} |", scene_name(path), cells.join(" | "));
            table.push((scene_name(path), rows));
        }
        let err = |rows: &Row, n: &str| rows.iter().find(|c| c.name == n).map(Cell::mean);
        // the relMSE of seed number `i`
        let err_at = |rows: &Row, n: &str, i: usize| rows.iter().find(|c| c.name == n).map(|c| c.relmse[i]);
        let ratio = |a: &str, b: &str| -> Vec<f64> {
            table.iter().filter_map(|(_, r)| Some(err(r, b)? / err(r, a)?)).collect::<Vec<f64>>()
        };
        println!();
        for (a, b, target) in [
            ("emis-vcm", "vcm", 1.2),
            ("emis-bdpt", "bdpt", 1.1),
            ("emis-vcm", "pt", 0.0),
            ("emis-vcm/pt-start", "emis-vcm", 0.0),
            ("emis-bdpt/pt-start", "emis-bdpt", 0.0),
        ] {
            let r = ratio(a, b);
            if !r.is_empty() {
                let per_scene: Vec<String> = r.iter().map(|x| format!("{x:.2}x")).collect();
                let verdict = if target > 0.0 {
                    format!(" (target ≥ {target}x: {})", if geometric_mean(&r) >= target { "met" } else { "NOT met" })
                } else {
                    String::new()
                };
                println!(
                    "speed-up of {a} over {b}: geometric mean {:.2}x{verdict}; per scene {}",
                    geometric_mean(&r),
                    per_scene.join(", ")
                );
            }
        }
        let worst: Vec<(String, f64)> = table
            .iter()
            .filter_map(|(s, r)| {
                let best = err(r, "pt")?.min(err(r, "vcm")?);
                Some((s.clone(), best / err(r, "emis-vcm")?))
            })
            .collect();
        if !worst.is_empty() {
            let below: Vec<&(String, f64)> = worst.iter().filter(|(_, x)| *x < 0.9).collect();
            println!(
                "emis-vcm against the better of pt and vcm: {} (target: never below 0.9x: {})",
                worst.iter().map(|(s, x)| format!("{s} {x:.2}x")).collect::<Vec<_>>().join(", "),
                if below.is_empty() { "met" } else { "NOT met" }
            );
            if args.seeds.len() > 1 {
                for (i, seed) in args.seeds.iter().enumerate() {
                    let per_seed: Vec<String> = table
                        .iter()
                        .filter_map(|(s, r)| {
                            let best = err_at(r, "pt", i)?.min(err_at(r, "vcm", i)?);
                            Some(format!("{s} {:.2}x", best / err_at(r, "emis-vcm", i)?))
                        })
                        .collect();
                    println!("  seed {seed} alone: {}", per_seed.join(", "));
                }
            }
        }
        if let Some(chart) = &args.chart {
            let file = chart.with_file_name(format!(
                "{}-{}s.png",
                chart.file_stem().and_then(|s| s.to_str()).unwrap_or("equal-time"),
                seconds
            ));
            let groups: Vec<Group> = table
                .iter()
                .map(|(s, r)| {
                    let pt = err(r, "pt").unwrap_or(f64::NAN);
                    Group { label: s.clone(), values: r.iter().map(|c| pt / c.mean()).collect() }
                })
                .collect();
            write_bar_chart(&file, &format!("speed-up over pt at equal time {seconds} s"), &names, &groups)?;
            println!("chart: {}", file.display());
        }
    }
    Ok(())
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
/// [`GUIDE_ITERATIONS`] (which also sum the denoiser's guides), and with it after them: the
/// calls a render makes ([`render_iterations`] without and with collection), so the
/// estimator's buffer and its hand-over are counted. Each overhead is the median over
/// `repeats` rounds of a ratio of runs made back to back within one round (robust to the
/// host's load changing between rounds, which separate fastest times are not).
fn accumulation_overhead(scene: &Scene, method: EmisMethod, iterations: u32, repeats: u32) -> Overhead {
    let config = EmisConfig::new(method);
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

/// One optimiser and one denoiser run on synthetic inputs of `w × h` with the VCM candidates.
fn optimizer_time(w: u32, h: u32) -> (f64, f64, usize) {
    let candidates = EmisConfig::new(EmisMethod::Vcm).candidates.candidates();
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
    let config = EmisConfig::new(EmisMethod::Vcm);
    let t = Instant::now();
    let image = denoised_intensity(
        w as usize,
        h as usize,
        &color,
        &Guides { albedo: &albedo, normal: &normal, depth: &depth },
        &config.denoise,
    );
    let denoise = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let decision = optimize(&OptimizerInput {
        candidates: &candidates,
        moments: &moments,
        image: &Image::from_data(w as usize, h as usize, image.data),
        statistics: PathStatistics::default(),
        constants: config.constants,
        filters: config.filters,
        merge_scope: MergeScope::PerPixel,
    });
    std::hint::black_box(decision);
    (t.elapsed().as_secs_f64(), denoise, moments.sums.len() * 4)
}

/// Runs `--emis-overheads`.
pub fn overheads(args: &BenchArgs, scenes: &[PathBuf]) -> anyhow::Result<()> {
    let threads = args.threads.unwrap_or(0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
    println!(
        "moment accumulation (51 VCM / 26 BDPT candidates), {} rounds of 2 iterations: time per pilot iteration (fastest round) without moments, with moments and the denoiser's guides (the first {GUIDE_ITERATIONS} iterations), with moments alone (the later ones); overheads are medians over rounds of ratios within a round, of wall time and of process CPU time:",
        args.repeats.max(1)
    );
    println!(
        "| scene | vcm pilot ms/it | + moments, guides | + moments | overhead, guides (wall / CPU) | overhead, moments (wall / CPU) | bdpt pilot ms/it | + moments, guides | + moments | overhead, guides (wall / CPU) | overhead, moments (wall / CPU) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let percent = |ratio: f64| (ratio - 1.0) * 100.0;
    for path in scenes {
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
    println!("\noptimiser (51 candidates, synthetic moments) and denoiser, best of {} runs:", args.repeats.max(1));
    for (w, h) in [(256u32, 256u32), (1920, 1080)] {
        let runs: Vec<(f64, f64, usize)> =
            (0..args.repeats.max(1)).map(|_| pool.install(|| optimizer_time(w, h))).collect();
        let best_opt = runs.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
        let best_den = runs.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
        let guides = (w * h) as usize * (3 + 3 + 1) * 4;
        println!(
            "{w}x{h}: optimiser {:.1} ms, denoiser {:.1} ms; moment buffer {:.1} MB (+{:.1} MB guides; the optimiser holds a filtered copy of the same size)",
            best_opt * 1e3,
            best_den * 1e3,
            runs[0].2 as f64 / 1e6,
            guides as f64 / 1e6
        );
    }
    Ok(())
}
