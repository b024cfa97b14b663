//! Diagnosis of decision 0037 (ignored, prints, asserts only its own bookkeeping): how the
//! light-path part of `emis-vcm`'s predicted moments grows with the pilot's length on
//! caustic-glass at 128², and whether that growth is the pilot's strategy changing or the
//! samples' heavy tail.
//!
//! `cargo test --release -p tessera-common --test light_path_moments -- --ignored --nocapture`
//! (about a minute after the build).
//!
//! 1. One update after n iterations of the fixed `vcm` pilot (n = 4, 16, 64, 256), so the
//!    strategy never changes: each candidate's predicted relative moment, and A + B/ν fitted
//!    to the c = 1 candidates at ν 0.25 and 2 (A: the part light paths do not change, B: the
//!    light-path part), beside the brute-force truth of `tests/data/emis-decision-truth.json`.
//! 2. The raw moment sums (no filter, no outlier rule) of the first 4 iterations against
//!    those of the next 60, relative to the converged reference: means, means without the
//!    top 16 pixels (0.1 %), and the share of the top 16.
//! 3. The median of means over groups of iterations against the plain mean (decision 0070).

mod common;

use common::scene_path;
use tessera_common::emis::decision_truth::{DecisionTruth, SceneTruth};
use tessera_common::emis::{EmisConfig, EmisMethod, EmisState, UpdateReport, render_emis};
use tessera_common::integrator::PathSettings;
use tessera_common::render::{Budget, RenderOptions};
use tessera_common::scene::Scene;

/// Side of the square images, as in the cached truth.
const SIZE: usize = 128;
const SCENE: &str = "caustic-glass";
const SEED: u64 = 3;

fn truth() -> SceneTruth {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/emis-decision-truth.json");
    let truth: DecisionTruth = serde_json::from_str(&std::fs::read_to_string(path).expect("truth")).expect("parses");
    truth.scene(SCENE).expect("the truth has the scene").clone()
}

/// The scene at `SIZE`².
fn scene() -> Scene {
    let scene = Scene::load(&scene_path(SCENE)).expect("loads");
    scene.with_resolution(SIZE as u32, SIZE as u32).expect("a square image")
}

/// The state after a `vcm` pilot of `iterations` with one update at its end.
fn pilot(scene: &Scene, iterations: u32) -> EmisState {
    let config = EmisConfig { updates: vec![iterations], ..EmisConfig::new(EmisMethod::Vcm) };
    let opts = RenderOptions { budget: Budget::Samples(iterations + 1), seed: SEED, threads: 0, tile_size: 32 };
    render_emis(scene, PathSettings::from_scene(scene, None), &config, &opts, &|_, _| {}).expect("render").state
}

fn predicted(report: &UpdateReport, nu: f32) -> f64 {
    let score = report.candidates.iter().find(|s| s.nu == nu && s.connections == Some(1));
    score.expect("an image-level candidate (ν, 1)").relative_moment
}

/// A and B of A + B/ν through the values at ν 0.25 and ν 2.
fn fit(at_quarter: f64, at_two: f64) -> (f64, f64) {
    let b = (at_quarter - at_two) / (4.0 - 0.5);
    (at_two - b / 2.0, b)
}

#[test]
#[ignore = "a diagnosis (decision 0037): prints, about a minute"]
fn light_path_part_grows_with_a_fixed_pilot() {
    let truth = truth();
    let scene = scene();
    let t = |nu: f32| truth.candidate(nu, 1).expect("a candidate").trimmed_variance;
    let (a, b) = fit(t(0.25), t(2.0));
    eprintln!("| pilot | ν 0.25 | ν 0.5 | ν 1 | ν 2 | A | B |\n|---|---|---|---|---|---|---|");
    eprintln!("| truth | {:.3} | {:.3} | {:.3} | {:.3} | {a:.2} | {b:.2} |", t(0.25), t(0.5), t(1.0), t(2.0));
    for n in [4, 16, 64, 256] {
        let state = pilot(&scene, n);
        let report = state.reports.last().expect("one update");
        assert_eq!((report.iteration, state.moments.iterations), (n, n));
        let p = |nu: f32| predicted(report, nu);
        let (a, b) = fit(p(0.25), p(2.0));
        eprintln!("| {n} | {:.3} | {:.3} | {:.3} | {:.3} | {a:.2} | {b:.2} |", p(0.25), p(0.5), p(1.0), p(2.0));
    }
}

#[test]
#[ignore = "a diagnosis (decision 0037): prints, about half a minute"]
fn first_iterations_against_the_next() {
    let scene = scene();
    let (short, long) = (pilot(&scene, 4), pilot(&scene, 64));
    // the same seed: the long pilot's first 4 iterations are the short one's
    let reference = common::reference_intensity(SCENE, SIZE);
    let k = short.candidates.len();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let without_top = |v: &[f64]| {
        let mut s = v.to_vec();
        s.sort_by(|x, y| y.total_cmp(x));
        (mean(&s[16..]), s[..16].iter().sum::<f64>() / s.iter().sum::<f64>())
    };
    eprintln!("| ν | c | merge | mean, 0–4 | 4–64 | without top 16, 0–4 | 4–64 | top 16's share, 0–4 | 4–64 |");
    eprintln!("|---|---|---|---|---|---|---|---|---|");
    for (i, c) in short.candidates.iter().enumerate().filter(|(_, c)| c.connections == 1 || c.nu == 0.0) {
        let (mut first, mut next) = (Vec::new(), Vec::new());
        for (p, &r) in reference.iter().enumerate() {
            let (s4, s64) = (short.moments.sums[p * k + i] as f64, long.moments.sums[p * k + i] as f64);
            if s64.is_finite() {
                let norm = (r * r) as f64 + 1e-4;
                first.push(s4 / 4.0 / norm);
                next.push((s64 - s4) / 60.0 / norm);
            }
        }
        let ((f, fs), (n, ns)) = (without_top(&first), without_top(&next));
        eprintln!(
            "| {} | {} | {} | {:.3} | {:.3} | {f:.3} | {n:.3} | {fs:.2} | {ns:.2} |",
            c.nu,
            c.connections,
            c.merge,
            mean(&first),
            mean(&next)
        );
    }
}

/// Issue 21, item 4: would a median of means over groups of iterations estimate the moments
/// better than their plain mean? The image mean of each candidate's per-pixel moment
/// (relative to the converged reference): the plain mean over 64 iterations, the median of the
/// means of 8 groups of 8 and of 4 groups of 16, and the plain mean over 256 iterations, the
/// nearest this test gets to the expectation.
#[test]
#[ignore = "a diagnosis (decision 0070): prints, about fifteen seconds"]
fn median_of_means_against_the_mean() {
    let scene = scene();
    let reference = common::reference_intensity(SCENE, SIZE);
    // the same seed: a longer pilot's first iterations are a shorter one's
    let prefixes: Vec<(u32, EmisState)> = (1..=8).map(|g| (8 * g, pilot(&scene, 8 * g))).collect();
    let long = pilot(&scene, 256);
    let k = long.candidates.len();
    let median = |v: &mut Vec<f64>| {
        v.sort_by(|x, y| x.total_cmp(y));
        let m = v.len() / 2;
        if v.len() % 2 == 0 { (v[m - 1] + v[m]) / 2.0 } else { v[m] }
    };
    eprintln!("| ν | c | merge | mean of 64 | median of 8 × 8 | median of 4 × 16 | mean of 256 |");
    eprintln!("|---|---|---|---|---|---|---|");
    for (i, c) in long.candidates.iter().enumerate().filter(|(_, c)| c.connections == 1 || c.nu == 0.0) {
        let (mut mean64, mut mom8, mut mom16, mut mean256, mut pixels) = (0.0, 0.0, 0.0, 0.0, 0usize);
        for (p, &r) in reference.iter().enumerate() {
            let sums: Vec<f64> = prefixes.iter().map(|(_, s)| s.moments.sums[p * k + i] as f64).collect();
            let s256 = long.moments.sums[p * k + i] as f64;
            if !s256.is_finite() || sums.iter().any(|s| !s.is_finite()) {
                continue;
            }
            let norm = (r * r) as f64 + 1e-4;
            let mut groups8: Vec<f64> =
                (0..8).map(|g| (sums[g] - if g == 0 { 0.0 } else { sums[g - 1] }) / 8.0 / norm).collect();
            let mut groups16: Vec<f64> =
                (0..4).map(|g| (sums[2 * g + 1] - if g == 0 { 0.0 } else { sums[2 * g - 1] }) / 16.0 / norm).collect();
            mean64 += sums[7] / 64.0 / norm;
            mom8 += median(&mut groups8);
            mom16 += median(&mut groups16);
            mean256 += s256 / 256.0 / norm;
            pixels += 1;
        }
        let n = pixels as f64;
        eprintln!(
            "| {} | {} | {} | {:.3} | {:.3} | {:.3} | {:.3} |",
            c.nu,
            c.connections,
            c.merge,
            mean64 / n,
            mom8 / n,
            mom16 / n,
            mean256 / n
        );
    }
    assert_eq!(prefixes.last().map(|(n, s)| (*n, s.moments.iterations)), Some((64, 64)));
}
