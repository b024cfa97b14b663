//! Merge moments per tile (docs/decisions/0018-decision-quality-tests.md): a `vcm` pilot with
//! ν = 0.5, c = 1 and a checkerboard merge mask (8×8-pixel squares of χ = 1 and χ = 0.25)
//! predicts, through δ, the second moments of the merge-on (χ = 1 everywhere) and merge-off
//! (χ = 0) candidates at its own ν and c; rendering those two candidates measures them.
//!
//! What is compared, per candidate: the mean per-iteration Σ y² (y the channel mean of a
//! sample's contribution, the square of what the image receives; light-tracing samples in
//! the pixel they land in), over each 8×8 tile and over all squares of each χ. Its expectation
//! is exactly what the estimator predicts, whatever the correlations, by linearity. Iterations
//! are independent, so each mean's standard error comes from the per-iteration spread, and a
//! prediction must agree with the measurement within [`Z_TILE`] (per tile) and [`Z_SQUARES`]
//! (per χ) combined standard errors.
//!
//! ν ≠ 1 tells the merge ratio χ·ν from the retired χ (decision 0001), the fractional χ
//! exercises the 1/χ of merges in δ, and the direct renders' literal squares check the
//! kernel's. Cornell-box, because its per-tile sums are
//! well behaved (caustic-glass's rare caustic paths make 8×8 tiles too noisy to tell anything
//! apart at this cost); Russian roulette is off, as in `emis_moments.rs`, since its survival
//! probabilities are not part of the densities; paths end after 6 segments, which halves the
//! cost in a closed box and changes nothing the estimator relies on.

mod common;

use common::{mean_and_standard_error, scene_path};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use tessera_common::emis::candidate::Candidate;
use tessera_common::emis::estimator::MomentEstimator;
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::observer::{SampleObserver, SampleRecord};
use tessera_common::integrator::path::merge::{MergeConfig, MergeMask};
use tessera_common::integrator::{Bidir, Integrator, PathSettings, TileRequest};
use tessera_common::scene::Scene;

const SIZE: u32 = 128;
const TILE: u32 = 8;
const TILES: usize = ((SIZE / TILE) * (SIZE / TILE)) as usize;
const NU: f32 = 0.5;
const CONNECTIONS: u32 = 1;

/// Tolerance per tile, in combined standard errors: 2 candidates × 256 tiles are compared,
/// and a family-wise false alarm rate of 1 % needs |z| < 4.3 for normal means (Šidák, a
/// two-sided α of 2e-5 per tile); Student's t with the ~95 degrees of freedom of 96
/// iterations' standard errors needs about 4.6, and the sums' skew a little more.
const Z_TILE: f64 = 5.5;

/// Tolerance per χ (2 candidates × 2 kinds of square): 4 standard errors, a family-wise false
/// alarm rate below 0.1 % for normal means.
const Z_SQUARES: f64 = 4.0;

/// Iterations per render: 96, or `EMIS_IT` for longer manual checks.
fn iterations() -> u32 {
    std::env::var("EMIS_IT").ok().and_then(|v| v.parse().ok()).unwrap_or(96)
}

fn tile_of(pixel: u32) -> usize {
    let (x, y) = (pixel % SIZE, pixel / SIZE);
    ((y / TILE) * (SIZE / TILE) + x / TILE) as usize
}

/// Whether tile `t` is a χ = 1 square.
fn full_square(t: usize) -> bool {
    let (tx, ty) = (t as u32 % (SIZE / TILE), t as u32 / (SIZE / TILE));
    (tx + ty) % 2 == 0
}

/// χ = 1 and χ = 0.25 in alternating 8×8 squares, aligned with the tiles.
fn checkerboard() -> Vec<f32> {
    (0..SIZE * SIZE).map(|p| if full_square(tile_of(p)) { 1.0 } else { 0.25 }).collect()
}

/// Σ y² per tile of every sample a render makes.
struct TileSquares(Vec<AtomicU64>);

impl TileSquares {
    fn new() -> Self {
        TileSquares((0..TILES).map(|_| AtomicU64::new(0f64.to_bits())).collect())
    }

    fn sums(&self) -> Vec<f64> {
        self.0.iter().map(|a| f64::from_bits(a.load(Ordering::Relaxed))).collect()
    }
}

impl SampleObserver for TileSquares {
    fn on_sample(&self, record: &SampleRecord) {
        let y = ((record.value.x + record.value.y + record.value.z) / 3.0) as f64;
        if !y.is_finite() {
            return;
        }
        let add = |old: u64| Some((f64::from_bits(old) + y * y).to_bits());
        let _ = self.0[tile_of(record.pixel)].fetch_update(Ordering::Relaxed, Ordering::Relaxed, add);
    }
}

fn scene() -> (Scene, PathSettings) {
    let scene =
        Scene::load(&scene_path("cornell-box")).expect("scene loads").with_resolution(SIZE, SIZE).expect("square");
    let settings = PathSettings { rr_depth: u32::MAX, ..PathSettings::from_scene(&scene, Some(6)) };
    (scene, settings)
}

fn vcm(settings: PathSettings, mask: MergeMask) -> Bidir {
    Bidir::vcm(settings, NU, CONNECTIONS, MergeConfig { mask, correlation_aware: true })
}

fn render_iteration(scene: &Scene, integrator: &impl Integrator, it: u32, seed: u64) {
    let full = Rect::full(SIZE, SIZE);
    integrator.render_tile(scene, &TileRequest::new(full, it..it + 1, seed), &mut TileAccum::new(full, &scene.film));
}

/// Per iteration: per candidate (off, on), per tile, Σ y².
type Sums = Vec<[Vec<f64>; 2]>;

/// The pilot's predictions of the merge-off and merge-on candidates at each of `nus` light
/// paths per pixel, all watching the same samples.
fn predicted(nus: &[f32]) -> Vec<Sums> {
    let (scene, path) = scene();
    let mask = MergeMask::PerPixel(Arc::new(checkerboard()));
    let mut out = vec![Vec::new(); nus.len()];
    for it in 0..iterations() {
        let estimators: Vec<MomentEstimator> = nus
            .iter()
            .map(|&nu| {
                let candidates = [false, true].map(|merge| Candidate { nu, connections: CONNECTIONS, merge });
                MomentEstimator::new(SIZE, SIZE, &candidates)
            })
            .collect();
        render_iteration(&scene, &vcm(path, mask.clone()).with_observer(&estimators[..]), it, 1);
        for (o, e) in out.iter_mut().zip(&estimators) {
            let (buffer, _) = e.snapshot();
            o.push([0, 1].map(|c| {
                let mut tiles = vec![0.0; TILES];
                for p in 0..SIZE * SIZE {
                    tiles[tile_of(p)] += buffer.moment(p, c);
                }
                tiles
            }));
        }
    }
    out
}

/// The candidates rendered with χ = 0 and χ = 1 everywhere, measured.
fn measured() -> Sums {
    let (scene, path) = scene();
    (0..iterations())
        .map(|it| {
            [0.0, 1.0].map(|chi| {
                let squares = TileSquares::new();
                render_iteration(&scene, &vcm(path, MergeMask::Constant(chi)).with_observer(&squares), it, 2);
                squares.sums()
            })
        })
        .collect()
}

/// The z-score of predicted against measured for the per-iteration sum over `tiles`.
fn z_score(pilot: &Sums, direct: &Sums, candidate: usize, tiles: &[usize]) -> f64 {
    let sum = |it: &[Vec<f64>; 2]| tiles.iter().map(|&t| it[candidate][t]).sum::<f64>();
    let p = mean_and_standard_error(pilot.iter().map(sum));
    let d = mean_and_standard_error(direct.iter().map(sum));
    let sigma = (p.1 * p.1 + d.1 * d.1).sqrt();
    if sigma > 0.0 { (p.0 - d.0) / sigma } else { 0.0 }
}

/// Every comparison that fails, as a message (empty: the pilot predicts the measurements).
fn disagreements(label: &str, pilot: &Sums, direct: &Sums) -> Vec<String> {
    let mut failures = Vec::new();
    for (c, candidate) in ["merge off", "merge on"].iter().enumerate() {
        let z: Vec<f64> = (0..TILES).map(|t| z_score(pilot, direct, c, &[t])).collect();
        let (tile, worst) =
            z.iter().enumerate().fold((0, 0.0f64), |a, (t, v)| if v.abs() > a.1 { (t, v.abs()) } else { a });
        eprintln!(
            "{label}, {candidate}: worst tile {tile} at |z| {worst:.2}, {} tiles beyond 4",
            z.iter().filter(|v| v.abs() > 4.0).count()
        );
        if worst > Z_TILE {
            failures.push(format!("{label}, {candidate}: tile {tile} is {worst:.2} standard errors off"));
        }
        for (chi, full) in [("χ = 1", true), ("χ = 0.25", false)] {
            let squares: Vec<usize> = (0..TILES).filter(|&t| full_square(t) == full).collect();
            let z = z_score(pilot, direct, c, &squares);
            eprintln!("{label}, {candidate}, all {chi} squares: z {z:.2}");
            if z.abs() > Z_SQUARES {
                failures.push(format!("{label}, {candidate}: the {chi} squares are {z:.2} standard errors off"));
            }
        }
    }
    failures
}

#[test]
fn merge_moments_per_tile_agree_with_direct_renders() {
    // the candidates at twice the rendered ν (the error of the retired merge ratio χ, which
    // ignored ν, in the other direction): the test must tell them apart
    let pilots = predicted(&[NU, 2.0 * NU]);
    let direct = measured();
    let failures = disagreements("estimator", &pilots[0], &direct);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(!disagreements("candidates at 2ν", &pilots[1], &direct).is_empty(), "the comparison has power");
}
