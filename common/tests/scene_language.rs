//! Mitsuba 3 scene-language features end to end (XML → `Scene`): file lookup through `<path>`
//! and `<include>` (with Mitsuba's pitfall for filenames in included files), old-version scenes,
//! the samplers and integrators accepted, spectra in RGB, and bundles of split scenes.

use std::collections::HashMap;
use tessera_common::bsdf::Bxdf;
use tessera_common::light::Light;
use tessera_common::math::Rgb;
use tessera_common::scene::{Scene, SceneError};

const SENSOR: &str = r#"<sensor type="perspective"><float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/></film></sensor>"#;

/// A triangle (3 vertices) and a quad (4 vertices), told apart by their vertex counts.
const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";

fn folder(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    for (name, text) in files {
        let path = dir.path().join(name);
        std::fs::create_dir_all(path.parent().expect("parent")).expect("mkdir");
        std::fs::write(path, text).expect("write");
    }
    dir
}

fn load(files: &[(&str, &str)]) -> (Result<Scene, SceneError>, tempfile::TempDir) {
    let dir = folder(files);
    (Scene::load(&dir.path().join("scene.xml")), dir)
}

fn scene_with(body: &str) -> String {
    format!("<scene version=\"3.0.0\">\n{SENSOR}\n{body}\n</scene>\n")
}

fn vertices(scene: &Scene) -> Vec<usize> {
    scene.meshes.iter().map(|m| m.positions.len()).collect()
}

fn obj_shape(filename: &str) -> String {
    format!(r#"<shape type="obj"><string name="filename" value="{filename}"/></shape>"#)
}

#[test]
fn path_entries_are_searched_before_the_scene_folder() {
    let xml = scene_with(&format!(r#"<path value="meshes"/>{}"#, obj_shape("m.obj")));
    let (scene, _dir) = load(&[("scene.xml", &xml), ("m.obj", TRIANGLE), ("meshes/m.obj", QUAD)]);
    assert_eq!(vertices(&scene.expect("loads")), [4]);
    // without the <path>, the scene's folder is used
    let (scene, _dir) =
        load(&[("scene.xml", &scene_with(&obj_shape("m.obj"))), ("meshes/m.obj", QUAD), ("m.obj", TRIANGLE)]);
    assert_eq!(vertices(&scene.expect("loads")), [3]);
}

#[test]
fn filenames_in_included_files_resolve_from_the_main_scene() {
    // Mitsuba resolves plugin filenames after parsing, against the main scene's list: a mesh
    // next to the included file is not found, a path from the main scene's folder is
    let inc = |f: &str| format!("<scene version=\"3.0.0\">{}</scene>", obj_shape(f));
    let xml = scene_with(r#"<include filename="sub/inc.xml"/>"#);
    let (result, dir) = load(&[("scene.xml", &xml), ("sub/inc.xml", &inc("tri.obj")), ("sub/tri.obj", TRIANGLE)]);
    let msg = result.err().expect("tri.obj is not next to the main scene").to_string();
    assert!(msg.contains(&dir.path().join("tri.obj").display().to_string()), "{msg}");
    let (result, _dir) = load(&[("scene.xml", &xml), ("sub/inc.xml", &inc("sub/tri.obj")), ("sub/tri.obj", TRIANGLE)]);
    assert_eq!(vertices(&result.expect("loads")), [3]);
}

#[test]
fn old_version_scene_loads_with_renamed_parameters() {
    let xml = r#"<scene version="0.6.0">
        <integrator type="path"><integer name="maxDepth" value="3"/><integer name="rrDepth" value="2"/></integrator>
        <sensor type="perspective">
            <float name="fov" value="40"/><string name="fovAxis" value="x"/><float name="nearClip" value="0.1"/>
            <transform name="toWorld"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
            <sampler type="independent"><integer name="sampleCount" value="8"/></sampler>
            <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/></film>
        </sensor>
        <shape type="sphere"><bsdf type="diffuse"><rgb name="diffuseReflectance" value="0.2"/></bsdf></shape>
        <shape type="sphere"><point name="center" value="3, 0, 0"/>
            <bsdf type="dielectric"><float name="intIOR" value="1.5"/><float name="extIOR" value="1.0"/></bsdf></shape>
        <shape type="rectangle"><transform name="toWorld"><translate z="2"/></transform>
            <emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
    </scene>"#;
    let (scene, _dir) = load(&[("scene.xml", xml)]);
    let scene = scene.expect("a 0.6 scene loads");
    assert_eq!((scene.integrator.max_depth, scene.integrator.rr_depth, scene.spp), (Some(3), 2, 8));
    assert!(matches!(&scene.materials[0].front, Bxdf::Diffuse(d) if d.reflectance == Rgb::splat(0.2)));
}

fn sampler_scene(sampler: &str) -> String {
    let sensor = SENSOR.replace("</film>", &format!("</film>{sampler}"));
    format!("<scene version=\"3.0.0\">\n{sensor}\n</scene>")
}

#[test]
fn every_mitsuba_sampler_is_accepted_with_its_rounded_count() {
    for (sampler, count, spp) in
        [("independent", 5, 5), ("stratified", 5, 9), ("multijitter", 5, 6), ("orthogonal", 5, 9), ("ldsampler", 5, 16)]
    {
        let s = format!(
            r#"<sampler type="{sampler}"><integer name="sample_count" value="{count}"/><integer name="seed" value="7"/></sampler>"#
        );
        let (scene, _dir) = load(&[("scene.xml", &sampler_scene(&s))]);
        let scene = scene.unwrap_or_else(|e| panic!("{sampler}: {e}"));
        assert_eq!((scene.spp, scene.seed), (spp, 7), "{sampler}");
    }
    let s = r#"<sampler type="stratified"><boolean name="jitter" value="false"/></sampler>"#;
    let msg = load(&[("scene.xml", &sampler_scene(s))]).0.err().expect("jitter=false is refused").to_string();
    assert!(msg.contains("jitter=false"), "{msg}");
}

fn integrator(xml: &str) -> Result<tessera_common::scene::IntegratorSettings, SceneError> {
    let (scene, _dir) = load(&[("scene.xml", &scene_with(xml))]);
    scene.map(|s| s.integrator)
}

#[test]
fn integrators_converging_to_path_are_accepted() {
    let depth = |xml: &str| integrator(xml).unwrap_or_else(|e| panic!("{xml}: {e}")).max_depth;
    assert_eq!(depth(r#"<integrator type="direct"><integer name="emitter_samples" value="4"/></integrator>"#), Some(2));
    assert_eq!(depth(r#"<integrator type="volpath"><integer name="max_depth" value="6"/></integrator>"#), Some(6));
    assert_eq!(
        depth(r#"<integrator type="volpathmis"><boolean name="use_spectral_mis" value="false"/></integrator>"#),
        None
    );
    assert_eq!(
        depth(
            r#"<integrator type="ptracer"><integer name="max_depth" value="4"/><integer name="samples_per_pass" value="1"/></integrator>"#
        ),
        Some(4)
    );
    assert_eq!(
        depth(
            r#"<integrator type="aov"><string name="aovs" value="dd.y:depth"/><integrator type="path"><integer name="max_depth" value="3"/></integrator><integrator type="direct"/></integrator>"#
        ),
        Some(3)
    );
    assert_eq!(depth(r#"<integrator type="moment"><integrator type="direct"/></integrator>"#), Some(2));
    let hidden = integrator(r#"<integrator type="direct"><boolean name="hide_emitters" value="true"/></integrator>"#);
    assert!(hidden.expect("loads").hide_emitters);
    let msg = integrator(r#"<integrator type="direct"><integer name="shading_samples" value="2"/><integer name="bsdf_samples" value="1"/></integrator>"#)
        .expect_err("shading_samples with bsdf_samples is refused")
        .to_string();
    assert!(msg.contains("shading_samples"), "{msg}");
    let msg = integrator(r#"<integrator type="direct"><integer name="max_depth" value="3"/></integrator>"#)
        .expect_err("direct has no max_depth")
        .to_string();
    assert!(msg.contains("unknown parameter \"max_depth\""), "{msg}");
}

const CORNELL_WHITE: &str = "400:0.343, 404:0.445, 408:0.551, 412:0.624, 416:0.665, 420:0.687, 424:0.708, \
    428:0.723, 432:0.715, 436:0.71, 440:0.745, 444:0.758, 448:0.739, 452:0.767, 456:0.777, 460:0.765, \
    464:0.751, 468:0.745, 472:0.748, 476:0.729, 480:0.745, 484:0.757, 488:0.753, 492:0.75, 496:0.746, \
    500:0.747, 504:0.735, 508:0.732, 512:0.739, 516:0.734, 520:0.725, 524:0.721, 528:0.733, 532:0.725, \
    536:0.732, 540:0.743, 544:0.744, 548:0.748, 552:0.728, 556:0.716, 560:0.733, 564:0.726, 568:0.713, \
    572:0.74, 576:0.754, 580:0.764, 584:0.752, 588:0.736, 592:0.734, 596:0.741, 600:0.74, 604:0.732, \
    608:0.745, 612:0.755, 616:0.751, 620:0.744, 624:0.731, 628:0.733, 632:0.744, 636:0.731, 640:0.712, \
    644:0.708, 648:0.729, 652:0.73, 656:0.727, 660:0.707, 664:0.703, 668:0.729, 672:0.75, 676:0.76, \
    680:0.751, 684:0.739, 688:0.724, 692:0.73, 696:0.74, 700:0.737";

/// The reflectance of a diffuse sphere and the radiance of an area light, both given by `xml`
/// (a colour property named `NAME`).
fn colors(xml: &str) -> (Rgb, Rgb) {
    let body = format!(
        r#"<shape type="sphere"><bsdf type="diffuse">{}</bsdf></shape>
        <shape type="rectangle"><emitter type="area">{}</emitter></shape>"#,
        xml.replace("NAME", "reflectance"),
        xml.replace("NAME", "radiance")
    );
    let (scene, _dir) = load(&[("scene.xml", &scene_with(&body))]);
    let scene = scene.unwrap_or_else(|e| panic!("{xml}: {e}"));
    let Bxdf::Diffuse(d) = &scene.materials[0].front else { panic!("diffuse expected") };
    let Light::Area { radiance, .. } = &scene.lights[0] else { panic!("area light expected") };
    (d.reflectance, *radiance)
}

fn assert_close(actual: Rgb, expected: [f32; 3], what: &str) {
    for k in 0..3 {
        let rel = (actual[k] - expected[k]).abs() / expected[k].abs().max(1e-6);
        assert!(rel < 1e-4, "{what}: {actual} vs {expected:?}");
    }
}

#[test]
fn spectra_convert_as_mitsuba_per_usage() {
    let (r, l) = colors(&format!(r#"<spectrum name="NAME" value="{CORNELL_WHITE}"/>"#));
    assert_close(r, [0.735013, 0.735625, 0.736264], "Cornell white reflectance");
    assert_close(l, [0.88531, 0.69901, 0.66603], "Cornell white radiance");
    let (r, l) = colors(r#"<spectrum name="NAME" value="0.5"/>"#);
    assert_close(r, [0.5, 0.5, 0.5], "single value reflectance");
    assert_close(l, [0.602397, 0.474146, 0.454458], "single value radiance");
    let (r, l) = colors(r#"<spectrum name="NAME" value="400:0.5, 700:0.5"/>"#);
    assert_close(r, [0.497671, 0.499878, 0.497455], "flat list reflectance");
    assert_close(l, [0.59985, 0.47476, 0.45172], "flat list radiance");
    let (r, _) = colors(r#"<spectrum name="NAME" value="400:2, 700:2"/>"#);
    assert_close(r, [1.0, 1.0, 1.0], "clipped reflectance");
    // <rgb> and <float> are used as given, for emitters too
    let (r, l) = colors(r#"<rgb name="NAME" value="0.25, 0.5, 0.75"/>"#);
    assert_eq!((r, l), (Rgb::new(0.25, 0.5, 0.75), Rgb::new(0.25, 0.5, 0.75)));
    let (r, _) = colors(r#"<float name="NAME" value="2"/>"#);
    assert_eq!(r, Rgb::splat(2.0), "a float reflectance is not range-checked");
}

#[test]
fn emitter_spectra_match_mitsuba() {
    let light = |xml: &str| {
        let body = format!(r#"<shape type="rectangle"><emitter type="area">{xml}</emitter></shape>"#);
        let (scene, _dir) =
            load(&[("scene.xml", &scene_with(&body)), ("light.spd", "400 0\n500 8\n600 15.6\n700 18.4\n")]);
        match scene.unwrap_or_else(|e| panic!("{xml}: {e}")).lights[0] {
            Light::Area { radiance, .. } => radiance,
            _ => panic!("area light expected"),
        }
    };
    assert_close(
        light(r#"<spectrum name="radiance" value="400:0, 500:8, 600:15.6, 700:18.4"/>"#),
        [20.7108, 10.8546, 2.77115],
        "Cornell light",
    );
    assert_close(
        light(r#"<spectrum name="radiance" filename="light.spd"/>"#),
        [20.7108, 10.8546, 2.77115],
        "Cornell light file",
    );
    assert_close(
        light(r#"<spectrum name="radiance" value="360:1, 830:1"/>"#),
        [1.20488, 0.948228, 0.909267],
        "full range",
    );
    assert_close(
        light(r#"<spectrum type="d65" name="radiance"><float name="scale" value="3"/></spectrum>"#),
        [3.0; 3],
        "d65",
    );
    assert_close(
        light(
            r#"<spectrum type="d65" name="radiance"><rgb name="color" value="1, 2, 3"/><float name="scale" value="2"/></spectrum>"#,
        ),
        [2.0, 4.0, 6.0],
        "d65 with colour",
    );
    assert_close(light(""), [1.0; 3], "Mitsuba's default radiance");
}

#[test]
fn split_scene_packs_unpacks_and_loads() {
    let xml = scene_with(
        r#"<path value="assets"/><include filename="parts/materials.xml"/>
        <shape type="obj"><string name="filename" value="tri.obj"/><ref id="white"/></shape>"#,
    );
    let materials = r#"<scene version="3.0.0"><include filename="more.xml"/>
        <bsdf type="diffuse" id="white"><spectrum name="reflectance" filename="white.spd"/></bsdf></scene>"#;
    let dir = folder(&[
        ("scene.xml", &xml),
        ("parts/materials.xml", materials),
        (
            "parts/more.xml",
            r#"<scene version="3.0.0"><shape type="obj"><string name="filename" value="quad.obj"/></shape></scene>"#,
        ),
        ("assets/tri.obj", TRIANGLE),
        ("assets/quad.obj", QUAD),
        ("assets/white.spd", "400 0.5\n700 0.5\n"),
        ("unused.obj", TRIANGLE),
    ]);
    let bundle = tessera_common::bundle::pack(&dir.path().join("scene.xml"), &HashMap::new()).expect("packs");
    let mut paths: Vec<&str> = bundle.files.iter().map(|(p, _)| p.as_str()).collect();
    paths.sort();
    assert_eq!(
        paths,
        ["assets/quad.obj", "assets/tri.obj", "assets/white.spd", "parts/materials.xml", "parts/more.xml", "scene.xml"]
    );
    let out = tempfile::tempdir().expect("tempdir");
    for (path, bytes) in &bundle.files {
        let target = out.path().join(tessera_common::bundle::safe_relative_path(path).expect("safe path"));
        std::fs::create_dir_all(target.parent().expect("parent")).expect("mkdir");
        std::fs::write(target, bytes).expect("write");
    }
    let scene = Scene::load(&out.path().join(&bundle.scene_path)).expect("the unpacked bundle loads");
    let mut counts = vertices(&scene);
    counts.sort();
    assert_eq!(counts, [3, 4]);
}

/// A file reached outside the scene's folder moves the bundle's root up to a folder holding
/// both, so the include's `../shared` still names it inside the bundle.
#[test]
fn pack_roots_the_bundle_above_a_reachable_file_outside_the_scene_folder() {
    let root = folder(&[
        ("scene/scene.xml", &scene_with(r#"<include filename="../shared/common.xml"/>"#)),
        ("shared/common.xml", r#"<scene version="3.0.0"/>"#),
    ]);
    let bundle = tessera_common::bundle::pack(&root.path().join("scene/scene.xml"), &HashMap::new()).unwrap();
    assert_eq!(bundle.scene_path, "scene/scene.xml");
    let paths: Vec<&str> = bundle.files.iter().map(|(p, _)| p.as_str()).collect();
    assert_eq!(paths, ["scene/scene.xml", "shared/common.xml"]);
}
