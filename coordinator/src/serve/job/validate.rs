//! Validation of an uploaded tile result before it may touch the image: the rectangle and
//! sample range must be the tile's, the payload exactly the size of the tile's layout (its
//! rectangle and the filter's border), every sum and weight finite, and every pixel's sample
//! count exactly the tile's sample count inside the rectangle and 0 in the border (the renderer
//! counts every sample, zeroing non-finite ones). A failure names what is wrong and the result
//! is refused.

use super::model::TileSpec;
use tessera_common::film::{Layout, Rect, TileAccum};

/// What a worker says it rendered.
#[derive(Clone, Debug, PartialEq)]
pub struct ResultClaim {
    /// The rectangle.
    pub rect: Rect,
    /// The sample range.
    pub samples: std::ops::Range<u32>,
    /// Non-finite samples the renderer zeroed.
    pub non_finite: u64,
    /// Bytes of EMIS pilot data at the end of the payload (checked apart).
    pub pilot_bytes: u64,
}

/// Decodes and checks the image part of a result for `tile`, whose sums have `layout`; the
/// error says what is wrong.
pub fn validate_result(
    tile: &TileSpec,
    layout: Layout,
    claim: &ResultClaim,
    payload: &[u8],
) -> Result<TileAccum, String> {
    if claim.rect != tile.rect {
        return Err(format!("result rect {:?} does not match the tile's {:?}", claim.rect, tile.rect));
    }
    if claim.samples != tile.samples {
        return Err(format!("result samples {:?} do not match the tile's {:?}", claim.samples, tile.samples));
    }
    let expected = tessera_link::payload::payload_bytes(&layout).unwrap_or(usize::MAX);
    let accum = tessera_link::payload::decode_tile(payload, tile.rect, layout, claim.non_finite).ok_or_else(|| {
        format!("result payload has {} bytes, expected {expected} for {:?}", payload.len(), layout.bounds)
    })?;
    if let Some(i) = accum.sum.iter().position(|s| !s.iter().all(|c| c.is_finite())) {
        return Err(format!("result sum of pixel {i} is not finite ({:?})", accum.sum[i]));
    }
    if let Some(i) = accum.weight.iter().flatten().position(|w| !w.is_finite()) {
        return Err(format!("result weight of pixel {i} is not finite"));
    }
    if let Some(i) = accum.splat.iter().flatten().position(|s| !s.iter().all(|c| c.is_finite())) {
        return Err(format!("result splat of pixel {i} is not finite"));
    }
    check_magnitudes(tile, &accum)?;
    let samples = tile.samples.len() as u32;
    let b = layout.bounds;
    for (i, &count) in accum.count.iter().enumerate() {
        let (x, y) = (b.x0 + i as u32 % b.width(), b.y0 + i as u32 / b.width());
        let expected = if tile.rect.contains(x, y) { samples } else { 0 };
        if count != expected {
            return Err(format!("result sample count of pixel ({x}, {y}) is {count}, expected {expected}"));
        }
    }
    let max_non_finite = tile.rect.area() as u64 * samples as u64 * 2;
    if claim.non_finite > max_non_finite {
        return Err(format!("result claims {} non-finite samples, more than possible", claim.non_finite));
    }
    Ok(accum)
}

/// What one sample may add to a pixel: a finite f32 radiance (the renderer zeroes the rest)
/// times a filter weight of at most 1, with headroom for splats of several light vertices.
const MAX_PER_SAMPLE: f64 = f32::MAX as f64 * 64.0;

/// Refuses sums no renderer could make from the tile's samples: a worker's finite 1e300 came
/// out of the film as Inf.
fn check_magnitudes(tile: &TileSpec, accum: &TileAccum) -> Result<(), String> {
    let bound = (tile.pixel_samples().max(1) as f64) * MAX_PER_SAMPLE;
    let within = |v: f64| v.abs() <= bound;
    if let Some(i) = accum.sum.iter().position(|s| !s.iter().all(|&c| within(c))) {
        return Err(format!(
            "result sum of pixel {i} ({:?}) is more than the tile's samples can add up to",
            accum.sum[i]
        ));
    }
    if let Some(i) = accum.weight.iter().flatten().position(|&w| !within(w)) {
        return Err(format!("result weight of pixel {i} is more than the tile's samples can add up to"));
    }
    if let Some(i) = accum.splat.iter().flatten().position(|s| !s.iter().all(|&c| within(c))) {
        return Err(format!("result splat of pixel {i} is more than the tile's samples can add up to"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessera_common::film::filter::{Filter, FilterKind};

    fn tile() -> TileSpec {
        TileSpec { rect: Rect { x0: 0, y0: 0, x1: 2, y1: 1 }, samples: 0..4 }
    }

    fn claim() -> ResultClaim {
        ResultClaim { rect: tile().rect, samples: 0..4, non_finite: 0, pilot_bytes: 0 }
    }

    fn boxed() -> Layout {
        Layout::of(tile().rect, 2, 1, &Filter::BOX)
    }

    fn payload(sum: &[[f64; 3]], weight: Option<&[f64]>, count: &[u32]) -> Vec<u8> {
        let mut out = Vec::new();
        tessera_link::payload::write_channels(&mut out, sum, weight, None, count).unwrap();
        out
    }

    #[test]
    fn validate_accepts_a_well_formed_result() {
        let accum =
            validate_result(&tile(), boxed(), &claim(), &payload(&[[1.0, 2.0, 3.0], [0.0; 3]], None, &[4, 4])).unwrap();
        assert_eq!(accum.count, vec![4, 4]);
        assert_eq!(accum.sum[0], [1.0, 2.0, 3.0]);
    }

    #[test]
    fn validate_refuses_wrong_size_nan_counts_and_rect() {
        let short = payload(&[[1.0; 3]], None, &[4]);
        assert!(validate_result(&tile(), boxed(), &claim(), &short).unwrap_err().contains("bytes"));
        let nan = payload(&[[f64::NAN, 0.0, 0.0], [0.0; 3]], None, &[4, 4]);
        assert!(validate_result(&tile(), boxed(), &claim(), &nan).unwrap_err().contains("not finite"));
        let huge = payload(&[[1e300, 0.0, 0.0], [0.0; 3]], None, &[4, 4]);
        let e = validate_result(&tile(), boxed(), &claim(), &huge).unwrap_err();
        assert!(e.contains("more than the tile's samples can add up to"), "{e}");
        let big = payload(&[[1e38 * 8.0, 0.0, 0.0], [0.0; 3]], None, &[4, 4]);
        assert!(validate_result(&tile(), boxed(), &claim(), &big).is_ok(), "8 samples of f32's largest finite values");
        let counts = payload(&[[0.0; 3], [0.0; 3]], None, &[4, 5]);
        let e = validate_result(&tile(), boxed(), &claim(), &counts).unwrap_err();
        assert!(e.contains("sample count of pixel (1, 0)"), "{e}");
        let ok = payload(&[[0.0; 3], [0.0; 3]], None, &[4, 4]);
        let moved = ResultClaim { rect: Rect { x0: 1, y0: 0, x1: 3, y1: 1 }, ..claim() };
        assert!(validate_result(&tile(), boxed(), &moved, &ok).unwrap_err().contains("rect"));
        let samples = ResultClaim { samples: 1..5, ..claim() };
        assert!(validate_result(&tile(), boxed(), &samples, &ok).unwrap_err().contains("samples"));
    }

    #[test]
    fn filtered_results_cover_the_border_with_weights_and_no_samples_of_their_own() {
        // a 1×1 tile at (1, 1) of a 4×4 film with the tent filter: bounds (0..3) × (0..3)
        let tile = TileSpec { rect: Rect { x0: 1, y0: 1, x1: 2, y1: 2 }, samples: 0..2 };
        let claim = ResultClaim { rect: tile.rect, samples: 0..2, non_finite: 0, pilot_bytes: 0 };
        let layout = Layout::of(tile.rect, 4, 4, &Filter::new(FilterKind::Tent { radius: 1.0 }));
        assert_eq!(layout.bounds, Rect { x0: 0, y0: 0, x1: 3, y1: 3 });
        let mut count = [0u32; 9];
        count[4] = 2;
        let good = payload(&[[0.5; 3]; 9], Some(&[0.25; 9]), &count);
        assert!(validate_result(&tile, layout, &claim, &good).is_ok());
        count[0] = 1;
        let stray = payload(&[[0.5; 3]; 9], Some(&[0.25; 9]), &count);
        let e = validate_result(&tile, layout, &claim, &stray).unwrap_err();
        assert!(e.contains("pixel (0, 0) is 1, expected 0"), "{e}");
        let mut weights = [0.25; 9];
        weights[3] = f64::INFINITY;
        count[0] = 0;
        let inf = payload(&[[0.5; 3]; 9], Some(&weights), &count);
        assert!(validate_result(&tile, layout, &claim, &inf).unwrap_err().contains("weight"));
        let unweighted = payload(&[[0.5; 3]; 9], None, &count);
        assert!(validate_result(&tile, layout, &claim, &unweighted).unwrap_err().contains("bytes"));
    }
}
