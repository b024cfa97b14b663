//! Chi² tests of every light's direct-lighting and emission samplers against their pdfs.

use super::*;
use crate::geometry::Transform;
use crate::sampler::Sampler;
use crate::testing::chi2::chi2_test;

fn shapes() -> (Vec<Shape>, Vec<Mesh>) {
    let mut rect = Mesh::rectangle();
    let t = Transform::translate(glam::DVec3::new(0.3, 0.2, 2.0)).after(
        &Transform::rotate(glam::DVec3::X, 160.0)
            .unwrap()
            .after(&Transform::scale(glam::DVec3::new(0.8, 0.5, 1.0)).unwrap()),
    );
    rect.transform(&t);
    let mut cube = Mesh::cube();
    cube.transform(
        &Transform::translate(glam::DVec3::new(-1.0, 0.5, 1.5))
            .after(&Transform::scale(glam::DVec3::splat(0.4)).unwrap()),
    );
    let meshes = vec![rect, cube];
    let mk = |geometry, mesh: Option<&Mesh>| {
        let area = match &geometry {
            ShapeGeometry::Mesh(m) => {
                let m: &Mesh = &meshes[*m as usize];
                (0..m.triangles.len()).map(|i| m.triangle_area(i)).sum()
            }
            ShapeGeometry::Sphere { radius, .. } => 4.0 * PI * radius * radius,
            ShapeGeometry::Disk { .. } => PI * 0.5 * 0.3,
        };
        let mut s = Shape {
            geometry,
            material: 0,
            light: Some(0),
            flip_normals: false,
            area,
            area_sampling: Default::default(),
            id: None,
            object_rotation: glam::Mat3::IDENTITY,
        };
        s.prepare_area_sampling(mesh);
        s
    };
    let disk_t = Transform::translate(glam::DVec3::new(0.0, -1.0, 1.0)).after(
        &Transform::rotate(glam::DVec3::X, -70.0)
            .unwrap()
            .after(&Transform::scale(glam::DVec3::new(0.5, 0.3, 1.0)).unwrap()),
    );
    let shapes = vec![
        mk(ShapeGeometry::Mesh(0), Some(&meshes[0])),
        mk(ShapeGeometry::Mesh(1), Some(&meshes[1])),
        mk(ShapeGeometry::Sphere { center: Vec3::new(0.5, 0.5, 3.0), radius: 0.7 }, None),
        mk(ShapeGeometry::Sphere { center: Vec3::new(-0.2, 0.1, 4.0), radius: 0.02 }, None),
        mk(ShapeGeometry::Disk { to_world: disk_t, normal: disk_t.normal(Vec3::Z).normalize() }, None),
    ];
    (shapes, meshes)
}

#[test]
fn direct_sampling_matches_pdf_chi2() {
    let (shapes, meshes) = shapes();
    let ctx = LightContext { shapes: &shapes, meshes: &meshes, center: Vec3::ZERO, radius: 10.0 };
    // shape 3 is a tiny sphere tested by `tiny_sphere_cone_is_uniform` instead
    let mut lights: Vec<(String, Light)> = [0usize, 1, 2, 4]
        .iter()
        .map(|&i| (format!("area on shape {i}"), Light::Area { shape: i as u32, radiance: Rgb::ONE, texture: None }))
        .collect();
    lights.push(("constant".into(), Light::Constant { radiance: Rgb::ONE }));
    lights.push(("envmap".into(), test_envmap()));
    let alpha = 1.0 - 0.99f64.powf(1.0 / lights.len() as f64);
    let p_ref = Vec3::new(0.0, 0.0, 0.0);
    for (name, light) in &lights {
        let accel = match light {
            Light::Area { shape, .. } => {
                Some(crate::scene::accel::Accel::build(std::slice::from_ref(&shapes[*shape as usize]), &meshes))
            }
            _ => None,
        };
        let r = chi2_test(
            300_000,
            32,
            64,
            |i| {
                let mut s = Sampler::for_pixel(4, i as u32, 0);
                let d = light.sample_direct(&ctx, p_ref, s.next_2d())?;
                // area sampling also picks points hidden behind the shape's own front faces;
                // those are other paths (always occluded), so only first-hit points count
                if let (Light::Area { shape, .. }, Some(accel)) = (light, &accel) {
                    let (p, _) = first_hit(accel, &shapes[*shape as usize], &meshes, p_ref, d.wi)?;
                    if (p - d.p).length() > 1e-3 {
                        return None;
                    }
                }
                Some(d.wi)
            },
            |w| match (light, &accel) {
                (Light::Area { shape, .. }, Some(accel)) => {
                    match first_hit(accel, &shapes[*shape as usize], &meshes, p_ref, w) {
                        Some((p, n)) => light.pdf_direct(&ctx, p_ref, p, n),
                        None => 0.0,
                    }
                }
                _ => light.pdf_direct(&ctx, p_ref, p_ref + w, -w),
            },
        );
        assert!(r.passes(alpha), "{name}: {r:?}");
    }
}

/// A sphere subtending a tiny cone takes the Taylor branch: directions must stay inside the
/// cone, land on the sphere, and be uniform in solid angle ((1 − cos θ)/(1 − cos θmax) ~ U(0,1)).
#[test]
fn tiny_sphere_cone_is_uniform() {
    let (shapes, meshes) = shapes();
    let ctx = LightContext { shapes: &shapes, meshes: &meshes, center: Vec3::ZERO, radius: 10.0 };
    let light = Light::Area { shape: 3, radiance: Rgb::ONE, texture: None };
    let ShapeGeometry::Sphere { center, radius } = shapes[3].geometry else { unreachable!() };
    let axis = center.normalize();
    let (one_minus_cos_max, _) = sphere_cone(center.length_squared(), radius);
    let n = 100_000;
    let (mut m1, mut m2) = (0.0f64, 0.0f64);
    for i in 0..n {
        let mut s = Sampler::for_pixel(8, i, 0);
        let d = light.sample_direct(&ctx, Vec3::ZERO, s.next_2d()).unwrap();
        assert!(((d.p - center).length() - radius).abs() < 1e-4 * radius.max(1.0), "on the sphere");
        assert!((d.pdf * 2.0 * PI * one_minus_cos_max - 1.0).abs() < 1e-3);
        let x = ((1.0 - d.wi.dot(axis) as f64) / one_minus_cos_max as f64).min(1.5);
        m1 += x;
        m2 += x * x;
    }
    let (mean, var) = (m1 / n as f64, m2 / n as f64 - (m1 / n as f64).powi(2));
    // f32 rounding of 1 - cos at this scale is about 1e-7 / 1.2e-5: allow 2 %
    assert!((mean - 0.5).abs() < 0.02 && (var - 1.0 / 12.0).abs() < 0.01, "mean {mean} var {var}");
}

#[test]
fn emission_direction_sampling_matches_pdf_chi2() {
    let (shapes, meshes) = shapes();
    let ctx = LightContext { shapes: &shapes, meshes: &meshes, center: Vec3::ZERO, radius: 10.0 };
    let lights = [
        Light::Area { shape: 0, radiance: Rgb::ONE, texture: None },
        Light::Area { shape: 2, radiance: Rgb::ONE, texture: None },
        Light::Point { position: Vec3::ONE, intensity: Rgb::ONE },
        Light::Constant { radiance: Rgb::ONE },
        test_envmap(),
        test_spot(),
    ];
    // Šidák-corrected 1 % for the family
    let alpha = 1.0 - 0.99f64.powf(1.0 / lights.len() as f64);
    for light in lights {
        // fix the position sample so the direction distribution is for one normal
        let u_pos = Vec2::new(0.3, 0.6);
        let e0 = light.sample_emission(&ctx, u_pos, Vec2::splat(0.5)).unwrap();
        let r = chi2_test(
            200_000,
            32,
            64,
            |i| {
                let mut s = Sampler::for_pixel(6, i as u32, 0);
                light.sample_emission(&ctx, u_pos, s.next_2d()).map(|e| e.d)
            },
            // lights at infinity take the direction towards them, the opposite of travel
            |d| light.pdf_emission(&ctx, e0.n, if light.is_infinite() { -d } else { d }).1,
        );
        assert!(r.passes(alpha), "{light:?}: {r:?}");
    }
}

/// An environment map with a bright patch, rotated.
fn test_envmap() -> Light {
    let (w, h) = (16, 8);
    let texels: Vec<Rgb> = (0..w * h)
        .map(
            |i| if (5..8).contains(&(i % w)) && (2..4).contains(&(i / w)) { Rgb::splat(30.0) } else { Rgb::splat(0.5) },
        )
        .collect();
    let rotation = glam::Mat3::from_axis_angle(Vec3::new(1.0, 0.2, 0.3).normalize(), 0.7);
    Light::Envmap(Arc::new(Envmap::new(w, h, &texels, 1.0, rotation)))
}

/// A spot light at (0.2, 0.1, 0.3) aimed along (0.3, -0.2, 1), cutoff 30°, beam 20°.
fn test_spot() -> Light {
    Light::Spot(Spot {
        position: Vec3::new(0.2, 0.1, 0.3),
        frame: Frame::from_normal(Vec3::new(0.3, -0.2, 1.0).normalize()),
        intensity: Rgb::splat(5.0),
        cutoff: 30f32.to_radians(),
        beam: 20f32.to_radians(),
        projection: None,
    })
}

#[test]
fn spot_falloff_is_linear_in_the_angle_as_in_mitsuba() {
    // Mitsuba 3.9.1, cutoff 20°, default beam 15°: 0.5 at 17.5°, 0.02 at 19.9°
    let spot = Spot {
        position: Vec3::ZERO,
        frame: Frame::from_normal(Vec3::Z),
        intensity: Rgb::ONE,
        cutoff: 20f32.to_radians(),
        beam: 15f32.to_radians(),
        projection: None,
    };
    let at = |deg: f32| {
        let r = deg.to_radians();
        spot.emitted(Vec3::new(r.sin(), 0.0, r.cos())).x
    };
    assert_eq!(at(0.0), 1.0);
    assert_eq!(at(14.9), 1.0);
    assert!((at(17.5) - 0.5).abs() < 1e-4, "{}", at(17.5));
    assert!((at(19.9) - 0.02).abs() < 1e-4, "{}", at(19.9));
    assert_eq!(at(20.1), 0.0);
    let ctx = LightContext { shapes: &[], meshes: &[], center: Vec3::ZERO, radius: 10.0 };
    let l = Light::Spot(spot);
    let s = l.sample_direct(&ctx, Vec3::new(0.0, 0.0, 2.0), Vec2::ZERO).unwrap();
    assert!(s.delta && (s.radiance.x - 0.25).abs() < 1e-6);
    assert!(l.sample_direct(&ctx, Vec3::new(2.0, 0.0, 0.0), Vec2::ZERO).unwrap().radiance == Rgb::ZERO);
}

#[test]
fn directional_light_arrives_along_its_direction_and_is_delta() {
    let ctx = LightContext { shapes: &[], meshes: &[], center: Vec3::ZERO, radius: 3.0 };
    let direction = Vec3::new(0.0, -1.0, 0.0);
    let l = Light::Directional { direction, irradiance: Rgb::splat(2.0) };
    let s = l.sample_direct(&ctx, Vec3::new(0.5, 0.0, 0.0), Vec2::new(0.3, 0.8)).unwrap();
    assert!(s.delta && s.dist.is_infinite() && (s.wi - Vec3::Y).length() < 1e-6 && s.radiance.x == 2.0);
    assert!(l.is_infinite() && l.is_delta() && l.eval_infinite(Vec3::Y) == Rgb::ZERO);
    // emission: parallel rays from the scene's disk, carrying E·πR² in total
    let e = l.sample_emission(&ctx, Vec2::new(0.2, 0.9), Vec2::ZERO).unwrap();
    assert!((e.d - direction).length() < 1e-6 && e.pdf_dir == 1.0);
    assert!((e.pdf_pos * PI * 9.0 - 1.0).abs() < 1e-5);
    assert!((e.p - ctx.center).dot(direction) < -2.9, "the disk lies on the light's side");
}

#[test]
fn point_light_follows_inverse_square() {
    let (shapes, meshes) = shapes();
    let ctx = LightContext { shapes: &shapes, meshes: &meshes, center: Vec3::ZERO, radius: 10.0 };
    let l = Light::Point { position: Vec3::new(0.0, 2.0, 0.0), intensity: Rgb::splat(8.0) };
    let s = l.sample_direct(&ctx, Vec3::ZERO, Vec2::ZERO).unwrap();
    assert!(s.delta && (s.radiance.x - 2.0).abs() < 1e-6 && (s.wi - Vec3::Y).length() < 1e-6);
}

#[test]
fn area_light_emits_only_on_its_front() {
    let n = Vec3::Z;
    assert_eq!(Light::eval_area(Rgb::ONE, n, Vec3::new(0.0, 0.3, 0.9)), Rgb::ONE);
    assert_eq!(Light::eval_area(Rgb::ONE, n, Vec3::new(0.0, 0.3, -0.9)), Rgb::ZERO);
}

/// Brute-force ray/shape intersection for the test's pdf lookups.
fn first_hit(
    accel: &crate::scene::accel::Accel,
    shape: &Shape,
    meshes: &[Mesh],
    o: Vec3,
    d: Vec3,
) -> Option<(Vec3, Vec3)> {
    let hit = accel.closest_hit(&crate::geometry::Ray::new(o, d))?;
    let p = o + d * hit.t;
    let n = match &shape.geometry {
        ShapeGeometry::Mesh(m) => {
            let [a, b, c] = meshes[*m as usize].corners(hit.index as usize);
            (b - a).cross(c - a).normalize()
        }
        ShapeGeometry::Sphere { center, .. } => (p - *center).normalize(),
        ShapeGeometry::Disk { normal, .. } => *normal,
    };
    Some((p, n))
}
