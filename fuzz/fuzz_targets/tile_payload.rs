//! Fuzzes the decoder of the sums a worker uploads for a tile,
//! `tessera_link::payload::decode_tile` and `decode_channels`. The first three bytes choose a
//! film (1–8 × 1–8 pixels), its filter and one of its tiles (or the full frame, whose layout
//! keeps splats apart), as the coordinator knows them from its lease (`tessera_fuzz::job`); the
//! rest is the payload. What decodes must encode back to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_link::payload::{decode_channels, decode_tile, encode_tile, write_channels};

fuzz_target!(|data: &[u8]| {
    let Some((head, payload)) = data.split_first_chunk::<3>() else { return };
    let (spec, rect) = tessera_fuzz::job::lease(*head);
    if let Some(tile) = decode_tile(payload, rect, spec.layout(rect), 0) {
        assert_eq!(encode_tile(&tile), payload, "a decoded tile encodes to other bytes");
    }
    let (pixels, weights, splats) = (head[0] as usize, head[1] & 1 == 1, head[1] & 2 == 2);
    if let Some((sum, weight, splat, count)) = decode_channels(payload, pixels, weights, splats) {
        let mut out = Vec::new();
        write_channels(&mut out, &sum, weight.as_deref(), splat.as_deref(), &count)
            .expect("invariant: writing into a Vec cannot fail");
        assert_eq!(out, payload, "decoded channels encode to other bytes");
    }
});
