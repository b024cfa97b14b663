//! Validation of an uploaded tile result before it may touch the image: the rectangle and
//! sample range must be the tile's, the payload exactly the tile's size, every sum finite and
//! every pixel's sample count exactly the tile's sample count (the renderer counts every
//! sample, zeroing non-finite ones). A failure names what is wrong and the result is refused.

use super::model::TileSpec;
use tessera_common::film::{Rect, TileAccum};

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

/// Decodes and checks the image part of a result for `tile`; the error says what is wrong.
pub fn validate_result(tile: &TileSpec, claim: &ResultClaim, payload: &[u8]) -> Result<TileAccum, String> {
    if claim.rect != tile.rect {
        return Err(format!("result rect {:?} does not match the tile's {:?}", claim.rect, tile.rect));
    }
    if claim.samples != tile.samples {
        return Err(format!("result samples {:?} do not match the tile's {:?}", claim.samples, tile.samples));
    }
    let pixels = tile.rect.area();
    let (sum, count) = tessera_proto::decode_tile_payload(payload, pixels).ok_or_else(|| {
        format!(
            "result payload has {} bytes, expected {} for {pixels} pixels",
            payload.len(),
            pixels * tessera_proto::RESULT_BYTES_PER_PIXEL
        )
    })?;
    if let Some(i) = sum.iter().position(|s| !s.iter().all(|c| c.is_finite())) {
        return Err(format!("result sum of pixel {i} is not finite ({:?})", sum[i]));
    }
    let expected = tile.samples.len() as u32;
    if let Some(i) = count.iter().position(|&c| c != expected) {
        return Err(format!("result sample count of pixel {i} is {}, expected {expected}", count[i]));
    }
    let max_non_finite = pixels as u64 * expected as u64 * 2;
    if claim.non_finite > max_non_finite {
        return Err(format!("result claims {} non-finite samples, more than possible", claim.non_finite));
    }
    Ok(TileAccum { rect: tile.rect, sum, count, non_finite: claim.non_finite })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tile() -> TileSpec {
        TileSpec { rect: Rect { x0: 0, y0: 0, x1: 2, y1: 1 }, samples: 0..4 }
    }

    fn claim() -> ResultClaim {
        ResultClaim { rect: tile().rect, samples: 0..4, non_finite: 0, pilot_bytes: 0 }
    }

    #[test]
    fn validate_accepts_a_well_formed_result() {
        let payload = tessera_proto::encode_tile_payload(&[[1.0, 2.0, 3.0], [0.0; 3]], &[4, 4]);
        let accum = validate_result(&tile(), &claim(), &payload).unwrap();
        assert_eq!(accum.count, vec![4, 4]);
        assert_eq!(accum.sum[0], [1.0, 2.0, 3.0]);
    }

    #[test]
    fn validate_refuses_wrong_size_nan_counts_and_rect() {
        let short = tessera_proto::encode_tile_payload(&[[1.0; 3]], &[4]);
        assert!(validate_result(&tile(), &claim(), &short).unwrap_err().contains("bytes"));
        let nan = tessera_proto::encode_tile_payload(&[[f64::NAN, 0.0, 0.0], [0.0; 3]], &[4, 4]);
        assert!(validate_result(&tile(), &claim(), &nan).unwrap_err().contains("not finite"));
        let counts = tessera_proto::encode_tile_payload(&[[0.0; 3], [0.0; 3]], &[4, 5]);
        assert!(validate_result(&tile(), &claim(), &counts).unwrap_err().contains("sample count of pixel 1"));
        let ok = tessera_proto::encode_tile_payload(&[[0.0; 3], [0.0; 3]], &[4, 4]);
        let moved = ResultClaim { rect: Rect { x0: 1, y0: 0, x1: 3, y1: 1 }, ..claim() };
        assert!(validate_result(&tile(), &moved, &ok).unwrap_err().contains("rect"));
        let samples = ResultClaim { samples: 1..5, ..claim() };
        assert!(validate_result(&tile(), &samples, &ok).unwrap_err().contains("samples"));
    }
}
