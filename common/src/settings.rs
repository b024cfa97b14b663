//! Render settings as plain data: what a farm job carries from client to coordinator to worker
//! (serde, so REST and storage can use JSON), and the one function that turns them plus a
//! loaded scene into a [`Renderer`] (a tile [`Integrator`] or the EMIS loop's configuration),
//! used by `tessera render`, the coordinator and the worker alike.
//!
//! The rules are those of `tessera render` (`coordinator/src/local.rs`): unset values come from
//! the scene file (spp and seed from its sampler, max depth from its integrator), so a farm job
//! and a local render with the same settings build the same integrator and the same tiles.
//!
//! ```
//! use tessera_common::settings::{IntegratorName, RenderSettings};
//! let s: RenderSettings = serde_json::from_str(r#"{"integrator": "vcm", "spp": 4}"#).unwrap();
//! assert_eq!(s.integrator, IntegratorName::Vcm);
//! assert!(s.validate().is_ok());
//! ```

use crate::emis::cost::CostModel;
use crate::emis::denoise::ImageEstimate;
use crate::emis::optimize::{ConnectionScope, OutlierStage};
use crate::emis::{EmisConfig, EmisMethod, PilotStart};
use crate::integrator::path::merge::{MergeConfig, MergeMask};
use crate::integrator::{Bidir, Integrator, LightTracer, PathSettings, PathTracer};
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};

mod limits;
pub use limits::{DEFAULT_MAX_TILE_BYTES, MAX_SPP, WorkLimits};

/// The rendering algorithms a job can ask for (each one's text is also its command-line help).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum IntegratorName {
    /// Path tracing with next-event estimation and MIS (Mitsuba's `path`).
    #[default]
    Pt,
    /// Light tracing (Mitsuba's `ptracer`): light paths connected to the camera. Cannot see smooth
    /// glass or mirrors, or an environment, directly: those pixels stay dark.
    Lt,
    /// Bidirectional path tracing with a light-vertex cache: hits, next-event estimation, c
    /// connections per camera vertex and light tracing, balance heuristic over sample counts.
    Bdpt,
    /// Vertex connection and merging: bdpt plus photon-map merging at every camera vertex but the
    /// first (fixed radius, so slightly biased).
    Vcm,
    /// Efficiency-aware MIS on bdpt: path tracing first (or, with `--emis-pilot bidirectional`, a
    /// bdpt pilot with ν = 1, c = 1) estimates candidates' second moments; after iterations 1, 4,
    /// 16, 64 the best ν and c (by moment × cost) are chosen and used from then on.
    EmisBdpt,
    /// Efficiency-aware MIS on vcm: path tracing first (or, with `--emis-pilot bidirectional`, a
    /// vcm pilot with ν = 1, c = 1, merging everywhere) picks ν, c and a per-pixel merge mask;
    /// writes the mask, the relative moment, a strategy PNG and a JSON report of every update
    /// beside the image.
    EmisVcm,
}

impl IntegratorName {
    /// Every name, for messages.
    pub const ALL: [IntegratorName; 6] = [
        IntegratorName::Pt,
        IntegratorName::Lt,
        IntegratorName::Bdpt,
        IntegratorName::Vcm,
        IntegratorName::EmisBdpt,
        IntegratorName::EmisVcm,
    ];

    /// The command-line and wire spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            IntegratorName::Pt => "pt",
            IntegratorName::Lt => "lt",
            IntegratorName::Bdpt => "bdpt",
            IntegratorName::Vcm => "vcm",
            IntegratorName::EmisBdpt => "emis-bdpt",
            IntegratorName::EmisVcm => "emis-vcm",
        }
    }

    /// The EMIS method, for `emis-*`.
    pub fn emis_method(self) -> Option<EmisMethod> {
        match self {
            IntegratorName::EmisBdpt => Some(EmisMethod::Bdpt),
            IntegratorName::EmisVcm => Some(EmisMethod::Vcm),
            _ => None,
        }
    }

    /// Whether tiles are full frames × iteration ranges (light paths are image-level).
    pub fn full_frame(self) -> bool {
        !matches!(self, IntegratorName::Pt)
    }
}

impl std::str::FromStr for IntegratorName {
    type Err = SettingsError;
    fn from_str(s: &str) -> Result<Self, SettingsError> {
        IntegratorName::ALL.into_iter().find(|n| n.as_str() == s).ok_or_else(|| SettingsError::Invalid {
            field: "integrator",
            message: format!("unknown integrator \"{s}\" (expected pt, lt, bdpt, vcm, emis-bdpt or emis-vcm)"),
        })
    }
}

impl std::fmt::Display for IntegratorName {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Settings of one render. `None` means "the scene file's value".
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RenderSettings {
    /// Algorithm.
    pub integrator: IntegratorName,
    /// Samples per pixel (iterations for lt, bdpt, vcm).
    pub spp: Option<u32>,
    /// Time budget in seconds, instead of `spp`.
    pub time_s: Option<f64>,
    /// Seed of every random number.
    pub seed: Option<u64>,
    /// Longest path in segments counting the camera ray; -1 = unlimited.
    pub max_depth: Option<i64>,
    /// Light paths per pixel per iteration (ν).
    pub light_paths_per_pixel: f32,
    /// Connections per camera vertex (c).
    pub connections: u32,
    /// Vertex merging (vcm).
    pub merge: bool,
    /// Correlation-aware MIS for merges (vcm).
    pub correlation_aware: bool,
    /// Scene parameter overrides (`-D name=value`).
    pub defines: BTreeMap<String, String>,
    /// EMIS: optimise after these many iterations (increasing, above 0).
    pub emis_updates: Vec<u32>,
    /// EMIS: the cost heuristic's constants (docs/emis.md, D8).
    pub cost_model: CostModel,
    /// EMIS: the outlier rejection of the image-level sums.
    pub moment_outliers: OutlierStage,
    /// EMIS: the image estimate Ī that moments are made relative to.
    pub emis_image: ImageEstimate,
    /// EMIS: the method's own pilot, or path tracing first.
    pub emis_pilot: PilotStart,
    /// EMIS: one connection count for the image, or one per pixel.
    pub emis_connections: ConnectionScope,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            integrator: IntegratorName::Pt,
            spp: None,
            time_s: None,
            seed: None,
            max_depth: None,
            light_paths_per_pixel: 1.0,
            connections: 1,
            merge: true,
            correlation_aware: true,
            defines: BTreeMap::new(),
            emis_updates: EmisConfig::DEFAULT_UPDATES.to_vec(),
            cost_model: CostModel::default(),
            moment_outliers: OutlierStage::default(),
            emis_image: ImageEstimate::default(),
            emis_pilot: PilotStart::default(),
            emis_connections: ConnectionScope::default(),
        }
    }
}

/// What renders a job: a tile integrator, or efficiency-aware MIS with its update loop.
pub enum Renderer {
    /// `pt`, `lt`, `bdpt`, `vcm`.
    Tiles(Box<dyn Integrator>),
    /// `emis-bdpt`, `emis-vcm`.
    Emis(EmisConfig, PathSettings),
}

impl Renderer {
    /// The integrator's name.
    pub fn name(&self) -> &'static str {
        match self {
            Renderer::Tiles(i) => i.name(),
            Renderer::Emis(c, _) => c.name(),
        }
    }
}

/// A setting that was retired, or one value of a setting that was.
#[derive(Clone, Copy, Debug)]
pub struct Retired {
    /// The settings field.
    pub field: &'static str,
    /// The retired value; `None`: the whole field is retired.
    pub value: Option<&'static str>,
    /// What is always done now: the field's old default, or the value that replaces the
    /// retired one.
    pub now: &'static str,
}

/// Every retired setting and value. Jobs stored before, and older clients that still send a
/// retired field with its old default, are accepted; asking for a retired variant is refused
/// by name, since it no longer exists.
pub const RETIRED: &[Retired] = &[
    Retired { field: "merge_ratio", value: None, now: "principled" },
    Retired { field: "merge_kernel", value: None, now: "squared" },
    Retired { field: "cost_model", value: Some("reference"), now: "calibrated" },
    Retired { field: "moment_filter", value: None, now: "relative" },
    Retired { field: "moment_outliers", value: Some("filtered"), now: "shared" },
];

/// Rewrites a settings object without [`RETIRED`] settings: retired fields removed, retired
/// values replaced by what is always done now. The error names the first that asked for a
/// retired variant (the object is rewritten all the same, so a stored job can go on).
pub fn strip_retired(settings: &mut serde_json::Map<String, serde_json::Value>) -> Result<(), SettingsError> {
    let mut refused = None;
    for r in RETIRED {
        let asked = match (r.value, settings.get(r.field)) {
            (_, None) => continue,
            (None, Some(v)) => (*v != r.now).then(|| v.clone()),
            (Some(retired), Some(v)) if *v == retired => Some(v.clone()),
            (Some(_), Some(_)) => continue,
        };
        match r.value {
            None => drop(settings.remove(r.field)),
            Some(_) => drop(settings.insert(r.field.into(), r.now.into())),
        }
        if let Some(v) = asked {
            refused.get_or_insert_with(|| {
                invalid(r.field, format!("{v} was retired; {:?} is what is always done now", r.now))
            });
        }
    }
    refused.map_or(Ok(()), Err)
}

/// Settings that cannot work.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SettingsError {
    /// A field has an unusable value.
    #[error("settings field \"{field}\": {message}")]
    Invalid {
        /// The field at fault.
        field: &'static str,
        /// What is wrong.
        message: String,
    },
}

fn invalid(field: &'static str, message: String) -> SettingsError {
    SettingsError::Invalid { field, message }
}

impl RenderSettings {
    /// Checks the values that do not need the scene.
    pub fn validate(&self) -> Result<(), SettingsError> {
        if self.spp.is_some() && self.time_s.is_some() {
            return Err(invalid("time_s", "spp and time_s exclude each other".into()));
        }
        if self.spp == Some(0) {
            return Err(invalid("spp", "must be at least 1".into()));
        }
        if let Some(t) = self.time_s
            && !(t > 0.0 && t.is_finite())
        {
            return Err(invalid("time_s", format!("must be a positive number of seconds, got {t}")));
        }
        let nu = self.light_paths_per_pixel;
        if !(nu >= 0.0 && nu.is_finite()) || (self.integrator == IntegratorName::Lt && nu == 0.0) {
            return Err(invalid(
                "light_paths_per_pixel",
                format!("must be positive (or 0 for bdpt and vcm: no light paths), got {nu}"),
            ));
        }
        self.max_depth_limit()?;
        if self.emis_updates.windows(2).any(|w| w[0] >= w[1]) || self.emis_updates.first() == Some(&0) {
            return Err(invalid(
                "emis_updates",
                format!("must be increasing iteration counts above 0, got {:?}", self.emis_updates),
            ));
        }
        Ok(())
    }

    /// `max_depth` as the integrators take it (`None` = the scene's).
    fn max_depth_limit(&self) -> Result<Option<u32>, SettingsError> {
        match self.max_depth {
            None => Ok(None),
            Some(-1) => Ok(Some(u32::MAX)),
            Some(d) if d >= 0 => Ok(Some(d.min(u32::MAX as i64) as u32)),
            Some(d) => Err(invalid("max_depth", format!("must be -1 (unlimited) or non-negative, got {d}"))),
        }
    }

    /// The defines as the scene loader takes them.
    pub fn define_map(&self) -> HashMap<String, String> {
        self.defines.iter().map(|(k, v)| (k.clone(), v.clone())).collect()
    }

    /// A copy with the scene's defaults filled in: `spp` (unless a time budget is set) and
    /// `seed`, so that every worker renders with exactly the same values.
    pub fn resolved(&self, scene: &Scene) -> RenderSettings {
        let mut s = self.clone();
        if s.time_s.is_none() {
            s.spp = Some(s.spp.unwrap_or(scene.spp));
        }
        s.seed = Some(s.seed.unwrap_or(scene.seed));
        s
    }

    /// Builds the renderer, with the same rules everywhere (`tessera render`, coordinator,
    /// worker).
    pub fn make_renderer(&self, scene: &Scene) -> Result<Renderer, SettingsError> {
        self.validate()?;
        let settings = PathSettings::from_scene(scene, self.max_depth_limit()?);
        let (nu, c) = (self.light_paths_per_pixel, self.connections);
        let tiles = |i: Box<dyn Integrator>| Ok(Renderer::Tiles(i));
        match self.integrator {
            IntegratorName::Pt => tiles(Box::new(PathTracer { settings })),
            IntegratorName::Lt => tiles(Box::new(LightTracer { settings, light_paths_per_pixel: nu })),
            IntegratorName::Bdpt => tiles(Box::new(Bidir::bdpt(settings, nu, c))),
            IntegratorName::Vcm => {
                let mask = MergeMask::Constant(if self.merge { 1.0 } else { 0.0 });
                tiles(Box::new(Bidir::vcm(
                    settings,
                    nu,
                    c,
                    MergeConfig { mask, correlation_aware: self.correlation_aware },
                )))
            }
            IntegratorName::EmisBdpt | IntegratorName::EmisVcm => Ok(Renderer::Emis(self.emis_config(), settings)),
        }
    }

    /// The EMIS configuration of `emis-*` settings (the defaults of the method otherwise).
    pub fn emis_config(&self) -> EmisConfig {
        let mut config = EmisConfig::new(self.integrator.emis_method().unwrap_or(EmisMethod::Vcm));
        config.updates = self.emis_updates.clone();
        config.correlation_aware = self.correlation_aware;
        config.constants = self.cost_model.constants();
        config.measured_costs = self.cost_model == CostModel::Measured;
        config.filters.outliers = self.moment_outliers;
        config.denoise = self.emis_image.settings();
        config.pilot = self.emis_pilot;
        config.connection_scope = self.emis_connections;
        config
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_reject_spp_with_time_and_name_the_field() {
        let s = RenderSettings { spp: Some(4), time_s: Some(1.0), ..Default::default() };
        assert!(s.validate().unwrap_err().to_string().contains("time_s"));
        let s = RenderSettings { max_depth: Some(-3), ..Default::default() };
        assert!(s.validate().unwrap_err().to_string().contains("max_depth"));
    }

    #[test]
    fn settings_json_rejects_unknown_fields() {
        let e = serde_json::from_str::<RenderSettings>(r#"{"integrator":"pt","sppp":3}"#).unwrap_err();
        assert!(e.to_string().contains("sppp"), "{e}");
        assert_eq!("bdpt".parse::<IntegratorName>().unwrap(), IntegratorName::Bdpt);
        assert!("emis".parse::<IntegratorName>().is_err());
        assert_eq!("emis-vcm".parse::<IntegratorName>().unwrap(), IntegratorName::EmisVcm);
        let s = RenderSettings { emis_updates: vec![4, 4], ..Default::default() };
        assert!(s.validate().unwrap_err().to_string().contains("emis_updates"));
        // retired settings are unknown to the settings themselves
        let e = serde_json::from_str::<RenderSettings>(r#"{"integrator":"emis-vcm","merge_ratio":"principled"}"#);
        assert!(e.unwrap_err().to_string().contains("merge_ratio"));
    }

    #[test]
    fn retired_settings_are_stripped_with_their_old_default_and_refused_otherwise() {
        let object = |text: &str| match serde_json::from_str(text).unwrap() {
            serde_json::Value::Object(m) => m,
            _ => unreachable!(),
        };
        let mut old = object(r#"{"integrator":"emis-vcm","merge_ratio":"principled","merge_kernel":"squared"}"#);
        strip_retired(&mut old).unwrap();
        let s: RenderSettings = serde_json::from_value(serde_json::Value::Object(old)).unwrap();
        assert_eq!(s.integrator, IntegratorName::EmisVcm);
        let mut variant = object(r#"{"merge_kernel":"reference"}"#);
        let e = strip_retired(&mut variant).unwrap_err().to_string();
        assert!(e.contains("\"merge_kernel\"") && e.contains("retired") && e.contains("squared"), "{e}");
        assert!(variant.is_empty(), "removed all the same");
        // a retired value of a live field: replaced, and refused by name
        let mut value = object(r#"{"cost_model":"reference"}"#);
        let e = strip_retired(&mut value).unwrap_err().to_string();
        assert!(e.contains("\"cost_model\"") && e.contains("calibrated"), "{e}");
        assert_eq!(value["cost_model"], "calibrated");
        let mut value = object(r#"{"moment_outliers":"filtered"}"#);
        assert!(strip_retired(&mut value).unwrap_err().to_string().contains("\"moment_outliers\""));
        assert_eq!(value["moment_outliers"], "shared");
        let mut live = object(r#"{"cost_model":"measured"}"#);
        strip_retired(&mut live).unwrap();
        assert_eq!(live["cost_model"], "measured");
    }
}
