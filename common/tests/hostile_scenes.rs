//! Scenes written to hurt whoever loads them: file names that leave a job's bundle, parameters
//! that expand geometrically, too many elements. Each is refused with an error naming the file
//! and line; none may hang, read outside the bundle or take unbounded memory.

use std::collections::HashMap;
use std::path::PathBuf;
use tessera_common::scene::{LoadOptions, Scene, SceneError};

const HEAD: &str = r#"<scene version="3.0.0">
<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
"#;

/// A bundle folder holding `files` (and a regular file outside it), its scene loaded confined
/// to the bundle.
fn load_confined(files: &[(&str, &str)]) -> (Result<Scene, SceneError>, PathBuf, tempfile::TempDir) {
    let tmp = tempfile::tempdir().expect("tempdir");
    let bundle = tmp.path().join("bundle");
    std::fs::create_dir_all(bundle.join("meshes")).expect("mkdir");
    std::fs::write(tmp.path().join("outside.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").expect("write");
    for (name, text) in files {
        std::fs::write(bundle.join(name), text).expect("write");
    }
    let options = LoadOptions { defines: HashMap::new(), confine_to: Some(bundle.clone()), ..LoadOptions::default() };
    (Scene::load_options(&bundle.join("scene.xml"), &options), bundle, tmp)
}

fn refused(files: &[(&str, &str)], line: u32, needle: &str) {
    let (result, bundle, _tmp) = load_confined(files);
    let err = match result {
        Ok(_) => panic!("a hostile scene loaded (expected {needle:?})"),
        Err(e) => e,
    };
    let msg = err.to_string();
    assert_eq!(err.location.file, bundle.join("scene.xml"), "{msg}");
    assert_eq!(err.location.line, line, "{msg}");
    assert!(msg.contains(needle), "{msg:?} should mention {needle:?}");
}

#[test]
fn files_outside_the_bundle_are_refused() {
    let shape = |file: &str| {
        format!("{HEAD}<shape type=\"obj\"><string name=\"filename\" value=\"{file}\"/></shape>\n</scene>\n")
    };
    refused(&[("scene.xml", &shape("/dev/zero"))], 3, "absolute path");
    refused(&[("scene.xml", &shape("../outside.obj"))], 3, "outside the job's bundle");
    refused(&[("scene.xml", &shape("meshes/../../outside.obj"))], 3, "outside the job's bundle");
    let envmap =
        format!("{HEAD}<emitter type=\"envmap\"><string name=\"filename\" value=\"/dev/zero\"/></emitter>\n</scene>\n");
    refused(&[("scene.xml", &envmap)], 3, "absolute path");
    let texture = format!(
        "{HEAD}<bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"../x.png\"/></texture></bsdf>\n</scene>\n"
    );
    refused(&[("scene.xml", &texture)], 3, "outside the job's bundle");
    let include = format!("{HEAD}<include filename=\"/etc/passwd\"/>\n</scene>\n");
    refused(&[("scene.xml", &include)], 3, "absolute path");
    let path = format!("{HEAD}<path value=\"/\"/>\n</scene>\n");
    refused(&[("scene.xml", &path)], 3, "outside the job's bundle");
    let path_up = format!("{HEAD}<path value=\"..\"/>\n</scene>\n");
    refused(&[("scene.xml", &path_up)], 3, "outside the job's bundle");
    let spectrum = format!(
        "{HEAD}<bsdf type=\"diffuse\"><spectrum name=\"reflectance\" filename=\"/dev/zero\"/></bsdf>\n</scene>\n"
    );
    refused(&[("scene.xml", &spectrum)], 3, "absolute path");
}

#[test]
fn symbolic_links_in_the_bundle_are_refused() {
    let xml =
        format!("{HEAD}<shape type=\"obj\"><string name=\"filename\" value=\"meshes/link.obj\"/></shape>\n</scene>\n");
    let tmp = tempfile::tempdir().expect("tempdir");
    let bundle = tmp.path().join("bundle");
    std::fs::create_dir_all(bundle.join("meshes")).expect("mkdir");
    std::fs::write(bundle.join("scene.xml"), xml).expect("write");
    std::os::unix::fs::symlink("/dev/zero", bundle.join("meshes/link.obj")).expect("symlink");
    let options = LoadOptions { confine_to: Some(bundle.clone()), ..LoadOptions::default() };
    let err = Scene::load_options(&bundle.join("scene.xml"), &options).err().expect("refused");
    assert!(err.to_string().contains("symbolic link"), "{err}");
    assert_eq!(err.location.line, 3, "{err}");
}

/// The same names load from a scene on the user's own disk (`tessera render`), which may name
/// any file.
#[test]
fn a_local_scene_may_name_files_anywhere() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let dir = tmp.path().join("scene");
    std::fs::create_dir_all(&dir).expect("mkdir");
    std::fs::write(tmp.path().join("outside.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").expect("write");
    let xml =
        format!("{HEAD}<shape type=\"obj\"><string name=\"filename\" value=\"../outside.obj\"/></shape>\n</scene>\n");
    std::fs::write(dir.join("scene.xml"), xml).expect("write");
    let scene = Scene::load(&dir.join("scene.xml")).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.triangle_count(), 1);
}

/// Ten `<default>`s, each repeating the previous one ten times, would expand to 10¹⁰ bytes.
#[test]
fn geometric_parameter_expansion_is_refused() {
    let mut xml = String::from("<scene version=\"3.0.0\">\n<default name=\"p0\" value=\"xxxxxxxxxx\"/>\n");
    for i in 1..10 {
        xml += &format!("<default name=\"p{i}\" value=\"{}\"/>\n", format!("$p{}", i - 1).repeat(10));
    }
    xml += "<sensor type=\"perspective\"><string name=\"label\" value=\"$p9\"/></sensor>\n</scene>\n";
    let (result, _, _tmp) = load_confined(&[("scene.xml", &xml)]);
    let err = result.err().expect("refused");
    assert!(err.to_string().contains("grows past"), "{err}");
    // level 6 (10⁷ bytes) is the first over the 1 MiB cap: line 2 + 6
    assert_eq!(err.location.line, 8, "{err}");
}

#[test]
fn too_many_xml_nodes_are_refused() {
    let xml = format!("<scene version=\"3.0.0\">{}</scene>", "<a/>".repeat(1_000_001));
    let (result, bundle, _tmp) = load_confined(&[("scene.xml", &xml)]);
    let err = result.err().expect("refused");
    assert!(err.to_string().contains("XML nodes"), "{err}");
    assert_eq!(err.location.file, bundle.join("scene.xml"));
}
