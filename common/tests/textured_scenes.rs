//! Scenes with textures, masks and the new emitters: what loads, what is shared, and that every
//! mistake is an error naming the file and line (never a panic, never a silent fallback).

mod common;

use std::collections::HashMap;
use tessera_common::bsdf::Bxdf;
use tessera_common::light::Light;
use tessera_common::scene::{LoadOptions, Scene, SceneError, SceneLimits};
use tessera_common::texture::TextureLimits;

const SENSOR: &str = r#"<sensor type="perspective"><float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/></film></sensor>"#;

/// A 4×2 8-bit RGB PNG.
fn png() -> Vec<u8> {
    let mut out = Vec::new();
    let img = image::RgbImage::from_fn(4, 2, |x, y| image::Rgb([(x * 60) as u8, (y * 200) as u8, 30]));
    img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png).expect("png");
    out
}

/// Writes `files` into a temporary folder and loads `scene.xml` (body wrapped in a scene with a
/// sensor) with `limits`.
fn load_with(
    body: &str,
    files: &[(&str, &[u8])],
    limits: TextureLimits,
) -> (Result<Scene, SceneError>, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("tempdir");
    for (name, data) in files {
        std::fs::write(dir.path().join(name), data).expect("write");
    }
    let xml = format!("<scene version=\"3.0.0\">\n{SENSOR}\n{body}\n</scene>\n");
    std::fs::write(dir.path().join("scene.xml"), xml).expect("write");
    let limits = SceneLimits { textures: limits, ..SceneLimits::default() };
    let options = LoadOptions { defines: HashMap::new(), limits, confine_to: None };
    (Scene::load_options(&dir.path().join("scene.xml"), &options), dir)
}

fn load(body: &str, files: &[(&str, &[u8])]) -> (Result<Scene, SceneError>, tempfile::TempDir) {
    load_with(body, files, TextureLimits::default())
}

/// The body's error, checked to name scene.xml at `line` (the body starts on line 4) and to
/// contain `needle`.
fn expect_error(body: &str, files: &[(&str, &[u8])], line: u32, needle: &str) -> String {
    let (result, dir) = load(body, files);
    let err = result.err().unwrap_or_else(|| panic!("expected an error mentioning {needle:?}"));
    let msg = err.to_string();
    assert_eq!((err.location.file.to_path_buf(), err.location.line), (dir.path().join("scene.xml"), line), "{msg}");
    assert!(msg.contains(needle), "{msg:?} should mention {needle:?}");
    msg
}

fn diffuse_with(texture: &str) -> String {
    format!(r#"<shape type="sphere"><bsdf type="diffuse">{texture}</bsdf></shape>"#)
}

#[test]
fn a_texture_referenced_twice_is_decoded_once() {
    let body = r#"<texture type="bitmap" id="wood"><string name="filename" value="wood.png"/></texture>
        <shape type="sphere"><bsdf type="diffuse"><ref name="reflectance" id="wood"/></bsdf></shape>
        <shape type="cube"><bsdf type="roughplastic"><ref name="diffuse_reflectance" id="wood"/></bsdf></shape>
        <shape type="disk"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="wood.png"/></texture></bsdf></shape>"#;
    let (scene, _dir) = load(body, &[("wood.png", &png())]);
    let scene = scene.expect("loads");
    // 4×2 texels of 3 bytes, padded to at least 2×2: 24 bytes, once for all three uses
    assert_eq!(scene.texture_bytes, 24);
    assert!(scene.material_textures.iter().filter(|t| t.is_some()).count() == 3);
}

#[test]
fn constant_textures_keep_the_fast_path() {
    let body =
        diffuse_with(r#"<texture type="srgb" name="reflectance"><rgb name="color" value="0.2, 0.4, 0.6"/></texture>"#);
    let (scene, _dir) = load(&body, &[]);
    let scene = scene.expect("loads");
    assert!(scene.material_textures.iter().all(|t| t.is_none()));
    assert!(matches!(&scene.materials[0].front, Bxdf::Diffuse(d) if d.reflectance.y == 0.4));
}

#[test]
fn image_files_that_cannot_be_used_are_errors_at_the_filename() {
    let tex = |file: &str| {
        diffuse_with(&format!(
            "<texture type=\"bitmap\" name=\"reflectance\">\n<string name=\"filename\" value=\"{file}\"/></texture>"
        ))
    };
    expect_error(&tex("missing.png"), &[], 5, "not found");
    expect_error(&tex("broken.png"), &[("broken.png", b"\x89PNG\r\n\x1a\nnot really")], 5, "corrupt");
    expect_error(&tex("notes.xyz"), &[("notes.xyz", b"hello")], 5, "unknown image format");
    // a budget smaller than the image: refused from its header
    let (result, _dir) = load_with(&tex("wood.png"), &[("wood.png", &png())], TextureLimits::total(10));
    let msg = result.err().expect("over budget").to_string();
    assert!(msg.contains("over the texture budget"), "{msg}");
}

#[test]
fn several_images_share_the_scene_budget() {
    let body = format!(
        "{}\n{}",
        diffuse_with(r#"<texture type="bitmap" name="reflectance"><string name="filename" value="a.png"/></texture>"#),
        diffuse_with(r#"<texture type="bitmap" name="reflectance"><string name="filename" value="b.png"/></texture>"#)
    );
    let files: [(&str, &[u8]); 2] = [("a.png", &png()), ("b.png", &png())];
    let limits = TextureLimits { max_decoded_bytes: 30, max_total_bytes: 40 };
    let (result, _dir) = load_with(&body, &files, limits);
    let msg = result.err().expect("the second image exceeds what is left").to_string();
    assert!(msg.contains("b.png") && msg.contains("may take 40 bytes in all"), "{msg}");
}

#[test]
fn bad_texture_parameters_name_their_line() {
    let bitmap = |param: &str| {
        diffuse_with(&format!(
            "<texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"w.png\"/>\n{param}</texture>"
        ))
    };
    let files: [(&str, &[u8]); 1] = [("w.png", &png())];
    expect_error(&bitmap(r#"<string name="filter_type" value="cubic"/>"#), &files, 5, "bilinear, nearest");
    expect_error(&bitmap(r#"<string name="wrap_mode" value="wrap"/>"#), &files, 5, "repeat, mirror, clamp");
    expect_error(&bitmap(r#"<float name="gamma" value="2.2"/>"#), &files, 5, "unknown parameter \"gamma\"");
    expect_error(
        &diffuse_with("<texture type=\"checkerboard\" name=\"albedo\"/>"),
        &[],
        4,
        "unknown parameter \"albedo\"",
    );
    expect_error(
        &diffuse_with("\n<texture type=\"noise\" name=\"reflectance\"/>"),
        &[],
        5,
        "unsupported texture \"noise\"",
    );
}

#[test]
fn mask_and_twosided_follow_mitsuba_rules() {
    let ok = r#"<shape type="rectangle"><bsdf type="mask"><float name="opacity" value="0.25"/>
        <bsdf type="twosided"><bsdf type="diffuse"/></bsdf></bsdf></shape>"#;
    let (scene, _dir) = load(ok, &[]);
    assert_eq!(scene.expect("loads").materials[0].opacity, 0.25);
    // Mitsuba's default opacity is 0.5
    let (scene, _dir) = load(r#"<shape type="rectangle"><bsdf type="mask"><bsdf type="diffuse"/></bsdf></shape>"#, &[]);
    assert_eq!(scene.expect("loads").materials[0].opacity, 0.5);
    expect_error("<shape type=\"rectangle\">\n<bsdf type=\"mask\"/></shape>", &[], 5, "mask needs one nested bsdf");
    expect_error(
        "<shape type=\"rectangle\"><bsdf type=\"mask\">\n<bsdf type=\"mask\"><bsdf type=\"diffuse\"/></bsdf></bsdf></shape>",
        &[],
        5,
        "a mask inside a mask",
    );
    expect_error(
        "<shape type=\"sphere\"><bsdf type=\"twosided\">\n<bsdf type=\"dielectric\"/></bsdf></shape>",
        &[],
        5,
        "allow_transmission",
    );
    let allowed = r#"<shape type="sphere"><bsdf type="twosided"><boolean name="allow_transmission" value="true"/>
        <bsdf type="mask"><float name="opacity" value="0.5"/><bsdf type="diffuse"/></bsdf></bsdf></shape>"#;
    let (scene, _dir) = load(allowed, &[]);
    assert_eq!(scene.expect("twosided(mask) with allow_transmission loads").materials[0].opacity, 0.5);
}

#[test]
fn parameters_mitsuba_does_not_texture_are_refused() {
    let tex = r#"<texture type="checkerboard" name="NAME"/>"#;
    let rough_plastic =
        format!("<shape type=\"sphere\"><bsdf type=\"roughplastic\">\n{}</bsdf></shape>", tex.replace("NAME", "alpha"));
    expect_error(&rough_plastic, &[], 5, "must be a number");
    let conductor =
        format!("<shape type=\"sphere\"><bsdf type=\"conductor\">\n{}</bsdf></shape>", tex.replace("NAME", "eta"));
    expect_error(&conductor, &[], 5, "textured \"eta\"");
    let spot = "<emitter type=\"spot\">\n<texture type=\"checkerboard\" name=\"intensity\"/></emitter>";
    expect_error(spot, &[], 5, "only an area light's radiance and a spot's texture can be textures");
    // a spot's projected image must vary, as Mitsuba requires
    let flat = "<emitter type=\"spot\">\n<rgb name=\"texture\" value=\"0.5\"/></emitter>";
    expect_error(flat, &[], 5, "must vary over the image");
}

#[test]
fn mesh_attributes_come_from_ply_properties_as_mitsuba_groups_them() {
    // the file Mitsuba 3.9.1 loads as vertex_color [255, 128, 0, 10, 20, 30, 0, 0, 0] (integer
    // colours unscaled), vertex_temp [0.5, 0.25, 1] and face_q_color [0.1, 0.2, 0.3]; "foo" has
    // no postfix and is ignored
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
        property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float temp_x\nproperty float foo\n\
        element face 1\nproperty list uchar int vertex_indices\nproperty float q_r\nproperty float q_g\nproperty float q_b\n\
        end_header\n0 0 0 255 128 0 0.5 2\n1 0 0 10 20 30 0.25 3\n0 1 0 0 0 0 1 4\n3 0 1 2 0.1 0.2 0.3\n";
    let body = r#"<shape type="ply"><string name="filename" value="t.ply"/>
        <bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance"><string name="name" value="face_q_color"/></texture></bsdf></shape>"#;
    let (scene, _dir) = load(body, &[("t.ply", ply.as_bytes())]);
    let scene = scene.expect("loads");
    let attrs = &scene.meshes[0].attributes;
    let get = |name: &str| attrs.iter().find(|a| a.name() == name).map(|a| (a.components(), a.data().to_vec()));
    assert_eq!(get("vertex_color"), Some((3, vec![255.0, 128.0, 0.0, 10.0, 20.0, 30.0, 0.0, 0.0, 0.0])));
    assert_eq!(get("vertex_temp"), Some((1, vec![0.5, 0.25, 1.0])));
    assert_eq!(get("face_q_color"), Some((3, vec![0.1, 0.2, 0.3])));
    assert_eq!(attrs.len(), 3);
    // an attribute the shape lacks names the shape and what it has
    let missing = "<shape type=\"ply\">\n<string name=\"filename\" value=\"t.ply\"/><bsdf type=\"diffuse\"><texture type=\"mesh_attribute\" name=\"reflectance\"><string name=\"name\" value=\"vertex_uv\"/></texture></bsdf></shape>";
    let msg = expect_error(missing, &[("t.ply", ply.as_bytes())], 4, "vertex_uv");
    assert!(msg.contains("vertex_color"), "lists the attributes there are: {msg}");
    // plastic needs its texture's mean, which mesh_attribute lacks (Mitsuba fails too)
    let plastic = "<shape type=\"ply\"><string name=\"filename\" value=\"t.ply\"/><bsdf type=\"plastic\">\n<texture type=\"mesh_attribute\" name=\"diffuse_reflectance\"><string name=\"name\" value=\"vertex_color\"/></texture></bsdf></shape>";
    expect_error(plastic, &[("t.ply", ply.as_bytes())], 5, "lacks");
}

#[test]
fn emitters_check_their_parameters() {
    expect_error(
        "<emitter type=\"directional\"><vector name=\"direction\" value=\"0, -1, 0\"/>\n<transform name=\"to_world\"/></emitter>",
        &[],
        4,
        "not both",
    );
    expect_error(
        "<emitter type=\"spot\"><float name=\"cutoff_angle\" value=\"20\"/>\n<float name=\"beam_width\" value=\"30\"/></emitter>",
        &[],
        5,
        "beam_width",
    );
    expect_error(
        "<emitter type=\"envmap\">\n<string name=\"filename\" value=\"sky.exr\"/></emitter>",
        &[],
        5,
        "not found",
    );
    let (scene, _dir) = load(
        r#"<emitter type="spot"><transform name="to_world"><lookat origin="0, 2, 0" target="0, 0, 0"/></transform></emitter>
        <emitter type="envmap"><string name="filename" value="sky.png"/><float name="scale" value="2"/></emitter>"#,
        &[("sky.png", &png())],
    );
    let scene = scene.expect("loads");
    let Light::Spot(spot) = &scene.lights[0] else { panic!("spot") };
    // Mitsuba's defaults: cutoff 20 degrees, beam width 3/4 of it
    assert!((spot.cutoff.to_degrees() - 20.0).abs() < 1e-4 && (spot.beam.to_degrees() - 15.0).abs() < 1e-4);
    assert!((spot.frame.n - glam::Vec3::new(0.0, -1.0, 0.0)).length() < 1e-5);
    assert!(matches!(scene.lights[1], Light::Envmap(_)));
    assert!(scene.texture_bytes > 0, "the environment map's memory is counted");
}

#[test]
fn textured_area_lights_load() {
    let body = r#"<shape type="rectangle"><emitter type="area">
        <texture type="bitmap" name="radiance"><string name="filename" value="w.png"/></texture></emitter></shape>"#;
    let (scene, _dir) = load(body, &[("w.png", &png())]);
    let scene = scene.expect("loads");
    assert!(matches!(&scene.lights[0], Light::Area { texture: Some(_), .. }));
}

/// Mitsuba 3.9.1 cannot serve as the reference for `mesh_attribute` radiance: its next-event
/// estimation evaluates the texture on a surface interaction without a shape and gets zero
/// (`src/emitters/area.cpp`, `SurfaceInteraction3f(ds, ...)`). Tessera's estimators must agree
/// with each other instead: path tracing (emission looked up at next-event samples and at hits)
/// and light tracing (at emission samples) see the same mean.
#[test]
fn vertex_coloured_emitters_look_the_same_to_every_estimator() {
    // a 4x1 quad strip facing down, warm at one end and cold at the other, above a floor
    let mut ply = String::from(
        "ply\nformat ascii 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\n\
         property float r\nproperty float g\nproperty float b\nelement face 8\nproperty list uchar int vertex_indices\nend_header\n",
    );
    for j in 0..2 {
        for i in 0..5 {
            let t = i as f32 / 4.0;
            ply += &format!("{} {} 1 {} 1 {}\n", -1.0 + 2.0 * t, -0.3 + 0.6 * j as f32, 4.0 * (1.0 - t), 0.2 + 4.0 * t);
        }
    }
    for i in 0..4 {
        // wound clockwise seen from above, so the strip faces down (-z)
        ply += &format!("3 {} {} {}\n3 {} {} {}\n", i, i + 5, i + 1, i + 1, i + 5, i + 6);
    }
    let body = r#"<shape type="rectangle"><transform name="to_world"><scale value="3"/></transform><bsdf type="diffuse"/></shape>
        <shape type="ply"><string name="filename" value="strip.ply"/><emitter type="area">
        <texture type="mesh_attribute" name="radiance"><string name="name" value="vertex_color"/></texture></emitter></shape>"#;
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("strip.ply"), ply).expect("write");
    let sensor = r#"<sensor type="perspective"><float name="fov" value="50"/>
        <transform name="to_world"><lookat origin="0, -3, 2.5" target="0, 0, 0" up="0, 0, 1"/></transform>
        <film type="hdrfilm"><integer name="width" value="48"/><integer name="height" value="32"/></film></sensor>"#;
    let xml = format!("<scene version=\"3.0.0\">{sensor}{body}</scene>");
    std::fs::write(dir.path().join("scene.xml"), xml).expect("write");
    let scene = Scene::load(&dir.path().join("scene.xml")).expect("loads");
    let mean = |film: tessera_common::film::Film| {
        let px = film.average();
        let mut m = [0f64; 3];
        for p in &px {
            for c in 0..3 {
                m[c] += p[c] as f64 / px.len() as f64;
            }
        }
        m
    };
    let pt = mean(common::render_pt(&scene, 256, 1, 0));
    let lt = mean(common::render_lt(&scene, 256, 2, 0));
    let bdpt = mean(common::render_bdpt(&scene, 64, 3, 0));
    for c in 0..3 {
        assert!(pt[c] > 0.01, "the strip lights the floor: {pt:?}");
        assert!((lt[c] / pt[c] - 1.0).abs() < 0.01, "lt {lt:?} vs pt {pt:?}");
        assert!((bdpt[c] / pt[c] - 1.0).abs() < 0.01, "bdpt {bdpt:?} vs pt {pt:?}");
    }
}
