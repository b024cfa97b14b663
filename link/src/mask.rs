//! A per-pixel EMIS mask (merge probability, expected connections) as the blob the coordinator
//! stores and workers fetch: width·height little-endian f32, row-major.

/// The blob of `mask`.
pub fn encode(mask: &[f32]) -> Vec<u8> {
    mask.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The mask of `pixels` values in `bytes`, or why not.
pub fn decode(bytes: &[u8], pixels: usize) -> Result<Vec<f32>, String> {
    if bytes.len() != pixels.saturating_mul(4) {
        return Err(format!("{} bytes, expected {} for {pixels} pixels", bytes.len(), pixels.saturating_mul(4)));
    }
    Ok(bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("invariant: 4 bytes"))).collect())
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_mask_round_trips_and_a_wrong_size_is_refused() {
        let mask = [0.0, 0.25, 1.0, 3.5];
        assert_eq!(super::decode(&super::encode(&mask), 4).unwrap(), mask);
        assert!(super::decode(&super::encode(&mask), 3).unwrap_err().contains("16 bytes, expected 12"));
    }
}
