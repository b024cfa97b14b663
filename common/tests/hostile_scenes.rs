//! Scenes written to hurt whoever loads them: file names that leave a job's bundle, parameters
//! that expand geometrically, too many elements. Each is refused with an error naming the file
//! and line; none may hang, read outside the bundle or take unbounded memory.

use std::collections::HashMap;
use std::path::PathBuf;
use tessera_common::scene::{LoadOptions, Scene, SceneError, SceneLimits};

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
    assert_eq!(*err.location.file, *std::path::Path::new("scene.xml"), "{msg}");
    assert_eq!(err.location.line, line, "{msg}");
    assert!(msg.contains(needle), "{msg:?} should mention {needle:?}");
    assert!(!msg.contains(bundle.to_str().unwrap()), "{msg:?} names the server's folder");
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
    assert_eq!(*err.location.file, *std::path::Path::new("scene.xml"));
    assert!(!err.to_string().contains(bundle.to_str().unwrap()), "{err} names the server's folder");
}

/// Runs `f` on a thread with the stack a tokio worker or `spawn_blocking` thread has.
fn on_small_stack<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::Builder::new().stack_size(2 << 20).spawn(f).expect("thread").join().expect("no overflow")
}

/// A few hundred nested elements overflowed a 2 MiB stack (the parse, the later walks and the
/// tree's drop recurse); they are refused at the first element past the limit, and a scene
/// nested right up to it parses on such a stack.
#[test]
fn deep_nesting_is_refused_at_its_line() {
    let nested = |depth: usize| {
        let mut xml = String::from("<scene version=\"3.0.0\">\n");
        for _ in 1..depth {
            xml += "<bsdf type=\"twosided\">\n";
        }
        for _ in 1..depth {
            xml += "</bsdf>";
        }
        xml + "</scene>\n"
    };
    let err = on_small_stack(move || load_confined(&[("scene.xml", &nested(5000))]).0.err().expect("refused"));
    assert!(err.to_string().contains("nest more than 32 deep"), "{err}");
    assert_eq!((err.location.line, &*err.location.file), (33, std::path::Path::new("scene.xml")), "{err}");
    let tree = on_small_stack(move || {
        let xml = nested(tessera_common::scene::xml::MAX_NESTING);
        tessera_common::scene::xml::parse(&xml, std::path::Path::new("s.xml"), &HashMap::new())
            .map(|t| t.elements.len())
    });
    assert_eq!(tree, Ok(1));
}

/// References that put a deep element under another deep one are refused before any walk of
/// the expanded tree can overflow.
#[test]
fn references_cannot_nest_past_the_limit() {
    let mut xml = String::from("<scene version=\"3.0.0\">\n");
    // a chain of 30-deep elements, each referencing the previous one at its bottom
    for i in 0..8 {
        xml += &format!("<texture type=\"checkerboard\" id=\"t{i}\">");
        xml += &"<texture type=\"checkerboard\" name=\"color0\">".repeat(28);
        if i > 0 {
            xml += &format!("<ref id=\"t{}\" name=\"color0\"/>", i - 1);
        }
        xml += &"</texture>".repeat(29);
        xml += "\n";
    }
    xml += "</scene>\n";
    let err = on_small_stack(move || load_confined(&[("scene.xml", &xml)]).0.err().expect("refused"));
    assert!(err.to_string().contains("references nest elements more than"), "{err}");
}

/// A 1 MiB string referenced by a thousand shapes was a gigabyte of copies: references are
/// counted in bytes.
#[test]
fn reference_copies_are_counted_in_bytes() {
    let big = "x".repeat(1 << 20);
    let mut xml = format!("{HEAD}<bsdf type=\"diffuse\" id=\"b\"><string name=\"note\" value=\"{big}\"/></bsdf>\n");
    for _ in 0..1000 {
        xml += "<shape type=\"sphere\"><ref id=\"b\"/></shape>\n";
    }
    xml += "</scene>\n";
    let err = load_confined(&[("scene.xml", &xml)]).0.err().expect("refused");
    assert!(err.to_string().contains("references expand the scene past 64 MiB"), "{err}");
    // about the 60th copy is the first over the limit (the definition, kept and placed, counts too)
    assert!((3 + 55..=3 + 64).contains(&err.location.line), "{err}");
}

/// Every file name is looked for in every `<path>` folder; their number is bounded.
#[test]
fn search_paths_are_bounded() {
    let paths = "<path value=\".\"/>\n".repeat(4000);
    let xml = format!("{HEAD}{paths}</scene>\n");
    let err = load_confined(&[("scene.xml", &xml)]).0.err().expect("refused");
    assert!(err.to_string().contains("at most 64 <path> folders"), "{err}");
    assert_eq!(err.location.line, 3 + 64, "{err}");
}

/// Errors name the user's files, never the folder a job's bundle is kept in, whatever name
/// makes a path resolve to the folder itself.
#[test]
fn errors_never_show_the_bundle_folder() {
    for name in [".", "./", "..", "sub/..", "./.", "meshes", "meshes/", "meshes/.."] {
        let cases = [
            format!(
                "{HEAD}<bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\"><string name=\"filename\" value=\"{name}\"/></texture></bsdf>\n</scene>\n"
            ),
            format!("{HEAD}<shape type=\"ply\"><string name=\"filename\" value=\"{name}\"/></shape>\n</scene>\n"),
            format!("{HEAD}<include filename=\"{name}\"/>\n</scene>\n"),
            format!(
                "{HEAD}<emitter type=\"envmap\"><string name=\"filename\" value=\"{name}\"/></emitter>\n</scene>\n"
            ),
            format!(
                "{HEAD}<bsdf type=\"diffuse\"><spectrum name=\"reflectance\" filename=\"{name}\"/></bsdf>\n</scene>\n"
            ),
        ];
        for xml in cases {
            let (result, bundle, tmp) = load_confined(&[("scene.xml", &xml)]);
            let err = result.err().expect("refused").to_string();
            for hidden in [bundle.display().to_string(), tmp.path().display().to_string()] {
                assert!(!err.contains(&hidden), "{name}: {err}");
            }
        }
    }
}

/// Shapes share a mesh file's triangles in the budget as separate copies.
#[test]
fn triangles_are_counted_against_the_scene_limit() {
    let cube = "<shape type=\"ply\"><string name=\"filename\" value=\"cube.ply\"/></shape>\n";
    let xml = format!("{HEAD}{}</scene>\n", cube.repeat(3));
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n3 1 2 0\n3 0 1 2\n";
    let tmp = tempfile::tempdir().expect("tempdir");
    std::fs::write(tmp.path().join("scene.xml"), &xml).expect("write");
    std::fs::write(tmp.path().join("cube.ply"), ply).expect("write");
    let limits = SceneLimits { max_triangles: 10, ..SceneLimits::default() };
    let options = LoadOptions { limits, ..LoadOptions::default() };
    let err = Scene::load_options(&tmp.path().join("scene.xml"), &options).err().expect("refused");
    assert!(err.to_string().contains("more than 10 triangles"), "{err}");
    assert_eq!(err.location.line, 5, "the third shape: {err}");
    let options = LoadOptions { limits: SceneLimits { max_triangles: 12, ..limits }, ..LoadOptions::default() };
    let scene = Scene::load_options(&tmp.path().join("scene.xml"), &options).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(scene.triangle_count(), 12);
}

/// A header's claims are checked against the bytes behind them before anything is reserved.
#[test]
fn declared_sizes_are_bounded_by_the_file() {
    let ply = "ply\nformat binary_little_endian 1.0\nelement vertex 2000000000\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
    let xml = format!("{HEAD}<shape type=\"ply\"><string name=\"filename\" value=\"m.ply\"/></shape>\n</scene>\n");
    let err = load_confined(&[("scene.xml", &xml), ("m.ply", ply)]).0.err().expect("refused");
    assert!(err.to_string().contains("declares 2000000000 records"), "{err}");
    assert_eq!(&*err.location.file, std::path::Path::new("m.ply"), "{err}");
}
