//! How a job is cut into tiles and passes: the canonical decomposition that makes a farm
//! render bit-identical to `tessera render`.
//!
//! Local rendering (`tessera_common::render`) adds tile sums into a zeroed film. With a sample
//! budget, image-tile integrators (pt) render every tile's whole sample range in one pass: each
//! pixel's sum is accumulated sample by sample inside one tile and added once to a zero, so the
//! tile size does not change a single bit. Full-frame integrators (lt, bdpt, vcm) render one
//! iteration per pass and add the passes in iteration order. The farm therefore uses
//! * pt: [`TILE_SIZE`]² rectangles × the whole range `[0, spp)`, any merge order;
//! * lt, bdpt, vcm: the full frame × `[i, i + 1)` per tile, merged in iteration order.
//!
//! Tiles are numbered in merge order across passes, and the coordinator merges strictly in
//! that order (holding results that arrive early), so the film gets the same additions in the
//! same order as locally: bit-for-bit equality, not just equality within rounding.
//!
//! Time budgets have no local bit-exact twin (local passes depend on wall time too); they plan
//! one pass at a time at the barrier that ends the previous one.

use super::model::{JobSpec, TileSpec};
use tessera_common::film::Rect;

/// Edge of the rectangles of image-tile integrators.
pub const TILE_SIZE: u32 = 64;

/// What a job does when a pass has been merged completely (a barrier).
#[derive(Clone, Debug, PartialEq)]
pub enum BarrierAction {
    /// Render these tiles as the next final pass.
    NextPass(Vec<TileSpec>),
    /// Hook for EMIS: the pilot pass is merged, so the coordinator runs the optimiser on the
    /// merged moments and then calls `JobsModel::optimized` with the final pass. No current
    /// integrator plans a pilot pass, so nothing produces this yet.
    Optimize,
    /// Nothing left: the job is done.
    Finish,
}

/// The tiles of the first pass.
pub fn first_pass(spec: &JobSpec) -> Vec<TileSpec> {
    match spec.settings.spp {
        Some(spp) => pass_tiles(spec, 0, spp),
        // a time budget starts with one sample per pixel to measure the speed
        None => pass_tiles(spec, 0, 1),
    }
}

/// Tiles rendering samples `[begin, begin + count)` of every pixel.
pub fn pass_tiles(spec: &JobSpec, begin: u32, count: u32) -> Vec<TileSpec> {
    if spec.full_frame {
        (begin..begin + count)
            .map(|i| TileSpec { rect: Rect::full(spec.width, spec.height), samples: i..i + 1 })
            .collect()
    } else {
        Rect::tiles(spec.width, spec.height, TILE_SIZE)
            .into_iter()
            .map(|rect| TileSpec { rect, samples: begin..begin + count })
            .collect()
    }
}

/// What to do at the barrier after a pass. `spp_done` samples per pixel are merged, rendering
/// has run for `elapsed_s` seconds.
pub fn after_pass(spec: &JobSpec, spp_done: u32, elapsed_s: f64) -> BarrierAction {
    let Some(budget) = spec.settings.time_s else { return BarrierAction::Finish };
    let remaining = budget - elapsed_s;
    if remaining <= 0.0 || spp_done == 0 {
        return BarrierAction::Finish;
    }
    // passes of about a tenth of the budget, never planned past the deadline (as locally)
    let per_spp = (elapsed_s / spp_done as f64).max(1e-9);
    let count = ((remaining / per_spp).floor() as u32).min(((budget * 0.1 / per_spp) as u32).max(1));
    if count == 0 { BarrierAction::Finish } else { BarrierAction::NextPass(pass_tiles(spec, spp_done, count)) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessera_common::settings::{IntegratorName, RenderSettings};

    fn spec(integrator: IntegratorName, spp: Option<u32>, time_s: Option<f64>) -> JobSpec {
        JobSpec {
            name: "t".into(),
            priority: 0,
            settings: RenderSettings { integrator, spp, time_s, seed: Some(1), ..Default::default() },
            width: 130,
            height: 70,
            full_frame: integrator.full_frame(),
            bundle_digest: "d".into(),
            scene_path: "scene.xml".into(),
        }
    }

    #[test]
    fn plan_pt_covers_every_pixel_once_with_all_samples() {
        let tiles = first_pass(&spec(IntegratorName::Pt, Some(8), None));
        assert_eq!(tiles.len(), 3 * 2);
        assert_eq!(tiles.iter().map(|t| t.rect.area()).sum::<usize>(), 130 * 70);
        assert!(tiles.iter().all(|t| t.samples == (0..8)));
    }

    #[test]
    fn plan_bidir_is_one_full_frame_iteration_per_tile() {
        let tiles = first_pass(&spec(IntegratorName::Vcm, Some(3), None));
        assert_eq!(tiles.len(), 3);
        for (i, t) in tiles.iter().enumerate() {
            assert_eq!(t.rect, Rect::full(130, 70));
            assert_eq!(t.samples, i as u32..i as u32 + 1);
        }
        assert_eq!(after_pass(&spec(IntegratorName::Vcm, Some(3), None), 3, 1.0), BarrierAction::Finish);
    }

    #[test]
    fn plan_time_budget_adds_passes_until_the_time_is_used() {
        let s = spec(IntegratorName::Pt, None, Some(10.0));
        assert!(first_pass(&s).iter().all(|t| t.samples == (0..1)));
        match after_pass(&s, 1, 0.1) {
            BarrierAction::NextPass(t) => assert_eq!(t[0].samples, 1..11),
            other => panic!("{other:?}"),
        }
        assert_eq!(after_pass(&s, 50, 10.5), BarrierAction::Finish);
    }
}
