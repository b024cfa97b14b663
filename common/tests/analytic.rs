//! Scenes with closed-form answers, rendered by `pt`.

mod common;

use common::{render_bdpt, render_lt, render_pt, render_vcm};
use std::collections::HashMap;
use std::path::Path;
use tessera_common::scene::Scene;

fn scene(xml: &str) -> Scene {
    Scene::from_xml(xml, Path::new("analytic.xml"), &HashMap::new()).expect("scene builds")
}

fn sensor(origin: &str, target: &str, size: u32) -> String {
    format!(
        r#"<sensor type="perspective"><float name="fov" value="30"/>
             <transform name="to_world"><lookat origin="{origin}" target="{target}" up="0, 1, 0"/></transform>
             <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/><rfilter type="box"/></film></sensor>"#
    )
}

/// Mean and standard error of the mean of the given pixels' luminance-free channel 0.
fn mean_and_stderr(film: &tessera_common::film::Film, pick: impl Fn(usize) -> bool) -> (f64, f64, usize) {
    let img = film.average();
    let vals: Vec<f64> = img.iter().enumerate().filter(|(i, _)| pick(*i)).map(|(_, p)| p[0] as f64).collect();
    let n = vals.len() as f64;
    let mean = vals.iter().sum::<f64>() / n;
    let var = vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, (var / n).sqrt(), vals.len())
}

/// A convex diffuse sphere of albedo ρ under a constant environment of radiance 1 reflects
/// exactly ρ in every direction (it sees only the environment), and the background is 1.
#[test]
fn diffuse_sphere_under_constant_sky_reflects_its_albedo() {
    let rho = 0.6;
    let s = scene(&format!(
        r#"<scene version="3.0.0">{}
             <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
             <shape type="sphere"><float name="radius" value="1"/><bsdf type="diffuse"><rgb name="reflectance" value="{rho}"/></bsdf></shape>
           </scene>"#,
        sensor("0, 0, 6", "0, 0, 0", 32)
    ));
    let film = render_pt(&s, 64, 7, 0);
    let w = 32usize;
    // the sphere's image is a disk around the centre with radius ≈ 16 · tan(asin(1/6)) / tan(15°)
    let on_sphere = |i: usize| {
        let (x, y) = ((i % w) as f64 - 15.5, (i / w) as f64 - 15.5);
        x * x + y * y < 6.0 * 6.0
    };
    let off_sphere = |i: usize| {
        let (x, y) = ((i % w) as f64 - 15.5, (i / w) as f64 - 15.5);
        x * x + y * y > 12.0 * 12.0
    };
    let (m, se, n) = mean_and_stderr(&film, on_sphere);
    assert!(n > 50);
    assert!((m - rho).abs() < 4.0 * se.max(1e-4), "sphere: {m} ± {se}, expected {rho}");
    let (bg, _, _) = mean_and_stderr(&film, off_sphere);
    assert!((bg - 1.0).abs() < 1e-6, "background {bg}");
}

/// A camera inside a closed diffuse sphere of albedo ρ whose inner surface emits radiance Le.
fn furnace(rho: f64, le: f64, max_depth: i64) -> Scene {
    scene(&format!(
        r#"<scene version="3.0.0">{}
             <integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>
             <shape type="sphere"><float name="radius" value="3"/><boolean name="flip_normals" value="true"/>
               <bsdf type="diffuse"><rgb name="reflectance" value="{rho}"/></bsdf>
               <emitter type="area"><rgb name="radiance" value="{le}"/></emitter></shape>
           </scene>"#,
        sensor("0, 0, 0", "0, 0, 1", 16)
    ))
}

/// Inside a closed diffuse sphere of albedo ρ whose inner surface also emits radiance Le, the
/// radiance is Le / (1 − ρ) everywhere (white furnace with emission): every bounce, Russian
/// roulette and light sampling must be unbiased for this to hold.
#[test]
fn closed_emissive_sphere_furnace() {
    let (rho, le) = (0.5, 1.0);
    let film = render_pt(&furnace(rho, le, -1), 64, 3, 0);
    let (m, se, _) = mean_and_stderr(&film, |_| true);
    let expected = le / (1.0 - rho);
    assert!((m - expected).abs() < 4.0 * se, "furnace: {m} ± {se}, expected {expected}");
    assert!(se < 0.02 * expected, "precise enough to mean something: {se}");
}

/// `max_depth` counts segments like Mitsuba: with max_depth 2 the furnace above gives only
/// emission + one bounce of emission: Le (1 + ρ).
#[test]
fn max_depth_counts_segments_like_mitsuba() {
    let (rho, le) = (0.5, 1.0);
    for (depth, expected) in [(1, le), (2, le * (1.0 + rho)), (3, le * (1.0 + rho + rho * rho))] {
        let film = render_pt(&furnace(rho, le, depth), 64, 5, 0);
        let (m, se, _) = mean_and_stderr(&film, |_| true);
        assert!((m - expected).abs() < 4.0 * se.max(1e-5), "max_depth {depth}: {m} ± {se}, expected {expected}");
    }
}

/// A light sealed inside a closed box: no light path reaches the camera outside it. Every
/// integrator gives a clean black image: no NaN, no panic.
#[test]
fn sealed_light_gives_a_clean_black_image() {
    let s = scene(&format!(
        r#"<scene version="3.0.0">{}
             <shape type="cube"><bsdf type="diffuse"/></shape>
             <shape type="sphere"><float name="radius" value="0.2"/><emitter type="area"><rgb name="radiance" value="10"/></emitter></shape>
             <emitter type="point"><point name="position" value="0, 0.5, 0"/><rgb name="intensity" value="5"/></emitter>
           </scene>"#,
        sensor("0, 0, 6", "0, 0, 0", 16)
    ));
    for (name, film) in [
        ("pt", render_pt(&s, 4, 1, 0)),
        ("lt", render_lt(&s, 4, 1, 0)),
        ("bdpt", render_bdpt(&s, 4, 1, 0)),
        ("vcm", render_vcm(&s, 4, 1, 0)),
    ] {
        assert_eq!(film.non_finite, 0, "{name}");
        assert!(film.average().iter().flatten().all(|&v| v == 0.0), "{name}: light leaked");
    }
}
