//! Bad input gives an error that names the file and the line (and never panics).

use std::path::Path;
use tessera_common::scene::{Scene, SceneError};

const SENSOR: &str = r#"<sensor type="perspective"><float name="fov" value="40"/>
        <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/><rfilter type="box"/></film></sensor>"#;

/// Writes `files` into a temporary folder and loads `scene.xml` from it.
fn load(files: &[(&str, &str)]) -> (Result<Scene, SceneError>, tempfile::TempDir) {
    let dir = tempfile::tempdir().expect("tempdir");
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).expect("write");
    }
    (Scene::load(&dir.path().join("scene.xml")), dir)
}

fn expect_error(files: &[(&str, &str)], file: &str, line: u32, needle: &str) {
    let (result, dir) = load(files);
    let err = match result {
        Ok(_) => panic!("expected an error mentioning {needle:?}"),
        Err(e) => e,
    };
    let msg = err.to_string();
    assert_eq!(*err.location.file, dir.path().join(file), "{msg}");
    assert_eq!(err.location.line, line, "{msg}");
    assert!(msg.contains(needle), "{msg:?} should mention {needle:?}");
    assert!(msg.contains(&format!("{file}:{line}")), "message names file and line: {msg}");
}

#[test]
fn malformed_xml_names_the_line() {
    let xml = format!("<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\">\n</scene>\n");
    // the parser notices at </scene> (line 5) that <shape> (line 3) was never closed
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "malformed xml");
}

#[test]
fn unknown_plugin_names_the_line() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\">\n  <bsdf type=\"velvet\"/>\n</shape>\n</scene>\n"
    );
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "unsupported bsdf \"velvet\"");
}

#[test]
fn unknown_parameter_names_the_line() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\">\n  <float name=\"radiuss\" value=\"2\"/>\n</shape>\n</scene>\n"
    );
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "unknown parameter \"radiuss\"");
}

#[test]
fn missing_mesh_file_is_named() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"obj\">\n  <string name=\"filename\" value=\"nowhere.obj\"/>\n</shape>\n</scene>\n"
    );
    let (result, dir) = load(&[("scene.xml", &xml)]);
    let msg = result.err().expect("error").to_string();
    assert!(
        msg.contains(&dir.path().join("nowhere.obj").display().to_string()) && msg.contains("cannot read mesh"),
        "{msg}"
    );
}

#[test]
fn bad_number_names_the_line() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\">\n  <float name=\"radius\" value=\"1.5x\"/>\n</shape>\n</scene>\n"
    );
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "\"1.5x\" is not a number");
}

#[test]
fn nan_vertex_in_obj_names_the_mesh_line() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"obj\"><string name=\"filename\" value=\"bad.obj\"/></shape>\n</scene>\n"
    );
    let obj = "# a triangle\nv 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n";
    expect_error(&[("scene.xml", &xml), ("bad.obj", obj)], "bad.obj", 4, "non-finite");
}

#[test]
fn nan_vertex_in_ply_names_the_mesh_line() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"ply\"><string name=\"filename\" value=\"bad.ply\"/></shape>\n</scene>\n"
    );
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 nan 0\n3 0 1 2\n";
    expect_error(&[("scene.xml", &xml), ("bad.ply", ply)], "bad.ply", 12, "invalid ply");
    // binary files have no lines: the vertex is named instead
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, f32::NAN, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    bin.push(3);
    for i in [0i32, 1, 2] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::write(dir.path().join("scene.xml"), &xml).expect("write");
    std::fs::write(dir.path().join("bad.ply"), &bin).expect("write");
    let msg = Scene::load(&dir.path().join("scene.xml")).err().expect("error").to_string();
    assert!(msg.contains("bad.ply") && msg.contains("vertex 2 has a non-finite \"y\""), "{msg}");
}

#[test]
fn face_index_out_of_range_names_the_line() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"obj\"><string name=\"filename\" value=\"bad.obj\"/></shape>\n</scene>\n"
    );
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n";
    expect_error(&[("scene.xml", &xml), ("bad.obj", obj)], "bad.obj", 4, "out of range");
}

#[test]
fn undefined_reference_and_parameter_name_the_line() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\">\n  <ref id=\"gold\"/>\n</shape>\n</scene>\n"
    );
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "unknown id \"gold\"");
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\">\n  <float name=\"radius\" value=\"$r\"/>\n</shape>\n</scene>\n"
    );
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "undefined parameter \"$r\"");
}

#[test]
fn defaults_and_substitution_work() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n<default name=\"r\" value=\"2.5\"/>\n{SENSOR}\n<shape type=\"sphere\"><float name=\"radius\" value=\"$r\"/></shape>\n</scene>\n"
    );
    let (scene, _dir) = load(&[("scene.xml", &xml)]);
    let scene = scene.expect("loads");
    match &scene.shapes[0].geometry {
        tessera_common::scene::shape::ShapeGeometry::Sphere { radius, .. } => assert_eq!(*radius, 2.5),
        _ => panic!("sphere expected"),
    }
}

#[test]
fn every_repository_scene_loads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for entry in std::fs::read_dir(&root).expect("scenes folder") {
        let path = entry.expect("entry").path().join("scene.xml");
        if path.exists() {
            Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        }
    }
}

/// Like [`expect_error`], also checking the column.
fn expect_error_at(files: &[(&str, &str)], file: &str, line: u32, column: u32, needle: &str) {
    let (result, dir) = load(files);
    let err = result.err().unwrap_or_else(|| panic!("expected an error mentioning {needle:?}"));
    let msg = err.to_string();
    assert_eq!(
        (err.location.file.to_path_buf(), err.location.line, err.location.column),
        (dir.path().join(file), line, column),
        "{msg}"
    );
    assert!(msg.contains(needle), "{msg:?} should mention {needle:?}");
}

#[test]
fn refused_plugins_name_file_line_and_column() {
    for (element, needle) in [
        (r#"<shape type="cylinder"/>"#, r#"shape "cylinder" is not supported"#),
        (r#"<medium type="homogeneous"/>"#, r#"medium "homogeneous" is not supported"#),
        (r#"<shape type="sphere"><bsdf type="pplastic"/></shape>"#, r#"bsdf "pplastic" is not supported"#),
        (
            r#"<integrator type="stokes"><integrator type="path"/></integrator>"#,
            r#"integrator "stokes" is not supported"#,
        ),
        (r#"<sensor type="thinlens"/>"#, r#"sensor "thinlens" is not supported"#),
        // nested, where a supported texture would go
        (
            r#"<shape type="sphere"><bsdf type="diffuse"><texture type="volume" name="reflectance"/></bsdf></shape>"#,
            r#"texture "volume" is not supported"#,
        ),
    ] {
        // the refused element starts on line 5, two spaces in (a nested one further right)
        let xml = format!("<scene version=\"3.0.0\">\n{SENSOR}\n<!-- refused -->\n  {element}\n</scene>\n");
        let tag = &needle[..needle.find(' ').expect("tag")];
        let column = 3 + element.find(&format!("<{tag} ")).expect("refused element") as u32;
        expect_error_at(&[("scene.xml", &xml)], "scene.xml", 5, column, needle);
    }
}

#[test]
fn refused_plugin_in_an_included_file_names_that_file() {
    let xml = format!("<scene version=\"3.0.0\">\n{SENSOR}\n<include filename=\"inc.xml\"/>\n</scene>\n");
    let inc = "<scene version=\"3.0.0\">\n\n <shape type=\"instance\"/>\n</scene>\n";
    expect_error_at(&[("scene.xml", &xml), ("inc.xml", inc)], "inc.xml", 3, 2, r#"shape "instance" is not supported"#);
}

#[test]
fn camel_case_name_in_a_3_0_scene_is_an_unknown_parameter() {
    let xml = format!(
        "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\">\n  <transform name=\"toWorld\"/>\n</shape>\n</scene>\n"
    );
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "unknown parameter \"toWorld\"");
}

#[test]
fn colour_errors_follow_mitsuba() {
    let bsdf = |colour: &str| {
        format!(
            "<scene version=\"3.0.0\">\n{SENSOR}\n<shape type=\"sphere\"><bsdf type=\"diffuse\">\n  {colour}\n</bsdf></shape>\n</scene>\n"
        )
    };
    expect_error(
        &[("scene.xml", &bsdf(r#"<rgb name="reflectance" value="1.2, 0.5, 0.5"/>"#))],
        "scene.xml",
        5,
        "must lie in [0, 1]",
    );
    expect_error(
        &[(
            "scene.xml",
            &bsdf(
                r#"<spectrum type="blackbody" name="reflectance"><float name="temperature" value="3000"/></spectrum>"#,
            ),
        )],
        "scene.xml",
        5,
        "blackbody is not available in RGB rendering",
    );
    expect_error(
        &[("scene.xml", &bsdf(r#"<spectrum name="reflectance" value="500:1, 400:1"/>"#))],
        "scene.xml",
        5,
        "increase strictly",
    );
    expect_error(
        &[("scene.xml", &bsdf(r#"<spectrum name="reflectance" filename="none.spd"/>"#))],
        "scene.xml",
        5,
        "\"none.spd\" not found",
    );
    expect_error(
        &[("scene.xml", &bsdf(r#"<spectrum type="d65" name="albedo"/>"#))],
        "scene.xml",
        5,
        "unknown parameter \"albedo\"",
    );
}

#[test]
fn missing_include_names_the_including_line() {
    let xml = format!("<scene version=\"3.0.0\">\n{SENSOR}\n\n<include filename=\"parts/none.xml\"/>\n</scene>\n");
    expect_error(&[("scene.xml", &xml)], "scene.xml", 5, "included file \"parts/none.xml\" not found");
}

#[test]
fn unused_caller_parameter_is_an_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("scene.xml");
    std::fs::write(&path, format!("<scene version=\"3.0.0\">\n{SENSOR}\n</scene>\n")).expect("write");
    let defines = [("spp".to_string(), "16".to_string())].into();
    let msg = Scene::load_with(&path, &defines).err().expect("error").to_string();
    assert!(msg.contains("\"spp\"") && msg.contains("not used"), "{msg}");
}

/// A top-level area emitter lights the shape that references it; a second shape referencing
/// it is refused at its `<ref>`, as Mitsuba refuses it; one no shape references is left out.
#[test]
fn an_area_emitter_referenced_by_two_shapes_is_refused_at_the_second() {
    let light = r#"<emitter type="area" id="lamp"><rgb name="radiance" value="1, 1, 1"/></emitter>"#;
    let sphere =
        |y: f32| format!(r#"<shape type="sphere"><point name="center" value="0, {y}, -3"/><ref id="lamp"/></shape>"#);
    let one = format!("<scene version=\"3.0.0\">\n{SENSOR}\n{light}\n{}\n</scene>\n", sphere(0.0));
    let (scene, _dir) = load(&[("scene.xml", &one)]);
    assert_eq!(scene.expect("one shape references it").lights.len(), 1);
    let two = format!("<scene version=\"3.0.0\">\n{SENSOR}\n{light}\n{}\n{}\n</scene>\n", sphere(0.0), sphere(1.0));
    expect_error(&[("scene.xml", &two)], "scene.xml", 6, "already lights the shape at");
    let none = format!("<scene version=\"3.0.0\">\n{SENSOR}\n{light}\n<shape type=\"sphere\"/>\n</scene>\n");
    let (scene, _dir) = load(&[("scene.xml", &none)]);
    assert!(scene.expect("an unreferenced emitter is left out").lights.is_empty());
}
