//! `tessera bench …`: every measurement of the renderer, EMIS and the farm, one subcommand
//! each. Speed and quality are measured here, never by timed tests: the machines are shared and
//! noisy, so every mode compares side by side within one run.

pub mod calibrate;
pub mod chart;
pub mod decision_truth;
pub mod envmap;
pub mod equal_time;
pub mod farm;
pub mod ground_truth;
pub mod overheads;
pub mod photon_map;
pub mod pt_recording;
pub mod speed;
pub mod warm_start;

use anyhow::Context;
use clap::Subcommand;
use std::path::PathBuf;
use tessera_common::emis::cost::CostModel;
use tessera_common::emis::denoise::ImageEstimate;
use tessera_common::emis::optimize::OutlierStage;
use tessera_common::settings::RenderSettings;

/// The measurements.
#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Samples per second of an integrator on scenes, optionally beside Mitsuba 3.
    Speed(speed::SpeedArgs),
    /// Every scene with every integrator for the same time: relMSE against the reference,
    /// speed-ups and the EMIS targets.
    EqualTime(equal_time::EqualTimeArgs),
    /// EMIS overheads: moment accumulation, optimiser and denoiser time, moment memory.
    Overheads(overheads::OverheadsArgs),
    /// Does the EMIS pilot choose what the candidates' measured errors would choose?
    GroundTruth(ground_truth::GroundTruthArgs),
    /// The brute-force truth of the EMIS decision-quality tests: every image-level candidate's
    /// relative variance and time at 128², written as JSON for `common/tests`.
    DecisionTruth(decision_truth::DecisionTruthArgs),
    /// Time path tracing, light tracing, connections and merging and fit the EMIS cost
    /// heuristic's constants.
    CalibrateCosts(calibrate::CalibrateArgs),
    /// Photon-map build and query rates.
    PhotonMap(photon_map::PhotonMapArgs),
    /// Time and memory to make an environment map render-ready (8k x 4k by default).
    Envmap(envmap::EnvmapArgs),
    /// The farm coordinator: result ingest, scaling with real workers, bytes on the wire.
    Farm(farm::FarmArgs),
    /// EMIS frames started from the frame before's decision against started cold, at equal
    /// time on a camera move.
    WarmStart(warm_start::WarmStartArgs),
}

/// Runs a `tessera bench` subcommand.
pub fn run(command: &BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Speed(args) => speed::run(args),
        BenchCommand::EqualTime(args) => equal_time::run(args),
        BenchCommand::Overheads(args) => overheads::run(args),
        BenchCommand::GroundTruth(args) => ground_truth::run(args),
        BenchCommand::DecisionTruth(args) => decision_truth::run(args),
        BenchCommand::CalibrateCosts(args) => calibrate::run(args),
        BenchCommand::PhotonMap(args) => photon_map::run(args),
        BenchCommand::Envmap(args) => envmap::run(args),
        BenchCommand::Farm(args) => farm::run(args),
        BenchCommand::WarmStart(args) => warm_start::run(args),
    }
}

/// The EMIS optimiser's model variants, experiments `tessera bench` compares (`tessera render`
/// and farm jobs use the defaults).
#[derive(clap::Args, Debug, Clone)]
pub struct EmisModelArgs {
    /// emis-*: cost heuristic constants: calibrated on this renderer, or measured per job.
    #[arg(long, value_enum, default_value = "calibrated")]
    pub cost_model: CostModel,
    /// emis-*: before the image-level sums reject each candidate's outliers (the reference's
    /// rule), first take out, where it is an outlier, the part of a pixel's moment that every
    /// candidate shares (rare samples no strategy can change), before the box filter spreads
    /// it over the neighbours; or apply the reference's rule alone.
    #[arg(long, value_enum, default_value = "shared")]
    pub moment_outliers: OutlierStage,
    /// emis-*: the image estimate Ī the moments are made relative to: the pilot image (its
    /// channel mean and radius-3 box), or the pilot image denoised by the guided filter first.
    /// A path-tracing start's updates use the guided filter either way.
    #[arg(long, value_enum, default_value = "pilot")]
    pub emis_image: ImageEstimate,
}

impl EmisModelArgs {
    /// Sets these options in `settings`.
    pub fn apply(&self, settings: &mut RenderSettings) {
        settings.cost_model = self.cost_model;
        settings.moment_outliers = self.moment_outliers;
        settings.emis_image = self.emis_image;
    }
}

/// The scenes and threads most modes take.
#[derive(clap::Args, Debug, Clone)]
pub struct SceneArgs {
    /// Scene files [default: every scenes/*/scene.xml].
    pub scenes: Vec<PathBuf>,
    /// Render threads [default: all cores].
    #[arg(long)]
    pub threads: Option<usize>,
}

impl SceneArgs {
    /// The scenes given, or every `scenes/*/scene.xml` under the working directory.
    pub fn scenes(&self) -> anyhow::Result<Vec<PathBuf>> {
        if !self.scenes.is_empty() {
            return Ok(self.scenes.clone());
        }
        let mut v: Vec<PathBuf> = std::fs::read_dir("scenes")
            .context("no scenes given and no ./scenes folder")?
            .filter_map(|e| e.ok())
            .map(|e| e.path().join("scene.xml"))
            .filter(|p| p.exists())
            .collect();
        v.sort();
        Ok(v)
    }

    /// A thread pool of `--threads` threads (all cores by default).
    pub fn pool(&self) -> anyhow::Result<rayon::ThreadPool> {
        Ok(rayon::ThreadPoolBuilder::new().num_threads(self.threads.unwrap_or(0)).build()?)
    }
}

/// Process CPU time (user + system) in seconds.
pub fn cpu_seconds() -> f64 {
    // SAFETY: getrusage only writes into the struct we pass
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut usage) };
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(usage.ru_utime) + tv(usage.ru_stime)
}

/// The geometric mean of positive values (NaN for none).
pub fn geometric_mean(v: &[f64]) -> f64 {
    (v.iter().map(|x| x.ln()).sum::<f64>() / v.len() as f64).exp()
}
