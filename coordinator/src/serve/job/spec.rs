//! What a job is asked to render, fixed at submission: its description ([`JobSpec`]) and the
//! work unit it is cut into ([`TileSpec`], an image rectangle × a range of iterations). The
//! state machine ([`super::model`]) and the planner ([`super::plan`]) both build on these.

use serde::{Deserialize, Serialize};
use std::ops::Range;
use tessera_common::film::filter::{Filter, FilterKind};
use tessera_common::film::{Layout, Rect};
use tessera_common::settings::{IntegratorName, RenderSettings};

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
    /// The film's reconstruction filter (jobs stored before filters carry none: the box).
    #[serde(default = "box_filter")]
    pub filter: FilterKind,
}

fn box_filter() -> FilterKind {
    FilterKind::Box
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
        }
    }

    /// The channels and pixels of the sums of a tile over `rect`.
    pub fn layout(&self, rect: Rect) -> Layout {
        Layout::of(rect, self.width, self.height, &Filter::new(self.filter))
    }
}

/// What a tile renders.
#[derive(Clone, Debug, PartialEq)]
pub struct TileSpec {
    /// Pixels.
    pub rect: Rect,
    /// Sample (iteration) indices.
    pub samples: Range<u32>,
}

impl TileSpec {
    /// Pixel samples the tile contributes.
    pub fn pixel_samples(&self) -> u64 {
        self.rect.area() as u64 * self.samples.len() as u64
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
