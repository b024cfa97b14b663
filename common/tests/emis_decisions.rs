//! Decision-quality regression tests of `emis-vcm` (docs/decisions/0018-decision-quality-tests.md):
//! at 128², on three scenes of different character, the (ν, c) the updates after 4 and 16
//! iterations choose must be within 1.25× of the best image-level candidate's work-normalised
//! error (relMSE × time, relMSE as the equal-time benchmark measures it: without the top 0.1 %
//! of pixels), for seeds 1, 2 and 3. The truth is brute force, measured once by
//! `tessera bench decision-truth` and cached in `tests/data/emis-decision-truth.json`
//! ([`DecisionTruth`]); these tests only run the optimiser's own renders (17 iterations per
//! seed), which are deterministic, so the tests are too.
//!
//! Plus one invariant per extreme: where light paths are essential (caustic-glass) every
//! update keeps ν > 0; where path tracing wins (veach-mis) the merge mask stays almost empty.
//! docs/decisions/0018-decision-quality-tests.md, 0028-pilot-image-not-denoised.md and
//! 0046-incumbent-margin.md have the figures.
//! `EMIS_DIAG=1` prints every candidate's prediction beside its truth at each judged update;
//! `EMIS_OUTLIERS=each` decides with that outlier rule instead of the default;
//! `EMIS_INCUMBENT_MARGIN=0` (or another scale) with that incumbent margin.
//!
//! Those tests judge the method's own pilot (`EmisConfig::own_pilot`), whose updates all
//! decide from the full set. The default pilot (path tracing first, what `tessera render` and
//! farm jobs run) is judged by the decision its render ends on, the last update's, within the
//! same 1.25 (`default_pilot_*`). On caustic-glass at seed 1 that fails: path tracing sees no
//! caustic path in 16 iterations at 128², wins every update and ends there (regret 7.07), so
//! that test is ignored and says so; requiring 4 recorded iterations before path tracing
//! settles does not change it (measured: it keeps path tracing at 16).
//!
//! Regenerate the truth after a change that alters what candidates render or cost (from the
//! repository root, release build, an otherwise idle machine; about 45 minutes on 2 cores):
//!
//! ```text
//! cargo run --release -- bench decision-truth scenes/caustic-glass/scene.xml \
//!     scenes/cornell-box/scene.xml scenes/veach-mis/scene.xml
//! ```

mod common;

use common::scene_path;
use tessera_common::emis::{EmisConfig, EmisMethod, PilotStart, UpdateReport, render_emis};
use tessera_common::integrator::PathSettings;
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::Scene;
use tessera_testing::decision_truth::{DecisionTruth, SceneTruth};

/// Side of the square images.
const SIZE: u32 = 128;
/// The seeds every scene is decided with.
const SEEDS: [u64; 3] = [1, 2, 3];
/// The updates judged.
const JUDGED: [u32; 2] = [4, 16];
/// Largest regret accepted: the chosen (ν, c)'s relMSE × time over the best candidate's.
const MAX_REGRET: f64 = 1.25;

fn truth(name: &str) -> SceneTruth {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/emis-decision-truth.json");
    let text = std::fs::read_to_string(&path).expect("the cached truth exists");
    let truth: DecisionTruth = serde_json::from_str(&text).expect("the cached truth parses");
    assert_eq!((truth.width, truth.height), (SIZE, SIZE), "the truth is for {SIZE}² renders");
    let scene = truth.scene(name).unwrap_or_else(|| panic!("the truth has {name}")).clone();
    assert_eq!(scene.candidates.len(), 26, "{name}: 25 (ν, c) and path tracing");
    scene
}

/// Every update's report of one `emis-vcm` render at `SIZE`² with `pilot`.
fn updates(name: &str, seed: u64, pilot: PilotStart) -> Vec<UpdateReport> {
    let scene = Scene::load(&scene_path(name)).expect("scene loads").with_resolution(SIZE, SIZE).expect("square");
    // the update after 16 runs only if an iteration follows it
    let mut config = EmisConfig { updates: vec![1, 4, 16], pilot, ..EmisConfig::own_pilot(EmisMethod::Vcm) };
    if let Ok(rule) = std::env::var("EMIS_OUTLIERS") {
        config.filters.outliers = serde_json::from_value(rule.into()).expect("EMIS_OUTLIERS: shared or each");
    }
    if let Ok(margin) = std::env::var("EMIS_INCUMBENT_MARGIN") {
        config.incumbent_margin = margin.parse().expect("EMIS_INCUMBENT_MARGIN: a number");
    }
    let opts = RenderOptions { budget: Budget::Samples(17), seed, threads: 0, tile_size: 32 };
    let out = render_emis(&scene, PathSettings::from_scene(&scene, None), &config, &opts, &|_, _| {}).expect("render");
    out.state.reports
}

/// The reports of the judged updates of one render with the method's own pilot.
fn judged_updates(name: &str, seed: u64) -> Vec<UpdateReport> {
    let reports = updates(name, seed, PilotStart::Bidirectional);
    reports.into_iter().filter(|r| JUDGED.contains(&r.iteration)).collect()
}

/// One judged update with its regret.
struct Judged {
    report: UpdateReport,
    line: String,
    regret: f64,
}

/// Every seed's judged updates with their regrets, printed as a table.
fn judge(name: &str) -> Vec<Judged> {
    let truth = truth(name);
    let best = truth.best().expect("candidates");
    eprintln!("{name}: best ν {} c {}", best.nu, best.connections);
    eprintln!("| scene | seed | update | ν | c | mean χ | regret | every pixel | cost model |");
    let mut judged = Vec::new();
    for seed in SEEDS {
        let updates = judged_updates(name, seed);
        assert_eq!(updates.len(), JUDGED.len(), "{name}, seed {seed}: updates after 4 and 16 iterations");
        for report in updates {
            let regret = truth.regret(report.nu, report.connections).expect("the decision is a candidate");
            let model = truth.model_regret(report.nu, report.connections).expect("the decision is a candidate");
            let untrimmed = truth.untrimmed_regret(report.nu, report.connections).expect("the decision is a candidate");
            let line = format!(
                "| {name} | {seed} | {} | {} | {} | {:.3} | {regret:.3} | {untrimmed:.3} | {model:.3} |",
                report.iteration, report.nu, report.connections, report.mean_merge_probability
            );
            eprintln!("{line}");
            if std::env::var("EMIS_DIAG").is_ok() {
                print_predictions(&truth, &report);
            }
            judged.push(Judged { report, line, regret });
        }
    }
    judged
}

/// Every candidate's predicted relative moment × cost at an update beside its truth, for
/// finding out why a decision went wrong (`EMIS_DIAG=1`).
fn print_predictions(truth: &SceneTruth, report: &UpdateReport) {
    // the default, image-level connections: every candidate has its c
    for c in &report.candidates {
        let connections = c.connections.expect("an image-level c");
        let t = truth.candidate(c.nu, connections).expect("the prediction is a candidate");
        eprintln!(
            "  update {} ν {} c {}: predicted {:.3e} × cost {:.2} = {:.3e}; truth {:.3e} (every pixel {:.3e}) × {:.2} ms, regret {:.2}",
            report.iteration,
            c.nu,
            connections,
            c.relative_moment,
            c.cost,
            c.work_normalised,
            t.trimmed_variance,
            t.relative_variance,
            t.seconds * 1e3,
            truth.regret(c.nu, connections).unwrap_or(f64::NAN)
        );
    }
}

/// Fails with every judged update whose regret is above [`MAX_REGRET`].
fn assert_regrets(name: &str, judged: &[Judged]) {
    let failures: Vec<&str> = judged.iter().filter(|j| j.regret > MAX_REGRET).map(|j| j.line.as_str()).collect();
    assert!(failures.is_empty(), "{name}: regret above {MAX_REGRET}:\n{}", failures.join("\n"));
}

/// Light paths are essential: a caustic seen directly and through glass. Every update keeps
/// ν > 0.
#[test]
fn caustic_glass_decisions_keep_light_paths() {
    for j in &judge("caustic-glass") {
        assert!(j.report.nu > 0.0, "caustic-glass: path tracing chosen: {}", j.line);
    }
}

/// The light-path part of the moments is heavy-tailed and a short pilot sees a fraction of
/// it (docs/decisions/0036-light-path-moments-underestimated.md), so after 4 iterations
/// cheaper, noisier candidates look a few per cent better than the pilot's (ν 1, c 1) and were
/// chosen at regret 1.40–1.84; the incumbent margin keeps (ν 1, c 1), regret 1.14
/// (docs/decisions/0046-incumbent-margin.md).
#[test]
fn caustic_glass_decisions_are_near_the_best() {
    assert_regrets("caustic-glass", &judge("caustic-glass"));
}

/// In between: diffuse interreflection, where light tracing and connections help a little.
#[test]
fn cornell_box_decisions_are_near_the_best() {
    assert_regrets("cornell-box", &judge("cornell-box"));
}

/// Path tracing wins: glossy plates lit by small lights, where light paths add cost but
/// little variance reduction. Merging should be almost nowhere: mean χ below 0.05, 5 % of the
/// image. At 128² the mask's radii are 4 px (16 at 640×480, in proportion), so one pixel whose
/// merge bit wins becomes a spot worth 9² pixels of χ, 0.005 of the image: the bound allows
/// about ten such spots.
#[test]
fn veach_mis_merges_almost_nowhere() {
    for j in &judge("veach-mis") {
        assert!(j.report.mean_merge_probability < 0.05, "veach-mis: merging: {}", j.line);
    }
}

/// Passes since Ī is the pilot image not denoised (decision 0028): the guided filter darkened
/// the two-pixel lights 60–200 times, and light paths won with regret 1.70–2.74.
#[test]
fn veach_mis_decisions_are_near_the_best() {
    assert_regrets("veach-mis", &judge("veach-mis"));
}

/// The decision a render with the default pilot (path tracing first) ends on, the last
/// update's, for every seed, with its regret, printed as a table.
fn judge_default(name: &str) -> Vec<Judged> {
    let truth = truth(name);
    eprintln!("| scene | seed | updates (iteration: ν c, R restarted, S settled) | regret |");
    SEEDS
        .iter()
        .map(|&seed| {
            let reports = updates(name, seed, PilotStart::PathTracing);
            let report = reports.last().expect("the update after 1 runs").clone();
            let regret = truth.regret(report.nu, report.connections).expect("the decision is a candidate");
            let steps: Vec<String> = reports
                .iter()
                .map(|r| {
                    let marks = format!("{}{}", if r.restarted { " R" } else { "" }, if r.settled { " S" } else { "" });
                    format!("{}: {} {}{marks}", r.iteration, r.nu, r.connections)
                })
                .collect();
            let line = format!("| {name} | {seed} | {} | {regret:.3} |", steps.join(", "));
            eprintln!("{line}");
            Judged { report, line, regret }
        })
        .collect()
}

/// The default pilot on caustic-glass: the render ends on light paths, near the best. Fails
/// at seed 1 (module documentation): a known defect of the path-tracing start, not fixed.
#[test]
#[ignore = "known defect: the path-tracing start never sees caustic-glass's caustic at seed 1 (regret 7.07)"]
fn default_pilot_on_caustic_glass_ends_on_light_paths_near_the_best() {
    let judged = judge_default("caustic-glass");
    for j in &judged {
        assert!(j.report.nu > 0.0, "caustic-glass: ends in path tracing: {}", j.line);
    }
    assert_regrets("caustic-glass", &judged);
}

/// The default pilot on cornell-box ends near the best.
#[test]
fn default_pilot_on_cornell_box_ends_near_the_best() {
    assert_regrets("cornell-box", &judge_default("cornell-box"));
}

/// The default pilot on veach-mis ends near the best.
#[test]
fn default_pilot_on_veach_mis_ends_near_the_best() {
    assert_regrets("veach-mis", &judge_default("veach-mis"));
}
