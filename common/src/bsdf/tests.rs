//! Tests of every BSDF: chi² of the sampler against its pdf, consistency of sampled values
//! with `eval`/`pdf`, reciprocity, energy conservation and white-furnace tests.

use super::*;
use crate::math::{PI, warp};
use crate::sampler::Sampler;
use crate::testing::chi2::chi2_test;

fn ggx(a: f32) -> Microfacet {
    Microfacet::new(MicrofacetKind::Ggx, a, a, true)
}

fn beckmann(a: f32) -> Microfacet {
    Microfacet::new(MicrofacetKind::Beckmann, a, a, true)
}

/// Every model with non-delta lobes, with representative parameters.
fn smooth_models() -> Vec<(&'static str, Bxdf)> {
    let au = Rgb::new(0.143, 0.375, 1.442);
    let ak = Rgb::new(3.983, 2.386, 1.603);
    vec![
        ("diffuse", Bxdf::Diffuse(Diffuse { reflectance: Rgb::new(0.8, 0.5, 0.2) })),
        (
            "roughconductor-ggx-0.3",
            Bxdf::RoughConductor(RoughConductor {
                distribution: ggx(0.3),
                eta: au,
                k: ak,
                specular_reflectance: Rgb::ONE,
            }),
        ),
        (
            "roughconductor-ggx-aniso",
            Bxdf::RoughConductor(RoughConductor {
                distribution: Microfacet::new(MicrofacetKind::Ggx, 0.15, 0.4, true),
                eta: au,
                k: ak,
                specular_reflectance: Rgb::ONE,
            }),
        ),
        (
            "roughconductor-beckmann-0.2",
            Bxdf::RoughConductor(RoughConductor {
                distribution: beckmann(0.2),
                eta: au,
                k: ak,
                specular_reflectance: Rgb::ONE,
            }),
        ),
        (
            "roughdielectric-ggx-0.3",
            Bxdf::RoughDielectric(RoughDielectric {
                distribution: ggx(0.3),
                eta: 1.5,
                specular_reflectance: Rgb::ONE,
                specular_transmittance: Rgb::ONE,
            }),
        ),
        (
            "roughdielectric-beckmann-0.2",
            Bxdf::RoughDielectric(RoughDielectric {
                distribution: beckmann(0.2),
                eta: 1.5,
                specular_reflectance: Rgb::ONE,
                specular_transmittance: Rgb::ONE,
            }),
        ),
        ("plastic", Bxdf::Plastic(Plastic::new(1.49, Rgb::new(0.5, 0.3, 0.2), None, false))),
        (
            "roughplastic-ggx-0.2",
            Bxdf::RoughPlastic(RoughPlastic::new(ggx(0.2), 1.49, Rgb::new(0.5, 0.3, 0.2), None, false).unwrap()),
        ),
    ]
}

fn directions() -> Vec<Vec3> {
    vec![
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.5, 0.2, 0.6).normalize(),
        Vec3::new(-0.8, 0.3, 0.25).normalize(),
        Vec3::new(0.3, -0.2, -0.7).normalize(),
    ]
}

#[test]
fn bsdf_sampling_matches_pdf_chi2() {
    let mut tests = 0;
    let mut failures = Vec::new();
    let n_tests = smooth_models().len() * directions().len() * 2;
    // Šidák-corrected significance for the whole family at 1 %
    let alpha = 1.0 - (1.0 - 0.01f64).powf(1.0 / n_tests as f64);
    for (name, bxdf) in smooth_models() {
        for mode in [TransportMode::Radiance, TransportMode::Importance] {
            for wo in directions() {
                let material = Material::one_sided(bxdf.clone());
                let r = chi2_test(
                    400_000,
                    24,
                    48,
                    |i| {
                        let mut s = Sampler::for_pixel(11, i as u32, tests);
                        let bs = material.sample(wo, s.next_1d(), s.next_2d(), mode)?;
                        (!bs.delta).then_some(bs.wi)
                    },
                    |wi| material.pdf(wo, wi),
                );
                tests += 1;
                if !r.passes(alpha) {
                    failures.push(format!("{name} wo={wo} {mode:?}: {r:?}"));
                }
            }
        }
    }
    assert!(failures.is_empty(), "chi² failures:\n{}", failures.join("\n"));
}

#[test]
fn sampled_values_agree_with_eval_and_pdf() {
    for (name, bxdf) in smooth_models() {
        let m = Material::one_sided(bxdf);
        for wo in directions() {
            for i in 0..2000 {
                let mut s = Sampler::for_pixel(5, i, 0);
                let Some(bs) = m.sample(wo, s.next_1d(), s.next_2d(), TransportMode::Radiance) else { continue };
                if bs.delta {
                    continue;
                }
                let f = m.eval(wo, bs.wi, TransportMode::Radiance);
                let pdf = m.pdf(wo, bs.wi);
                assert!((pdf - bs.pdf).abs() <= 1e-3 * pdf.max(1.0), "{name}: pdf {pdf} vs sampled {}", bs.pdf);
                assert!(
                    (f - bs.f).abs().max_element() <= 1e-3 * f.max_element().max(1.0),
                    "{name}: f {f} vs sampled {}",
                    bs.f
                );
                let w = f * bs.wi.z.abs() / pdf;
                assert!((w - bs.weight).abs().max_element() <= 1e-3 * w.max_element().max(1.0), "{name}: weight");
                assert!(bs.weight.is_finite() && bs.weight.min_element() >= 0.0);
            }
        }
    }
}

/// Reflection is reciprocal: f(a, b) = f(b, a). Refraction obeys the generalised form
/// f(a, b) η_a² = f(b, a) η_b² for the raw BTDF (importance mode, no 1/η² radiance scaling),
/// where η_x is the index on the side of direction x.
#[test]
fn bsdfs_are_reciprocal() {
    for (name, bxdf) in smooth_models() {
        let m = Material::one_sided(bxdf);
        let interior_eta = if name.starts_with("roughdielectric") { 1.5f32 } else { 1.0 };
        for i in 0..2000u32 {
            let mut s = Sampler::for_pixel(9, i, 0);
            let a = warp::square_to_uniform_sphere(s.next_2d());
            let b = warp::square_to_uniform_sphere(s.next_2d());
            let eta_of = |w: Vec3| if w.z > 0.0 { 1.0 } else { interior_eta };
            let lhs = m.eval(a, b, TransportMode::Importance) * eta_of(a) * eta_of(a);
            let rhs = m.eval(b, a, TransportMode::Importance) * eta_of(b) * eta_of(b);
            let scale = lhs.max_element().max(rhs.max_element()).max(1e-3);
            assert!(
                (lhs - rhs).abs().max_element() <= 2e-3 * scale,
                "{name}: f(a,b)η_a²={lhs} f(b,a)η_b²={rhs} a={a} b={b}"
            );
        }
    }
}

/// Directional albedo ∫ f |cos| by importance sampling (weights average to the albedo).
fn albedo(m: &Material, wo: Vec3, n: u32) -> Rgb {
    let mut sum = Rgb::ZERO;
    for i in 0..n {
        let mut s = Sampler::for_pixel(21, i, 7);
        if let Some(bs) = m.sample(wo, s.next_1d(), s.next_2d(), TransportMode::Importance) {
            sum += bs.weight;
        }
    }
    sum / n as f32
}

#[test]
fn albedo_never_exceeds_one() {
    let white = |b: Bxdf| Material::one_sided(b);
    let mut models: Vec<(&str, Material)> = smooth_models().into_iter().map(|(n, b)| (n, white(b))).collect();
    models.push((
        "dielectric",
        white(Bxdf::Dielectric(Dielectric {
            eta: 1.5,
            specular_reflectance: Rgb::ONE,
            specular_transmittance: Rgb::ONE,
        })),
    ));
    models.push((
        "thindielectric",
        white(Bxdf::ThinDielectric(ThinDielectric {
            eta: 1.5,
            specular_reflectance: Rgb::ONE,
            specular_transmittance: Rgb::ONE,
        })),
    ));
    models.push((
        "conductor",
        white(Bxdf::Conductor(Conductor { eta: Rgb::ZERO, k: Rgb::ONE, specular_reflectance: Rgb::ONE })),
    ));
    models.push(("plastic-white", white(Bxdf::Plastic(Plastic::new(1.5, Rgb::ONE, None, false)))));
    models.push((
        "roughplastic-white",
        white(Bxdf::RoughPlastic(RoughPlastic::new(ggx(0.3), 1.5, Rgb::ONE, None, false).unwrap())),
    ));
    for (name, m) in models {
        for wo in directions().into_iter().filter(|w| w.z > 0.0) {
            let a = albedo(&m, wo, 100_000);
            assert!(a.max_element() <= 1.0 + 0.01, "{name}: albedo {a} at {wo}");
        }
    }
}

#[test]
fn white_furnace_diffuse_and_rough_conductor() {
    // a white Lambertian reflects everything
    let d = Material::one_sided(Bxdf::Diffuse(Diffuse { reflectance: Rgb::ONE }));
    for wo in directions().into_iter().filter(|w| w.z > 0.0) {
        let a = albedo(&d, wo, 50_000);
        assert!((a - Rgb::ONE).abs().max_element() < 1e-5, "diffuse furnace {a}");
    }
    // a perfect rough conductor (F = 1) loses only what single-scattering Smith masking loses:
    // the weak white furnace ∫ D(m) G1(wo, m) <wo, m> / cos θo dm = 1 holds exactly ...
    for alpha in [0.05f32, 0.2, 0.5] {
        let dist = ggx(alpha);
        for wo in directions().into_iter().filter(|w| w.z > 0.0) {
            let n = 400_000;
            let mut sum = 0.0f64;
            for i in 0..n {
                let mut s = Sampler::for_pixel(2, i, 0);
                let m = warp::square_to_uniform_sphere(s.next_2d());
                sum += (dist.d(m) * dist.g1(wo, m) * wo.dot(m).max(0.0) / wo.z) as f64 * 4.0 * PI as f64;
            }
            let weak = sum / n as f64;
            assert!((weak - 1.0).abs() < 0.03, "weak furnace alpha {alpha}: {weak}");
        }
        // ... and the full albedo, estimated by sampling, equals an independent quadrature of
        // eval and stays at most 1 (Smith single scattering loses energy as roughness grows)
        let m = Material::one_sided(Bxdf::RoughConductor(RoughConductor {
            distribution: dist,
            eta: Rgb::ZERO,
            k: Rgb::ONE,
            specular_reflectance: Rgb::ONE,
        }));
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8)] {
            let sampled = albedo(&m, wo, 400_000).x;
            let quadrature = albedo_by_quadrature(&m, wo);
            assert!(sampled <= 1.0 + 1e-3, "alpha {alpha}: {sampled}");
            assert!(
                (sampled - quadrature).abs() < 0.01,
                "rough conductor furnace alpha {alpha} wo {wo}: sampled {sampled} quadrature {quadrature}"
            );
            if alpha <= 0.05 {
                assert!(sampled > 0.97, "a nearly smooth perfect conductor reflects almost everything: {sampled}");
            }
        }
    }
}

/// ∫ f(wo, wi) |cos θi| dwi over the sphere by a midpoint rule in (cos θ, φ), fine near the
/// poles; independent of the sampling routines.
fn albedo_by_quadrature(m: &Material, wo: Vec3) -> f32 {
    let (nz, np) = (2000, 720);
    let mut sum = 0.0f64;
    for i in 0..nz {
        // cos θ spaced more densely near ±1 where glossy lobes live
        let t = (i as f64 + 0.5) / nz as f64;
        let z = (t * std::f64::consts::PI).cos() * -1.0;
        let dz = (std::f64::consts::PI / nz as f64) * (t * std::f64::consts::PI).sin();
        let r = (1.0 - z * z).max(0.0).sqrt();
        for j in 0..np {
            let phi = (j as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
            let wi = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
            sum += (m.eval(wo, wi, TransportMode::Importance).x * wi.z.abs()) as f64
                * dz
                * (2.0 * std::f64::consts::PI / np as f64);
        }
    }
    sum as f32
}

#[test]
fn twosided_mirrors_the_front() {
    let front = Bxdf::Diffuse(Diffuse { reflectance: Rgb::splat(0.5) });
    let one = Material::one_sided(front.clone());
    let two = Material::two_sided(front, None);
    let (wo, wi) = (Vec3::new(0.1, 0.2, -0.9).normalize(), Vec3::new(-0.3, 0.1, -0.8).normalize());
    assert_eq!(one.eval(wo, wi, TransportMode::Radiance), Rgb::ZERO);
    assert!((two.eval(wo, wi, TransportMode::Radiance) - Rgb::splat(0.5 / PI)).abs().max_element() < 1e-6);
    let mut s = Sampler::for_pixel(1, 1, 1);
    let bs = two.sample(wo, s.next_1d(), s.next_2d(), TransportMode::Radiance).unwrap();
    assert!(bs.wi.z < 0.0, "sampled on the viewer's side");
    assert!(one.sample(wo, 0.5, Vec2::splat(0.5), TransportMode::Radiance).is_none());
}

#[test]
fn smooth_dielectric_conserves_energy_and_scales_radiance() {
    let m = Material::one_sided(Bxdf::Dielectric(Dielectric {
        eta: 1.5,
        specular_reflectance: Rgb::ONE,
        specular_transmittance: Rgb::ONE,
    }));
    let wo = Vec3::new(0.6, 0.0, 0.8);
    let f = fresnel::fresnel_dielectric(0.8, 1.5).0;
    let r = m.sample(wo, f * 0.5, Vec2::ZERO, TransportMode::Radiance).unwrap();
    assert!(r.delta && !r.transmission && (r.weight - Rgb::ONE).abs().max_element() < 1e-6);
    let t = m.sample(wo, 0.99, Vec2::ZERO, TransportMode::Radiance).unwrap();
    assert!(t.transmission && (t.eta - 1.5).abs() < 1e-6);
    assert!((t.weight.x - 1.0 / 2.25).abs() < 1e-5, "radiance is compressed entering glass");
    let ti = m.sample(wo, 0.99, Vec2::ZERO, TransportMode::Importance).unwrap();
    assert!((ti.weight.x - 1.0).abs() < 1e-6);
}

#[test]
fn mask_passes_light_through_with_probability_one_minus_opacity() {
    let mut m = Material::one_sided(Bxdf::Diffuse(Diffuse { reflectance: Rgb::splat(0.5) }));
    m.opacity = 0.3;
    let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
    let wi = Vec3::new(-0.1, 0.4, 0.8).normalize();
    assert!((m.eval(wo, wi, TransportMode::Radiance) - Rgb::splat(0.3 * 0.5 / PI)).abs().max_element() < 1e-6);
    assert!((m.pdf(wo, wi) - 0.3 * wi.z / PI).abs() < 1e-6);
    let (n, mut through, mut weight) = (100_000, 0, Rgb::ZERO);
    for i in 0..n {
        let mut s = Sampler::for_pixel(5, i, 3);
        let bs = m.sample(wo, s.next_1d(), s.next_2d(), TransportMode::Importance).expect("a sample");
        weight += bs.weight;
        if bs.delta {
            through += 1;
            assert_eq!((bs.wi, bs.weight, bs.pdf, bs.transmission), (-wo, Rgb::ONE, 0.7, true));
        } else {
            // the scattered lobe keeps its weight; its value and density carry the opacity
            assert!((bs.pdf - m.pdf(wo, bs.wi)).abs() < 1e-5);
            assert!((bs.f - m.eval(wo, bs.wi, TransportMode::Importance)).abs().max_element() < 1e-5);
        }
    }
    let through = through as f32 / n as f32;
    assert!((through - 0.7).abs() < 0.01, "{through}");
    // albedo: 0.7 passed on unchanged plus 0.3 × the diffuse albedo 0.5
    assert!((weight / n as f32 - Rgb::splat(0.85)).abs().max_element() < 0.01, "{weight:?}");
}
