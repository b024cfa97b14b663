//! Tests of the film's sums: filtering, borders, merging and splat normalisation.

use super::filter::{Filter, FilterKind};
use super::*;

fn gaussian(w: u32, h: u32) -> FilmSpec {
    FilmSpec::new(w, h, Filter::new(FilterKind::DEFAULT))
}

#[test]
fn box_samples_land_in_their_pixel_and_average_plainly() {
    let spec = FilmSpec::boxed(4, 3);
    let rect = Rect { x0: 1, y0: 1, x1: 3, y1: 3 };
    let mut t = TileAccum::new(rect, &spec);
    assert_eq!(t.bounds, rect);
    assert!(t.weight.is_none() && t.splat.is_none());
    t.add_sample(2, 1, Vec2::new(2.9, 1.1), Rgb::new(1.0, 2.0, 3.0));
    t.add_sample(2, 1, Vec2::new(2.1, 1.9), Rgb::new(3.0, 2.0, 1.0));
    let mut film = Film::new(&spec);
    film.merge_tile(&t);
    let img = film.average();
    assert_eq!(img[6], [2.0, 2.0, 2.0]);
    assert_eq!(film.count[6], 2);
    assert_eq!(img[5], [0.0; 3]);
}

#[test]
fn filtered_samples_reach_the_border_and_merge_by_addition() {
    let spec = gaussian(16, 16);
    let left = Rect { x0: 0, y0: 0, x1: 8, y1: 16 };
    let right = Rect { x0: 8, y0: 0, x1: 16, y1: 16 };
    assert_eq!(spec.bounds(left), Rect { x0: 0, y0: 0, x1: 10, y1: 16 });
    assert_eq!(spec.bounds(right), Rect { x0: 6, y0: 0, x1: 16, y1: 16 });
    // a constant image: every pixel averages to the constant, border pixels included, however
    // the frame is cut into tiles
    let value = Rgb::new(0.5, 1.0, 2.0);
    let mut film = Film::new(&spec);
    for rect in [left, right] {
        let mut t = TileAccum::new(rect, &spec);
        for y in rect.y0..rect.y1 {
            for x in rect.x0..rect.x1 {
                for (a, b) in [(0.1, 0.7), (0.6, 0.2), (0.9, 0.9)] {
                    t.add_sample(x, y, Vec2::new(x as f32 + a, y as f32 + b), value);
                }
            }
        }
        film.merge_tile(&t);
    }
    for (i, p) in film.average().iter().enumerate() {
        for c in 0..3 {
            assert!((p[c] - value[c]).abs() < 1e-5, "pixel {i}: {p:?}");
        }
        assert_eq!(film.count[i], 3);
    }
    // a sample near the seam adds weight on both sides of it
    let mut t = TileAccum::new(left, &spec);
    t.add_sample(7, 5, Vec2::new(7.9, 5.5), Rgb::ONE);
    let w = t.weight.as_ref().unwrap();
    let at = |x: u32, y: u32| w[((y - t.bounds.y0) * t.bounds.width() + x - t.bounds.x0) as usize];
    assert!(at(9, 5) > 0.0 && at(8, 5) > at(9, 5));
    assert_eq!(t.count.iter().sum::<u32>(), 1);
}

#[test]
fn splats_estimate_the_same_pixel_value_as_camera_samples() {
    // a uniform splat density of value v per pixel per iteration must develop to v, like
    // camera samples of v, also at the image's border
    let spec = gaussian(8, 6);
    let full = spec.full();
    let mut t = TileAccum::new(full, &spec);
    assert!(t.splat.is_some());
    let v = Rgb::new(1.0, 0.25, 4.0);
    let iterations = 64u32;
    let n = 16u32; // splats per pixel side per iteration
    for _ in 0..iterations {
        for y in 0..6 * n {
            for x in 0..8 * n {
                let raster = Vec2::new((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
                t.add_splat(raster, v / (n * n) as f32);
            }
        }
    }
    t.count_iterations(iterations);
    let mut film = Film::new(&spec);
    film.merge_tile(&t);
    for p in film.average() {
        for c in 0..3 {
            assert!((p[c] - v[c]).abs() < 2e-3 * v[c], "{p:?}");
        }
    }
}

#[test]
fn non_finite_samples_are_zeroed_and_counted() {
    let spec = gaussian(4, 4);
    let mut t = TileAccum::new(spec.full(), &spec);
    t.add_sample(1, 1, Vec2::new(1.5, 1.5), Rgb::new(f32::NAN, 0.0, 0.0));
    t.add_splat(Vec2::new(2.5, 2.5), Rgb::splat(f32::INFINITY));
    assert_eq!(t.non_finite, 2);
    assert!(t.sum.iter().flatten().all(|v| v.is_finite()));
    assert!(t.splat.as_ref().unwrap().iter().flatten().all(|v| *v == 0.0));
}

#[test]
fn a_frame_filled_by_bands_equals_the_serial_calls_bit_for_bit() {
    // a small xorshift: samples anywhere in their pixel, splats anywhere (beyond the image
    // too), a few non-finite values, values of many magnitudes so that order shows
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let kinds =
        [FilterKind::Box, FilterKind::DEFAULT, FilterKind::Lanczos { lobes: 3 }, FilterKind::Tent { radius: 5.5 }];
    for kind in kinds {
        for (w, h) in [(37, 53), (5, 2), (64, 16)] {
            let spec = FilmSpec::new(w, h, Filter::new(kind));
            let mut rows: Vec<Vec<(Rgb, Vec2)>> = (0..h)
                .map(|y| {
                    (0..w)
                        .map(|x| {
                            let big = 10f32.powi((next() * 12.0) as i32 - 6);
                            let v = if next() < 0.01 {
                                Rgb::splat(f32::NAN)
                            } else {
                                Rgb::new(next(), next(), next()) * big
                            };
                            (v, Vec2::new(x as f32 + next(), y as f32 + next()))
                        })
                        .collect()
                })
                .collect();
            // a stopped pass: rows cut short or left empty
            if h > 2 {
                rows[1].clear();
                rows[2].truncate(w as usize / 2);
            }
            let splats: Vec<Vec<(Vec2, Rgb)>> = (0..3)
                .map(|_| {
                    (0..5000)
                        .map(|_| {
                            let raster = Vec2::new(next() * (w as f32 + 2.0) - 1.0, next() * (h as f32 + 2.0) - 1.0);
                            let v =
                                if next() < 0.01 { Rgb::splat(f32::INFINITY) } else { Rgb::new(next(), 1.0, next()) };
                            (raster, v)
                        })
                        .collect()
                })
                .collect();
            let mut serial = TileAccum::new(spec.full(), &spec);
            for (y, row) in rows.iter().enumerate() {
                for (x, (v, raster)) in row.iter().enumerate() {
                    serial.add_sample(x as u32, y as u32, *raster, *v);
                }
            }
            for (raster, v) in splats.iter().flatten() {
                serial.add_splat(*raster, *v);
            }
            let mut bands = TileAccum::new(spec.full(), &spec);
            let slices: Vec<&[(Rgb, Vec2)]> = rows.iter().map(|r| r.as_slice()).collect();
            bands.add_frame(&slices, &splats);
            assert!(serial.non_finite > 0, "{kind:?}");
            assert_eq!(bands, serial, "{kind:?} {w}×{h}");
        }
    }
}
