//! Command-line options shared by `tessera render`, `tessera submit` and the benchmarks: the
//! path-length, sample-count, merging and EMIS switches (their values are the renderer's own
//! setting enums, which derive `clap::ValueEnum` with `tessera-common`'s `clap` feature),
//! `-D` definitions and scene names. Of EMIS, when to update and which pilot are a user's choice;
//! the optimiser's research variants are one `--emis-experiment KEY=VALUE`.

use clap::ValueEnum;
use std::collections::HashMap;
use std::path::Path;
use tessera_common::emis::PilotStart;
use tessera_common::emis::cost::CostModel;
use tessera_common::emis::denoise::ImageEstimate;
use tessera_common::emis::optimize::{ConnectionScope, OutlierStage};
use tessera_common::scene::Scene;
use tessera_common::settings::{IntegratorName, RenderSettings, Renderer, SettingsError};

/// Path length, sample counts, merging and EMIS options, shared by `render` and `submit`.
#[derive(clap::Args, Debug, Clone)]
pub struct IntegratorArgs {
    /// Longest path in segments counting the camera ray, -1 for unlimited [default: the scene's].
    #[arg(long, allow_negative_numbers = true)]
    pub max_depth: Option<i64>,
    /// Light paths per pixel per iteration (ν) for lt, bdpt and vcm: N = floor(ν · pixels);
    /// 0 makes bdpt a path tracer on the shared bidirectional code (hits and NEE only).
    #[arg(long, default_value_t = 1.0)]
    pub light_paths_per_pixel: f32,
    /// Connections to cached light vertices per camera vertex (c) for bdpt and vcm.
    #[arg(long, default_value_t = 1)]
    pub connections: u32,
    /// Merging for vcm (on: merge probability 1 in every pixel).
    #[arg(long, value_enum, default_value = "on")]
    pub merge: Switch,
    /// Correlation-aware MIS weights for merges (vcm, emis-vcm).
    #[arg(long, value_enum, default_value = "on")]
    pub correlation_aware: Switch,
    /// emis-*: optimise after these many iterations (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "1,4,16,64")]
    pub emis_updates: Vec<u32>,
    /// emis-*: the pilot, path tracing first, which switches to the full candidate set,
    /// discarding the iterations so far, once a bidirectional strategy wins; or the method's
    /// own (N = P, c = 1).
    #[arg(long, value_enum, default_value = "path-tracing")]
    pub emis_pilot: PilotStart,
    /// emis-*: a research variant of the optimiser, as `tessera bench equal-time` compares
    /// them (repeatable): cost-model=measured, moment-outliers=each, image=guided,
    /// connections=per-pixel. The defaults are the ones the measurements support.
    #[arg(long, value_name = "KEY=VALUE", value_parser = parse_experiment)]
    pub emis_experiment: Vec<Experiment>,
    /// The flags that became `--emis-experiment` keys: hidden, and refused with
    /// their new spelling, so that a script using one learns what to write.
    #[command(flatten)]
    pub moved: MovedFlags,
}

/// Hidden flags that moved under `--emis-experiment`; parsing one fails with its new form.
#[derive(clap::Args, Debug, Clone)]
pub struct MovedFlags {
    #[arg(long, hide = true, value_parser = moved("cost-model"))]
    cost_model: Option<String>,
    #[arg(long, hide = true, value_parser = moved("moment-outliers"))]
    moment_outliers: Option<String>,
    #[arg(long, hide = true, value_parser = moved("image"))]
    emis_image: Option<String>,
    #[arg(long, hide = true, value_parser = moved("connections"))]
    emis_connections: Option<String>,
}

/// A parser that refuses its value, naming the `--emis-experiment` key it moved to.
fn moved(key: &'static str) -> impl Fn(&str) -> Result<String, String> + Clone + Send + Sync + 'static {
    move |value| Err(format!("this flag moved: write --emis-experiment {key}={value}"))
}

/// A research variant of the EMIS optimiser (`--emis-experiment KEY=VALUE`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Experiment {
    /// `cost-model=`: the cost constants.
    CostModel(CostModel),
    /// `moment-outliers=`: the outlier rule.
    MomentOutliers(OutlierStage),
    /// `image=`: the image estimate the moments are relative to.
    Image(ImageEstimate),
    /// `connections=`: one connection count for the image, or one per pixel.
    Connections(ConnectionScope),
}

impl Experiment {
    /// Sets this variant in `settings`.
    pub fn apply(self, settings: &mut RenderSettings) {
        match self {
            Experiment::CostModel(v) => settings.cost_model = v,
            Experiment::MomentOutliers(v) => settings.moment_outliers = v,
            Experiment::Image(v) => settings.emis_image = v,
            Experiment::Connections(v) => settings.emis_connections = v,
        }
    }
}

/// Parses `KEY=VALUE` of `--emis-experiment`; the error lists the keys or the key's values.
fn parse_experiment(s: &str) -> Result<Experiment, String> {
    fn value<T: ValueEnum>(key: &str, v: &str) -> Result<T, String> {
        T::from_str(v, false).map_err(|_| {
            let names: Vec<String> = T::value_variants()
                .iter()
                .filter_map(|x| Some(x.to_possible_value()?.get_name().to_string()))
                .collect();
            format!("{key}={v}: expected one of {}", names.join(", "))
        })
    }
    let (key, v) = s.split_once('=').ok_or_else(|| format!("\"{s}\": expected KEY=VALUE"))?;
    Ok(match key {
        "cost-model" => Experiment::CostModel(value(key, v)?),
        "moment-outliers" => Experiment::MomentOutliers(value(key, v)?),
        "image" => Experiment::Image(value(key, v)?),
        "connections" => Experiment::Connections(value(key, v)?),
        _ => return Err(format!("unknown key \"{key}\": expected cost-model, moment-outliers, image or connections")),
    })
}

/// What to render with what, shared by `tessera render` and `tessera submit`.
#[derive(clap::Args, Debug, Clone)]
pub struct JobArgs {
    /// Rendering algorithm.
    #[arg(long, value_enum, default_value = "pt")]
    pub integrator: IntegratorName,
    /// Samples per pixel; iterations for lt, bdpt and vcm [default: the scene's sampler sample_count].
    #[arg(long, conflicts_with = "time")]
    pub spp: Option<u32>,
    /// Render for this many seconds instead of a fixed sample count.
    #[arg(long)]
    pub time: Option<f64>,
    /// Seed of all random numbers; the same seed gives the same image [default: the scene's, or 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Path length, sample counts, merging and EMIS options.
    #[command(flatten)]
    pub mis: IntegratorArgs,
    /// Set a scene parameter ($name), overriding its <default>: -D name=value.
    #[arg(short = 'D', value_name = "NAME=VALUE")]
    pub define: Vec<String>,
}

/// Input a command refuses before rendering or asking anyone (exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InvalidInput(pub String);

impl JobArgs {
    /// The `-D` definitions.
    pub fn defines(&self) -> anyhow::Result<HashMap<String, String>> {
        parse_defines(&self.define)
    }

    /// The settings these arguments ask for, checked (spp, time and seed unresolved where
    /// not given: the scene supplies them).
    pub fn settings(&self) -> anyhow::Result<RenderSettings> {
        let mut settings = RenderSettings {
            integrator: self.integrator,
            spp: self.spp,
            time_s: self.time,
            seed: self.seed,
            defines: self.defines()?.into_iter().collect(),
            ..RenderSettings::default()
        };
        self.mis.apply(&mut settings);
        settings.validate().map_err(|e| InvalidInput(flag_error(e)))?;
        Ok(settings)
    }
}

impl IntegratorArgs {
    /// Sets these options in `settings`.
    pub fn apply(&self, settings: &mut RenderSettings) {
        settings.max_depth = self.max_depth;
        settings.light_paths_per_pixel = self.light_paths_per_pixel;
        settings.connections = self.connections;
        settings.merge = self.merge == Switch::On;
        settings.correlation_aware = self.correlation_aware == Switch::On;
        settings.emis_updates = self.emis_updates.clone();
        settings.emis_pilot = self.emis_pilot;
        for experiment in &self.emis_experiment {
            experiment.apply(settings);
        }
    }
}

/// An on/off switch.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Switch {
    /// Enabled.
    On,
    /// Disabled.
    Off,
}

/// A scene's display name: the file stem, or the folder name for files called `scene.xml`.
pub fn scene_name(path: &Path) -> String {
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("render");
    if stem == "scene" {
        if let Some(dir) = path
            .canonicalize()
            .ok()
            .as_deref()
            .and_then(Path::parent)
            .and_then(Path::file_name)
            .and_then(|s| s.to_str())
        {
            return dir.to_string();
        }
    }
    stem.to_string()
}

/// Parses `-D name=value` definitions.
pub fn parse_defines(defines: &[String]) -> anyhow::Result<HashMap<String, String>> {
    defines
        .iter()
        .map(|d| match d.split_once('=') {
            Some((k, v)) if !k.is_empty() => Ok((k.to_string(), v.to_string())),
            _ => Err(InvalidInput(format!("invalid -D \"{d}\": expected NAME=VALUE")).into()),
        })
        .collect()
}

/// Builds the renderer of `settings` (the rules shared with the farm), naming the command-line
/// flag of a bad value.
pub fn make_renderer(settings: &RenderSettings, scene: &Scene) -> anyhow::Result<Renderer> {
    settings.make_renderer(scene).map_err(|e| InvalidInput(flag_error(e)).into())
}

/// A settings error, naming the command-line flag of a bad field.
fn flag_error(e: SettingsError) -> String {
    match e {
        // the settings' field names, except `time_s`, are the flags' names
        SettingsError::Invalid { field, message } => {
            format!("--{} {message}", if field == "time_s" { "time".into() } else { field.replace('_', "-") })
        }
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--emis-experiment` sets the variant its key names, and names the keys or values it
    /// knows when it does not know what it is given.
    #[test]
    fn an_experiment_sets_its_setting_and_refuses_what_it_does_not_know() {
        let mut settings = RenderSettings::default();
        for arg in ["cost-model=measured", "moment-outliers=each", "image=guided", "connections=per-pixel"] {
            parse_experiment(arg).unwrap().apply(&mut settings);
        }
        assert_eq!(settings.cost_model, CostModel::Measured);
        assert_eq!(settings.moment_outliers, OutlierStage::Each);
        assert_eq!(settings.emis_image, ImageEstimate::Guided);
        assert_eq!(settings.emis_connections, ConnectionScope::PerPixel);
        let e = parse_experiment("moment-outliers=filtered").unwrap_err();
        assert!(e.contains("shared, each"), "{e}");
        assert!(parse_experiment("merge-ratio=reference").unwrap_err().contains("cost-model, moment-outliers"));
        assert!(parse_experiment("cost-model").unwrap_err().contains("KEY=VALUE"));
    }

    /// A flag that moved under `--emis-experiment` is refused with its new spelling.
    #[test]
    fn a_moved_flag_names_its_new_form() {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            args: IntegratorArgs,
        }
        let e = Cli::try_parse_from(["t", "--moment-outliers", "each"]).err().expect("refused").to_string();
        assert!(e.contains("--emis-experiment moment-outliers=each"), "{e}");
        let e = Cli::try_parse_from(["t", "--emis-connections", "per-pixel"]).err().expect("refused").to_string();
        assert!(e.contains("--emis-experiment connections=per-pixel"), "{e}");
        assert!(Cli::try_parse_from(["t", "--emis-experiment", "image=guided"]).is_ok());
    }
}
