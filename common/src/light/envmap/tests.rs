//! Tests of the environment map: lookups against Mitsuba, sampling against its density.

use super::*;
use crate::testing::chi2::chi2_test;

/// The 5×4 test image of `scripts/envmap-goldens.py`.
fn image() -> Vec<Rgb> {
    let (w, h) = (5, 4);
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let b = 0.3 + 0.1 * (((i % w) * 7 + (i / w) * 3) % 5) as f32;
            Rgb::new(0.1 + 0.2 * x + 0.05 * y, 1.0 - 0.15 * y, b)
        })
        .collect()
}

fn rotation() -> Mat3 {
    Mat3::from_axis_angle(Vec3::new(0.3, 1.0, 0.2).normalize(), 37f32.to_radians())
}

/// Radiance Mitsuba 3.9.1 (`scalar_rgb`) returns for these directions, with scale 2, unrotated
/// and rotated: `scripts/envmap-goldens.py`.
type Golden = ((f32, f32, f32), (f32, f32, f32));
const PLAIN: &[Golden] = &[
    ((0.0, 1.0, 0.0), (9.999998808e-01, 2.000000000e+00, 9.000000358e-01)),
    ((0.0, -1.0, 0.0), (1.299999833e+00, 1.100000024e+00, 1.200000048e+00)),
    ((0.0, 0.0, -1.0), (1.149999976e+00, 1.549999952e+00, 1.049999952e+00)),
    ((1.0, 0.0, 0.0), (6.500000358e-01, 1.549999952e+00, 9.250000119e-01)),
    ((0.0, 0.0, 1.0), (1.150000095e+00, 1.549999952e+00, 8.000000119e-01)),
    ((-1.0, 0.0, 0.0), (1.649999976e+00, 1.549999952e+00, 1.174999952e+00)),
    ((0.300586717, 0.500977861, -0.811584135), (6.482670903e-01, 1.700323582e+00, 1.112493992e+00)),
    ((-0.952579344, 0.136082763, 0.272165527), (1.548378944e+00, 1.589106202e+00, 1.245568275e+00)),
    ((0.0507020127, -0.912636228, 0.405616101), (1.220203638e+00, 1.220638871e+00, 9.589331746e-01)),
    ((-0.00999750094, 0.199950019, -0.979755092), (1.143768668e+00, 1.607670188e+00, 1.030027628e+00)),
];
const ROTATED: &[Golden] = &[
    ((0.0, 1.0, 0.0), (3.048281670e-01, 1.938216448e+00, 7.644321322e-01)),
    ((0.0, -1.0, 0.0), (1.563638926e+00, 1.161783695e+00, 7.964240313e-01)),
    ((0.0, 0.0, -1.0), (4.013139606e-01, 1.490711451e+00, 9.268177152e-01)),
    ((1.0, 0.0, 0.0), (8.518247604e-01, 1.532867551e+00, 8.965144157e-01)),
    ((0.0, 0.0, 1.0), (1.322349310e+00, 1.609288573e+00, 1.071163535e+00)),
    ((-1.0, 0.0, 0.0), (1.840403080e+00, 1.567132592e+00, 1.106538296e+00)),
    ((0.300586717, 0.500977861, -0.811584135), (4.253918529e-01, 1.638682842e+00, 1.014443040e+00)),
    ((-0.952579344, 0.136082763, 0.272165527), (1.743327260e+00, 1.621142507e+00, 1.111922383e+00)),
    ((0.0507020127, -0.912636228, 0.405616101), (1.435255885e+00, 1.278944016e+00, 8.403968215e-01)),
    ((-0.00999750094, 0.199950019, -0.979755092), (3.792248070e-01, 1.548451185e+00, 9.998219013e-01)),
];

#[test]
fn lookups_match_mitsuba() {
    for (goldens, to_world) in [(PLAIN, Mat3::IDENTITY), (ROTATED, rotation())] {
        let map = Envmap::new(5, 4, &image(), 2.0, to_world);
        // at the poles u is undefined, and the two programs' signs of zero pick different columns
        for &((dx, dy, dz), (r, g, b)) in goldens.iter().filter(|g| g.0.1.abs() < 1.0) {
            let got = map.eval(Vec3::new(dx, dy, dz));
            let want = Rgb::new(r, g, b);
            assert!((got - want).abs().max_element() < 2e-5, "direction ({dx}, {dy}, {dz}): {got} vs Mitsuba's {want}");
        }
    }
}

#[test]
fn sampling_matches_its_density_chi2() {
    // a map with a bright spot, a dark band and an exactly black corner
    let (w, h) = (24, 12);
    let texels: Vec<Rgb> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            if x < 3 && y < 2 {
                Rgb::ZERO
            } else if (10..13).contains(&x) && (4..6).contains(&y) {
                Rgb::splat(40.0)
            } else {
                Rgb::new(0.2 + 0.05 * y as f32, 0.5, 1.0 - 0.03 * x as f32)
            }
        })
        .collect();
    for to_world in [Mat3::IDENTITY, rotation()] {
        let map = Envmap::new(w, h, &texels, 1.0, to_world);
        let r = chi2_test(
            400_000,
            40,
            80,
            |i| map.sample(crate::sampler::Sampler::for_pixel(11, i as u32, 0).next_2d()).map(|(d, _)| d),
            |d| map.pdf(d),
        );
        assert!(r.passes(0.01), "{r:?}");
        // samples agree with the density the lookup reports for them
        for i in 0..1000u32 {
            if let Some((d, pdf)) = map.sample(crate::sampler::Sampler::for_pixel(5, i, 0).next_2d()) {
                assert!((map.pdf(d) - pdf).abs() <= 1e-4 * pdf, "{} vs {pdf}", map.pdf(d));
            }
        }
    }
}

#[test]
fn every_direction_with_radiance_has_density() {
    let map = Envmap::new(5, 4, &image(), 1.0, rotation());
    let mut s = crate::sampler::Sampler::for_pixel(3, 0, 0);
    for _ in 0..10_000 {
        let d = crate::math::warp::square_to_uniform_sphere(s.next_2d());
        if map.eval(d).max_element() > 0.0 {
            assert!(map.pdf(d) > 0.0);
        }
    }
}
