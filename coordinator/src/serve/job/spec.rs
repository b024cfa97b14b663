//! What a job is asked to render, fixed at submission: its description ([`JobSpec`]), the
//! [`Shape`] the job driver cuts into passes of [`TileSpec`]s (an image rectangle × a range of
//! iterations), on which the state machine ([`super::model`]) builds.

use serde::{Deserialize, Serialize};
use std::time::Duration;
pub use tessera_common::driver::TileSpec;
use tessera_common::driver::{Budget, EmisSchedule, Shape};
use tessera_common::emis::Strategy;
use tessera_common::film::filter::{Filter, FilterKind};
use tessera_common::film::{Layout, Rect};
use tessera_common::settings::{IntegratorName, RenderSettings};

/// Edge of the rectangles of image-tile integrators on the farm. Any edge gives the same bits:
/// an image tile holds a pixel's whole sample range of its pass.
pub const TILE_SIZE: u32 = 64;

/// The immutable description of a job, fixed at submission.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobSpec {
    /// Display name.
    pub name: String,
    /// Higher runs first.
    pub priority: i32,
    /// Settings with the scene's spp and seed filled in.
    pub settings: RenderSettings,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Whether tiles are full frames × iterations.
    pub full_frame: bool,
    /// Digest of the scene bundle blob.
    pub bundle_digest: String,
    /// The scene XML's path inside the bundle.
    pub scene_path: String,
    /// The film's reconstruction filter.
    pub filter: FilterKind,
    /// Jobs that must be done before this one starts (`--after`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub after: Vec<String>,
    /// Tags a worker must all have to be given this job's tiles (`--require-tags`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub require_tags: Vec<String>,
    /// The frame of a sequence this job renders (see `model/sequence.rs`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame: Option<super::model::FrameRef>,
    /// EMIS: the decision of the frame before, which this frame starts from (`--warm-start`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warm: Option<WarmStart>,
}

/// Where a tile's merge probability comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MergeSpec {
    /// No merging (emis-bdpt).
    None,
    /// The same χ everywhere (the pilot's).
    Constant(f32),
    /// A per-pixel mask stored as a blob (width·height little-endian f32).
    Mask(String),
}

/// An EMIS job's decision (its strategy once its updates ended) as the next frame of a job of
/// frames starts from it (`--warm-start`): the counts, and the per-pixel masks as blobs
/// (width·height little-endian f32), which the job and the next frame keep alive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WarmStart {
    /// Light paths per pixel per iteration (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex (0 with a connection mask).
    pub connections: u32,
    /// Per-pixel expected connections.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connection_mask: Option<String>,
    /// Merge probability.
    pub merge: MergeSpec,
}

impl WarmStart {
    /// The blobs it names.
    pub fn blobs(&self) -> impl Iterator<Item = &String> {
        let merge = match &self.merge {
            MergeSpec::Mask(d) => Some(d),
            _ => None,
        };
        self.connection_mask.iter().chain(merge)
    }
}

/// The most tags a worker may have or a job may require, and their longest length.
pub const MAX_TAGS: usize = 32;
/// The longest tag.
pub const MAX_TAG_BYTES: usize = 64;

/// Checks tags: at most [`MAX_TAGS`], each 1 to [`MAX_TAG_BYTES`] letters, digits, `-`, `_`
/// or `.`; `field` names them in the error.
pub fn check_tags(field: &str, tags: &[String]) -> Result<(), String> {
    if tags.len() > MAX_TAGS {
        return Err(format!("field \"{field}\" has more than {MAX_TAGS} tags"));
    }
    let good = |t: &String| {
        (1..=MAX_TAG_BYTES).contains(&t.len()) && t.bytes().all(|b| b.is_ascii_alphanumeric() || b"-_.".contains(&b))
    };
    match tags.iter().find(|t| !good(t)) {
        Some(t) => {
            Err(format!("field \"{field}\": tag \"{t}\" must be 1 to {MAX_TAG_BYTES} letters, digits, '-', '_' or '.'"))
        }
        None => Ok(()),
    }
}

/// The most jobs one job may wait for.
pub const MAX_AFTER: usize = 64;

/// Where and when a job runs, beside what it renders: its priority and the jobs it waits for
/// (ids or unique prefixes, as the client gave them).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Placement {
    /// Higher runs first.
    pub priority: i32,
    /// Jobs that must be done first.
    pub after: Vec<String>,
    /// Tags the workers that render it must have.
    pub require_tags: Vec<String>,
}

impl From<i32> for Placement {
    fn from(priority: i32) -> Placement {
        Placement { priority, ..Placement::default() }
    }
}

impl JobSpec {
    /// A job's spec as stored by the coordinator under `id`. Settings retired since it was
    /// stored are dropped: a job that asked for a retired variant goes on with what is always
    /// done now, and the log says so.
    pub fn from_stored(id: &str, text: &str) -> serde_json::Result<JobSpec> {
        let mut value: serde_json::Value = serde_json::from_str(text)?;
        if let Some(settings) = value.get_mut("settings").and_then(|s| s.as_object_mut())
            && let Err(e) = tessera_common::settings::strip_retired(settings)
        {
            tracing::warn!(job = id, "{e}: the job goes on without it");
        }
        serde_json::from_value(value)
    }

    /// A job of `integrator` with `spp` samples over a `width`×`height` box-filtered film and a
    /// placeholder bundle: what tests build jobs from, and what is shown of a job whose stored
    /// description is lost.
    pub fn bare(name: &str, integrator: IntegratorName, spp: Option<u32>, width: u32, height: u32) -> JobSpec {
        JobSpec {
            name: name.to_string(),
            priority: 0,
            settings: RenderSettings { integrator, spp, ..Default::default() },
            width,
            height,
            full_frame: integrator.full_frame(),
            bundle_digest: "d".into(),
            scene_path: "scene.xml".into(),
            filter: FilterKind::Box,
            after: Vec::new(),
            require_tags: Vec::new(),
            frame: None,
            warm: None,
        }
    }

    /// What the job driver cuts into passes: image tiles of [`TILE_SIZE`] or full frames, the
    /// budget, and EMIS's updates.
    pub fn shape(&self) -> Shape {
        let s = &self.settings;
        let budget = match (s.spp, s.time_s) {
            (Some(n), _) => Budget::Samples(n),
            // validated finite and positive; a budget past `Duration`'s range is forever
            (None, Some(t)) => Budget::Time(Duration::try_from_secs_f64(t).unwrap_or(Duration::MAX)),
            (None, None) => Budget::Samples(1),
        };
        let emis = s.integrator.emis_method().map(|m| EmisSchedule {
            updates: s.emis_updates.clone(),
            initial_nu: match &self.warm {
                Some(w) if s.emis_pilot.takes_warm(w.nu) => w.nu,
                _ => Strategy::initial(m, s.emis_pilot).nu,
            },
        });
        Shape { width: self.width, height: self.height, budget, tile: (!self.full_frame).then_some(TILE_SIZE), emis }
    }

    /// The channels and pixels of the sums of a tile over `rect`.
    pub fn layout(&self, rect: Rect) -> Layout {
        Layout::of(rect, self.width, self.height, &Filter::new(self.filter))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_specs_with_retired_settings_still_load() {
        let spec = JobSpec::bare("n", IntegratorName::EmisVcm, Some(4), 8, 8);
        let mut stored = serde_json::to_value(&spec).unwrap();
        for (field, value) in [("merge_ratio", "principled"), ("merge_kernel", "reference")] {
            stored["settings"][field] = value.into();
        }
        assert!(serde_json::from_value::<JobSpec>(stored.clone()).is_err(), "unknown to the settings");
        assert_eq!(JobSpec::from_stored("job", &stored.to_string()).unwrap(), spec);
    }
}
