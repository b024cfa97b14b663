//! Counter-based hashing: every random number Tessera draws is a pure function of a key and a
//! counter, so results never depend on thread scheduling, tile order or the machine.

/// 64-bit finaliser from SplitMix64 / MurmurHash3: a bijection with full avalanche.
#[inline]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hashes a sequence of words into one key, order-sensitively.
#[inline]
pub fn hash_words(words: &[u64]) -> u64 {
    let mut h = 0x6a09_e667_f3bc_c908u64;
    for &w in words {
        h = mix64(h ^ w.wrapping_mul(0x9e37_79b9_7f4a_7c15)).rotate_left(17);
    }
    mix64(h)
}

/// Maps 64 random bits to a float uniformly distributed in [0, 1), using the top 24 bits so
/// that every value is exactly representable and 1.0 is never returned.
#[inline]
pub fn bits_to_unit_f32(bits: u64) -> f32 {
    (bits >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}
