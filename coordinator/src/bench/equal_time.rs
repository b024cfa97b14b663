//! `tessera bench equal-time 20,60`: every scene rendered by every integrator of
//! `--integrators` for the same wall time (the columns of a seed one after another, in a
//! rotating order, `--repeats` rounds); relMSE against the scene's `reference.exr` (top
//! 0.1 % of pixel errors dropped) and, where the scene has `reference.stderr.exr`, against the
//! truth (each pixel's reference variance subtracted, decision 0047), scaled to the budget by
//! the time each render took (relMSE × elapsed / budget: a render stops between iterations,
//! and one that overran the budget would otherwise win by the overrun), speed-ups
//! (relMSE_B / relMSE_A), the EMIS targets (geometric mean of emis-vcm over vcm and of
//! emis-bdpt over bdpt, emis-vcm against the better of pt and vcm) and, with `--chart`, an SVG
//! bar chart per duration.

use super::chart::{Group, write_bar_chart};
use super::{EmisModelArgs, SceneArgs, geometric_mean};
use crate::options::{make_renderer, scene_name};
use clap::ValueEnum;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tessera_common::emis::PilotStart;
use tessera_common::emis::cost::CostModel;
use tessera_common::emis::denoise::ImageEstimate;
use tessera_common::emis::optimize::{ConnectionScope, OutlierStage};
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::Scene;
use tessera_common::settings::{IntegratorName, RenderSettings};

/// Arguments of `tessera bench equal-time`.
#[derive(clap::Args, Debug, Clone)]
pub struct EqualTimeArgs {
    /// Seconds per render, comma-separated durations run one after another (e.g. 20,60).
    #[arg(value_parser = parse_durations)]
    pub seconds: Durations,
    /// Scenes and threads.
    #[command(flatten)]
    pub scenes: SceneArgs,
    /// Integrators compared.
    #[arg(long, value_delimiter = ',', default_value = "pt,bdpt,vcm,emis-bdpt,emis-vcm")]
    pub integrators: Vec<IntegratorName>,
    /// Render every cell once per seed; relMSE is the mean over seeds, and the floor is also
    /// reported per seed, so that a verdict shows the run-to-run spread.
    #[arg(long, value_delimiter = ',', default_value = "1")]
    pub seeds: Vec<u64>,
    /// Render every cell this many times per seed (relMSE per seed is the mean). Each round
    /// renders a seed's columns one after another, in an order that rotates from round to
    /// round, so that a host whose speed drifts slows every column alike.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeats: u32,
    /// The EMIS optimiser's model.
    #[command(flatten)]
    pub model: EmisModelArgs,
    /// The pilots each `emis-*` integrator runs with (each a column).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "path-tracing")]
    pub emis_pilot: Vec<PilotStart>,
    /// The connection scopes each `emis-*` integrator runs with (each a column; per pixel is
    /// named `emis-vcm/c-pixel`).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "image")]
    pub emis_connections: Vec<ConnectionScope>,
    /// Cost models besides `--cost-model` each `emis-*` column also runs with (a column each,
    /// named `emis-vcm/k-measured`).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub compare_cost_models: Vec<CostModel>,
    /// Outlier rules besides `--moment-outliers` each `emis-*` column also runs with (a column
    /// each, named `emis-vcm/o-each`).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub compare_moment_outliers: Vec<OutlierStage>,
    /// Image estimates besides `--emis-image` each `emis-*` column also runs with (a column
    /// each, named `emis-vcm/i-guided`).
    #[arg(long, value_enum, value_delimiter = ',')]
    pub compare_emis_image: Vec<ImageEstimate>,
    /// Also draw the speed-ups as an SVG bar chart, one file per duration (NAME-20s.svg ...).
    #[arg(long)]
    pub chart: Option<PathBuf>,
}

/// The durations of one run, in seconds.
#[derive(Clone, Debug)]
pub struct Durations(pub Vec<f64>);

/// Parses `20,60`: positive seconds, comma-separated. One argument, so that scenes can follow.
fn parse_durations(s: &str) -> Result<Durations, String> {
    s.split(',')
        .map(|d| match d.trim().parse::<f64>() {
            Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
            _ => Err(format!("\"{d}\" is not a positive number of seconds")),
        })
        .collect::<Result<Vec<f64>, String>>()
        .map(Durations)
}

/// One integrator's equal-time results on one scene.
struct Cell {
    name: String,
    /// relMSE × elapsed / budget per seed of `--seeds`, the mean over `--repeats`.
    relmse: Vec<f64>,
    /// The same against the truth, the reference's own noise taken out
    /// ([`relmse_against_truth`](tessera_common::film::compare::relmse_against_truth)), where
    /// the scene has a `reference.stderr.exr`.
    truth: Option<Vec<f64>>,
    /// Seconds every run took.
    elapsed: Vec<f64>,
    /// Samples per second of every run.
    samples_per_s: Vec<f64>,
    /// Every run's place in its scene's run order (1 = first).
    places: Vec<usize>,
}

impl Cell {
    fn mean(&self) -> f64 {
        mean(&self.relmse)
    }
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

/// One scene's equal-time results, a cell per column.
type Row = Vec<Cell>;

/// The model settings a column changes.
#[derive(Clone, Copy, Default)]
struct Variant {
    cost: Option<CostModel>,
    outliers: Option<OutlierStage>,
    image: Option<ImageEstimate>,
}

/// One column: an integrator, for `emis-*` with a pilot and a connection scope.
struct Column {
    kind: IntegratorName,
    pilot: PilotStart,
    connections: ConnectionScope,
    /// Another cost model or outlier rule than the model arguments'.
    variant: Variant,
    name: String,
}

/// The columns: each integrator of `--integrators`, the `emis-*` ones once per pilot of
/// `--emis-pilot` and connection scope of `--emis-connections` (the default pilot, a
/// path-tracing start, is plain `emis-vcm`, which the targets read; the method's own pilot is
/// named `emis-vcm/own-pilot`, per-pixel connections `emis-vcm/c-pixel`).
fn columns(args: &EqualTimeArgs) -> Vec<Column> {
    let mut out = Vec::new();
    for &kind in &args.integrators {
        if kind.emis_method().is_none() {
            let (pilot, connections) = (PilotStart::default(), ConnectionScope::default());
            out.push(Column { kind, pilot, connections, variant: Variant::default(), name: kind.as_str().to_string() });
            continue;
        }
        for &pilot in &args.emis_pilot {
            for &connections in &args.emis_connections {
                let mut name = kind.as_str().to_string();
                if pilot == PilotStart::Bidirectional {
                    name.push_str("/own-pilot");
                }
                if connections == ConnectionScope::PerPixel {
                    name.push_str("/c-pixel");
                }
                // the model arguments' column, each compared setting alone, and each pair
                let models = std::iter::once(None).chain(args.compare_cost_models.iter().map(Some));
                for model in models {
                    let rules = std::iter::once(None).chain(args.compare_moment_outliers.iter().map(Some));
                    for rule in rules {
                        let mut name = name.clone();
                        if let Some(m) = model {
                            name.push_str(&format!(
                                "/k-{}",
                                m.to_possible_value().expect("no skipped values").get_name()
                            ));
                        }
                        if let Some(r) = rule {
                            name.push_str(&format!(
                                "/o-{}",
                                r.to_possible_value().expect("no skipped values").get_name()
                            ));
                        }
                        let variant = Variant { cost: model.copied(), outliers: rule.copied(), image: None };
                        out.push(Column { kind, pilot, connections, variant, name });
                    }
                }
                // each other image estimate alone, with the model arguments
                for image in &args.compare_emis_image {
                    let suffix = image.to_possible_value().expect("no skipped values");
                    let name = format!("{name}/i-{}", suffix.get_name());
                    let variant = Variant { image: Some(*image), ..Variant::default() };
                    out.push(Column { kind, pilot, connections, variant, name });
                }
            }
        }
    }
    out
}

/// One scene, every column: round after round, each seed's columns in an order rotated by
/// one per seed and round.
fn equal_time_scene(args: &EqualTimeArgs, path: &Path, seconds: f64) -> anyhow::Result<Row> {
    let scene = Scene::load(path)?;
    let reference = tessera_common::film::exr::read_rgb(&path.with_file_name("reference.exr"))?;
    let stderr_path = path.with_file_name("reference.stderr.exr");
    let reference_se =
        if stderr_path.exists() { Some(tessera_common::film::exr::read_rgb(&stderr_path)?) } else { None };
    let mut renderers = Vec::new();
    let mut rows = Vec::new();
    for Column { kind, pilot, connections, variant, name } in columns(args) {
        let mut settings = RenderSettings {
            integrator: kind,
            emis_pilot: pilot,
            emis_connections: connections,
            ..RenderSettings::default()
        };
        args.model.apply(&mut settings);
        if let Some(model) = variant.cost {
            settings.cost_model = model;
        }
        if let Some(rule) = variant.outliers {
            settings.moment_outliers = rule;
        }
        if let Some(image) = variant.image {
            settings.emis_image = image;
        }
        renderers.push(make_renderer(&settings, &scene)?);
        let truth = reference_se.as_ref().map(|_| vec![0.0; args.seeds.len()]);
        rows.push(Cell {
            name,
            relmse: vec![0.0; args.seeds.len()],
            truth,
            elapsed: Vec::new(),
            samples_per_s: Vec::new(),
            places: Vec::new(),
        });
    }
    let columns = rows.len();
    let mut turn = 0;
    for _ in 0..args.repeats {
        for (i, &seed) in args.seeds.iter().enumerate() {
            for c in (0..columns).map(|c| (c + turn) % columns) {
                let opts = RenderOptions {
                    budget: Budget::Time(Duration::from_secs_f64(seconds)),
                    seed,
                    threads: args.scenes.threads.unwrap_or(0),
                    tile_size: 32,
                };
                let (out, emis) = renderers[c].render(&scene, &opts, &|_, _| {})?;
                let image = emis.map_or_else(|| out.film.average(), |e| e.image(&out.film));
                let relmse = tessera_common::film::compare::relmse(
                    &image,
                    &reference.pixels,
                    tessera_common::film::compare::DROPPED_FRACTION,
                );
                // error × time is what equal time compares; relMSE falls as 1 / time
                let elapsed = out.elapsed.as_secs_f64();
                rows[c].relmse[i] += relmse * elapsed / seconds / args.repeats as f64;
                if let (Some(truth), Some(se)) = (rows[c].truth.as_mut(), reference_se.as_ref()) {
                    let against_truth = tessera_common::film::compare::relmse_against_truth(
                        &image,
                        &reference.pixels,
                        &se.pixels,
                        tessera_common::film::compare::DROPPED_FRACTION,
                    );
                    truth[i] += against_truth * elapsed / seconds / args.repeats as f64;
                }
                rows[c].elapsed.push(elapsed);
                rows[c].samples_per_s.push(out.film.total_samples() as f64 / out.elapsed.as_secs_f64());
                let place = rows.iter().map(|r| r.places.len()).sum::<usize>() + 1;
                rows[c].places.push(place);
            }
            turn += 1;
        }
    }
    Ok(rows)
}

/// The mean relMSE of column `name` in a scene's row.
fn err(rows: &Row, name: &str) -> Option<f64> {
    rows.iter().find(|c| c.name == name).map(Cell::mean)
}

/// The relMSE of column `name` for the `i`-th seed alone.
fn err_at(rows: &Row, name: &str, i: usize) -> Option<f64> {
    rows.iter().find(|c| c.name == name).map(|c| c.relmse[i])
}

/// One scene's line of the table: each column's scaled relMSE, speed-up over pt, samples/s
/// and mean seconds.
fn table_line(name: &str, rows: &Row) -> String {
    let pt = err(rows, "pt");
    let cells: Vec<String> = rows
        .iter()
        .map(|c| {
            let (e, sps, secs) = (c.mean(), mean(&c.samples_per_s), mean(&c.elapsed));
            match pt {
                Some(p) => format!("{e:.5} ({:.2}x, {:.2e} S/s, {secs:.1} s)", p / e, sps),
                None => format!("{e:.5} ({:.2e} S/s, {secs:.1} s)", sps),
            }
        })
        .collect();
    format!("| {name} | {} |", cells.join(" | "))
}

/// Issue 21's targets: emis-vcm over vcm and emis-bdpt over bdpt (geometric means over the
/// scenes), and emis-vcm against the better of pt and vcm on every scene and seed.
const VCM_TARGET: f64 = 1.7;
const BDPT_TARGET: f64 = 1.3;
const FLOOR_TARGET: f64 = 0.95;

/// The speed-ups the EMIS targets are stated in, geometric means over the scenes.
fn print_speedups(table: &[(String, Row)]) {
    let ratio =
        |a: &str, b: &str| -> Vec<f64> { table.iter().filter_map(|(_, r)| Some(err(r, b)? / err(r, a)?)).collect() };
    for (a, b, target) in [
        ("emis-vcm", "vcm", VCM_TARGET),
        ("emis-bdpt", "bdpt", BDPT_TARGET),
        ("emis-vcm", "pt", 0.0),
        ("emis-vcm", "emis-vcm/own-pilot", 0.0),
        ("emis-bdpt", "emis-bdpt/own-pilot", 0.0),
        ("emis-vcm/own-pilot", "vcm", VCM_TARGET),
        ("emis-bdpt/own-pilot", "bdpt", BDPT_TARGET),
        ("emis-vcm/c-pixel", "vcm", VCM_TARGET),
        ("emis-bdpt/c-pixel", "bdpt", BDPT_TARGET),
        ("emis-vcm/c-pixel", "emis-vcm", 0.0),
        ("emis-bdpt/c-pixel", "emis-bdpt", 0.0),
        ("emis-vcm/k-measured", "emis-vcm", 0.0),
        ("emis-bdpt/k-measured", "emis-bdpt", 0.0),
        ("emis-vcm/k-measured", "vcm", VCM_TARGET),
        ("emis-vcm/o-each", "emis-vcm", 0.0),
        ("emis-bdpt/o-each", "emis-bdpt", 0.0),
        ("emis-vcm/o-each", "vcm", VCM_TARGET),
        ("emis-bdpt/o-each", "bdpt", BDPT_TARGET),
        ("emis-vcm/k-measured/o-each", "emis-vcm", 0.0),
        ("emis-bdpt/k-measured/o-each", "emis-bdpt", 0.0),
        ("emis-vcm/k-measured/o-each", "vcm", VCM_TARGET),
        ("emis-bdpt/k-measured/o-each", "bdpt", BDPT_TARGET),
        ("emis-vcm/i-guided", "emis-vcm", 0.0),
        ("emis-bdpt/i-guided", "emis-bdpt", 0.0),
        ("emis-vcm/i-guided", "vcm", VCM_TARGET),
        ("emis-bdpt/i-guided", "bdpt", BDPT_TARGET),
        ("emis-vcm/i-pilot", "emis-vcm", 0.0),
        ("emis-bdpt/i-pilot", "emis-bdpt", 0.0),
    ] {
        let r = ratio(a, b);
        if r.is_empty() {
            continue;
        }
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

/// emis-vcm (each pilot's column) against the better of pt and vcm on every scene (the
/// floor), for the mean over seeds and, with several seeds, for each seed alone.
fn print_floor(table: &[(String, Row)], seeds: &[u64]) {
    let columns = [
        "emis-vcm",
        "emis-vcm/own-pilot",
        "emis-vcm/c-pixel",
        "emis-vcm/k-measured",
        "emis-vcm/o-each",
        "emis-vcm/k-measured/o-each",
        "emis-vcm/i-guided",
        "emis-vcm/i-pilot",
    ];
    for column in columns {
        let floor: Vec<(String, f64)> = table
            .iter()
            .filter_map(|(s, r)| Some((s.clone(), err(r, "pt")?.min(err(r, "vcm")?) / err(r, column)?)))
            .collect();
        if floor.is_empty() {
            continue;
        }
        // (scene, ratio) per seed, so that a scene without one of the columns leaves no gap
        let per_seed: Vec<Vec<(&str, f64)>> = (0..seeds.len())
            .map(|i| {
                table
                    .iter()
                    .filter_map(|(s, r)| {
                        Some((s.as_str(), err_at(r, "pt", i)?.min(err_at(r, "vcm", i)?) / err_at(r, column, i)?))
                    })
                    .collect()
            })
            .collect();
        let met =
            floor.iter().all(|(_, x)| *x >= FLOOR_TARGET) && per_seed.iter().flatten().all(|(_, x)| *x >= FLOOR_TARGET);
        println!(
            "{column} against the better of pt and vcm: {} (target: never below {FLOOR_TARGET}x, \
             for each seed too: {})",
            floor.iter().map(|(s, x)| format!("{s} {x:.2}x")).collect::<Vec<_>>().join(", "),
            if met { "met" } else { "NOT met" }
        );
        if seeds.len() > 1 {
            for (seed, ratios) in seeds.iter().zip(&per_seed) {
                let cells: Vec<String> = ratios.iter().map(|(s, x)| format!("{s} {x:.2}x")).collect();
                println!("  seed {seed} alone: {}", cells.join(", "));
            }
        }
    }
}

/// Every cell's relMSE for each seed alone, so that a mean's spread, and which seed a floor
/// verdict rests on, can be read off.
fn print_per_seed(table: &[(String, Row)], seeds: &[u64]) {
    if seeds.len() < 2 {
        return;
    }
    let names: Vec<&str> = table.first().map(|(_, r)| r.iter().map(|c| c.name.as_str()).collect()).unwrap_or_default();
    println!("relMSE per seed {seeds:?}:\n");
    println!("| scene | {} |", names.join(" | "));
    println!("|---|{}", "---|".repeat(names.len()));
    for (scene, rows) in table {
        let cells: Vec<String> =
            rows.iter().map(|c| c.relmse.iter().map(|e| format!("{e:.3e}")).collect::<Vec<_>>().join(", ")).collect();
        println!("| {scene} | {} |", cells.join(" | "));
    }
    println!();
}

/// How far pt's samples/s moved between its runs of a scene: the host's drift, which an
/// equal-time cell absorbs as noise.
fn print_drift(table: &[(String, Row)]) {
    let spreads: Vec<String> = table
        .iter()
        .filter_map(|(s, r)| {
            let runs = &r.iter().find(|c| c.name == "pt")?.samples_per_s;
            let (lo, hi) = runs.iter().fold((f64::MAX, 0.0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
            (runs.len() > 1).then(|| format!("{s} {:.0} %", 100.0 * (hi / lo - 1.0)))
        })
        .collect();
    if !spreads.is_empty() {
        println!("pt's samples/s, fastest run over slowest: {}", spreads.join(", "));
    }
}

/// Every run's samples/s with its place in the scene's run order, so that a drift of the host
/// can be told from a seed's noise: a cell that ran early and fast flatters its seed.
fn print_run_speeds(table: &[(String, Row)], seeds: &[u64]) {
    let Some((_, first)) = table.first() else { return };
    if first.iter().all(|c| c.samples_per_s.len() < 2) {
        return;
    }
    let names: Vec<&str> = first.iter().map(|c| c.name.as_str()).collect();
    println!("samples/s of every run (seed, place in the scene's run order):\n");
    println!("| scene | {} |", names.join(" | "));
    println!("|---|{}", "---|".repeat(names.len()));
    for (scene, rows) in table {
        let cells: Vec<String> = rows
            .iter()
            .map(|cell| {
                // runs go repeat by repeat, seed by seed
                let runs = cell
                    .samples_per_s
                    .iter()
                    .zip(&cell.places)
                    .enumerate()
                    .map(|(k, (s, place))| format!("{s:.3e} (s{}, #{place})", seeds[k % seeds.len()]));
                runs.collect::<Vec<_>>().join(", ")
            })
            .collect();
        println!("| {scene} | {} |", cells.join(" | "));
    }
    println!();
}

/// The per-seed table and the verdicts again with each cell's error against the truth: the
/// reference's own noise adds the same to every column and pulls ratios towards 1
/// (docs/decisions/0047-reference-noise-in-equal-time.md). Only when every scene has its
/// reference's standard errors.
fn print_against_truth(table: &[(String, Row)], seeds: &[u64]) {
    let truth: Option<Vec<(String, Row)>> = table
        .iter()
        .map(|(scene, row)| {
            let cells = row.iter().map(|c| {
                let relmse = c.truth.clone()?;
                Some(Cell {
                    name: c.name.clone(),
                    relmse,
                    truth: None,
                    elapsed: Vec::new(),
                    samples_per_s: Vec::new(),
                    places: Vec::new(),
                })
            });
            Some((scene.clone(), cells.collect::<Option<Row>>()?))
        })
        .collect();
    let Some(truth) = truth else { return };
    println!("\nagainst the truth: the same, each pixel's se² / (ref² + 1e-4) of the reference subtracted\n");
    print_per_seed(&truth, seeds);
    print_speedups(&truth);
    print_floor(&truth, seeds);
}

/// Draws the speed-ups over pt of one duration as `CHART-{seconds}s.svg`.
fn write_chart(chart: &Path, seconds: f64, names: &[String], table: &[(String, Row)]) -> anyhow::Result<()> {
    let stem = chart.file_stem().and_then(|s| s.to_str()).unwrap_or("equal-time");
    let file = chart.with_file_name(format!("{stem}-{seconds}s.svg"));
    let groups: Vec<Group> = table
        .iter()
        .map(|(s, r)| {
            let pt = err(r, "pt").unwrap_or(f64::NAN);
            Group { label: s.clone(), values: r.iter().map(|c| pt / c.mean()).collect() }
        })
        .collect();
    write_bar_chart(&file, &format!("speed-up over pt at equal time {seconds} s"), names, &groups)?;
    println!("chart: {}", file.display());
    Ok(())
}

/// Runs `tessera bench equal-time`: the comparison for every duration.
pub fn run(args: &EqualTimeArgs) -> anyhow::Result<()> {
    let scenes = args.scenes.scenes()?;
    let names: Vec<String> = columns(args).into_iter().map(|c| c.name).collect();
    for &seconds in &args.seconds.0 {
        let threads = args.scenes.threads.map_or("all".into(), |t| t.to_string());
        println!("\n## equal time {seconds} s ({threads} threads)\n");
        println!(
            "relMSE against the reference (top 0.1 % dropped) × seconds taken / {seconds} s (mean over \
             seeds {:?}, {} run(s) each), speed-up over pt = relMSE(pt) / relMSE, samples/s, mean seconds taken\n",
            args.seeds, args.repeats
        );
        println!("| scene | {} |", names.join(" | "));
        println!("|---|{}", "---|".repeat(names.len()));
        let mut table = Vec::new();
        for path in &scenes {
            let rows = equal_time_scene(args, path, seconds)?;
            println!("{}", table_line(&scene_name(path), &rows));
            table.push((scene_name(path), rows));
        }
        println!();
        print_per_seed(&table, &args.seeds);
        print_drift(&table);
        print_run_speeds(&table, &args.seeds);
        print_speedups(&table);
        print_floor(&table, &args.seeds);
        print_against_truth(&table, &args.seeds);
        if let Some(chart) = &args.chart {
            write_chart(chart, seconds, &names, &table)?;
        }
    }
    Ok(())
}
