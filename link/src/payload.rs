//! The sums a worker uploads for a tile (and the coordinator checkpoints for a film), in the
//! channels their [`Layout`] names, every number little-endian: each pixel's three Σ w·L
//! (f64), then, when present, each pixel's Σ w (f64), then each pixel's three splat sums (f64),
//! then each pixel's camera-sample count (u32), over the layout's bounds, row-major.

use std::io::Write;
use tessera_common::film::{Layout, Rect, TileAccum};

/// The decoded channels of one payload.
pub type Channels = (Vec<[f64; 3]>, Option<Vec<f64>>, Option<Vec<[f64; 3]>>, Vec<u32>);

/// Bytes per pixel of the channels `layout` names.
pub fn bytes_per_pixel(layout: &Layout) -> usize {
    24 + 4 + if layout.weights { 8 } else { 0 } + if layout.splats { 24 } else { 0 }
}

/// Bytes of a payload with `layout`; `None` if it does not fit in memory's address space.
pub fn payload_bytes(layout: &Layout) -> Option<usize> {
    layout.bounds.area().checked_mul(bytes_per_pixel(layout))
}

/// Writes channels in the payload's order.
pub fn write_channels(
    out: &mut (impl Write + ?Sized),
    sum: &[[f64; 3]],
    weight: Option<&[f64]>,
    splat: Option<&[[f64; 3]]>,
    count: &[u32],
) -> std::io::Result<()> {
    for s in sum {
        for c in s {
            out.write_all(&c.to_le_bytes())?;
        }
    }
    for w in weight.into_iter().flatten() {
        out.write_all(&w.to_le_bytes())?;
    }
    for s in splat.into_iter().flatten() {
        for c in s {
            out.write_all(&c.to_le_bytes())?;
        }
    }
    for c in count {
        out.write_all(&c.to_le_bytes())?;
    }
    Ok(())
}

/// A tile's sums as a payload.
pub fn encode_tile(t: &TileAccum) -> Vec<u8> {
    let layout = t.layout();
    let mut out = Vec::with_capacity(payload_bytes(&layout).unwrap_or(0));
    write_channels(&mut out, &t.sum, t.weight.as_deref(), t.splat.as_deref(), &t.count)
        .expect("invariant: writing into a Vec cannot fail");
    out
}

/// Decodes the channels of `pixels` pixels; `None` unless the length is exactly theirs.
pub fn decode_channels(bytes: &[u8], pixels: usize, weights: bool, splats: bool) -> Option<Channels> {
    let layout_bytes = 24 + 4 + if weights { 8 } else { 0 } + if splats { 24 } else { 0 };
    if bytes.len() != pixels.checked_mul(layout_bytes)? {
        return None;
    }
    let f = |b: &[u8]| f64::from_le_bytes(b.try_into().expect("invariant: 8-byte chunk"));
    let triples = |b: &[u8]| -> Vec<[f64; 3]> {
        b.chunks_exact(24).map(|p| [f(&p[0..8]), f(&p[8..16]), f(&p[16..24])]).collect()
    };
    let (sums, rest) = bytes.split_at(pixels * 24);
    let (weight, rest) = match weights {
        true => {
            let (w, rest) = rest.split_at(pixels * 8);
            (Some(w.chunks_exact(8).map(f).collect()), rest)
        }
        false => (None, rest),
    };
    let (splat, counts) = match splats {
        true => {
            let (s, rest) = rest.split_at(pixels * 24);
            (Some(triples(s)), rest)
        }
        false => (None, rest),
    };
    let count =
        counts.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().expect("invariant: 4-byte chunk"))).collect();
    Some((triples(sums), weight, splat, count))
}

/// Decodes a tile's payload for the samples of `rect` with `layout`; `None` when the length
/// is not exactly the layout's.
pub fn decode_tile(bytes: &[u8], rect: Rect, layout: Layout, non_finite: u64) -> Option<TileAccum> {
    let (sum, weight, splat, count) = decode_channels(bytes, layout.bounds.area(), layout.weights, layout.splats)?;
    Some(TileAccum::from_channels(rect, layout.bounds, sum, weight, splat, count, non_finite))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tessera_common::film::FilmSpec;
    use tessera_common::film::filter::{Filter, FilterKind};

    #[test]
    fn tiles_round_trip_bit_exactly_in_every_layout_and_lengths_are_checked() {
        for filter in [Filter::BOX, Filter::new(FilterKind::DEFAULT)] {
            let spec = FilmSpec::new(6, 5, filter);
            for rect in [Rect { x0: 2, y0: 1, x1: 4, y1: 3 }, spec.full()] {
                let mut t = TileAccum::new(rect, &spec);
                t.add_sample(
                    rect.x0,
                    rect.y0,
                    glam::Vec2::new(rect.x0 as f32 + 0.3, rect.y0 as f32 + 0.6),
                    glam::Vec3::new(0.1, -0.0, 7.0),
                );
                t.add_splat(glam::Vec2::new(2.5, 2.2), glam::Vec3::splat(3.0));
                t.non_finite = 2;
                let bytes = encode_tile(&t);
                assert_eq!(Some(bytes.len()), payload_bytes(&t.layout()));
                let back = decode_tile(&bytes, rect, t.layout(), 2).unwrap();
                assert_eq!(encode_tile(&back), bytes);
                assert_eq!(back.count, t.count);
                assert!(decode_tile(&bytes[1..], rect, t.layout(), 2).is_none());
                let mut longer = bytes.clone();
                longer.push(0);
                assert!(decode_tile(&longer, rect, t.layout(), 2).is_none());
            }
        }
    }
}
