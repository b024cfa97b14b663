//! Parser tests: includes, `<path>`, ids, refs and aliases, `$name` substitution, versions.

use super::*;
use std::path::Path;

/// Writes `files` (relative path, text) under a temporary folder.
fn folder(files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        let path = dir.path().join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    dir
}

fn parse_in(dir: &Path, defines: &[(&str, &str)]) -> Result<SceneTree, SceneError> {
    let file = dir.join("scene.xml");
    let text = std::fs::read_to_string(&file).unwrap();
    let defines = defines.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
    parse(&text, &file, &defines)
}

fn parse_str(xml: &str) -> Result<SceneTree, SceneError> {
    parse(xml, Path::new("mem/scene.xml"), &HashMap::new())
}

fn err(r: Result<SceneTree, SceneError>) -> SceneError {
    r.expect_err("expected an error")
}

const V3: &str = r#"version="3.0.0""#;

#[test]
fn include_splices_scene_children_and_resolves_nested_includes_per_file() {
    let dir = folder(&[
        (
            "scene.xml",
            &format!(
                r#"<scene {V3}><include filename="sub/a.xml"/><shape type="sphere"><ref id="m"/></shape></scene>"#
            ),
        ),
        // b.xml is found next to a.xml, the including file
        ("sub/a.xml", &format!(r#"<scene {V3}><include filename="b.xml"/><emitter type="point" id="lamp"/></scene>"#)),
        ("sub/b.xml", &format!(r#"<scene {V3}><bsdf type="diffuse" id="m"/></scene>"#)),
    ]);
    let tree = parse_in(dir.path(), &[]).unwrap();
    let tags: Vec<&str> = tree.elements.iter().map(|e| e.tag.as_str()).collect();
    assert_eq!(tags, ["bsdf", "emitter", "shape"]);
    assert_eq!(*tree.elements[0].location.file, dir.path().join("sub/b.xml"));
    assert_eq!(tree.elements[2].children[0].id.as_deref(), Some("m"));
    assert_eq!(tree.files, [dir.path().join("sub/a.xml"), dir.path().join("sub/b.xml")]);
}

#[test]
fn include_of_an_object_root_becomes_a_named_child() {
    let dir = folder(&[
        (
            "scene.xml",
            &format!(r#"<scene {V3}><shape type="sphere"><include filename="mat.xml" name="inner"/></shape></scene>"#),
        ),
        (
            "mat.xml",
            &format!(r#"<bsdf type="diffuse" {V3} name="ignored"><float name="reflectance" value="0.3"/></bsdf>"#),
        ),
    ]);
    let tree = parse_in(dir.path(), &[]).unwrap();
    let child = &tree.elements[0].children[0];
    assert_eq!((child.tag.as_str(), child.name.as_deref()), ("bsdf", Some("inner")));
}

#[test]
fn include_missing_file_names_the_including_line() {
    let dir = folder(&[("scene.xml", &format!("<scene {V3}>\n\n  <include filename=\"nowhere.xml\"/>\n</scene>"))]);
    let e = err(parse_in(dir.path(), &[]));
    assert_eq!(
        (e.location.file.to_path_buf(), e.location.line, e.location.column),
        (dir.path().join("scene.xml"), 3, 3)
    );
    assert!(e.message.contains("\"nowhere.xml\" not found"), "{e}");
}

#[test]
fn include_errors_name_the_included_file() {
    let dir = folder(&[
        ("scene.xml", &format!("<scene {V3}>\n<include filename=\"inc.xml\"/>\n</scene>")),
        (
            "inc.xml",
            &format!("<scene {V3}>\n\n<shape type=\"sphere\"><float name=\"radius\" value=\"x\"/></shape>\n</scene>"),
        ),
    ]);
    let e = err(parse_in(dir.path(), &[]));
    assert_eq!((e.location.file.to_path_buf(), e.location.line), (dir.path().join("inc.xml"), 3), "{e}");
}

#[test]
fn include_depth_is_limited_to_fifteen() {
    let chain = |n: usize| -> Vec<(String, String)> {
        (0..n)
            .map(|i| {
                let name = if i == 0 { "scene.xml".to_string() } else { format!("f{i}.xml") };
                let body = if i + 1 < n { format!(r#"<include filename="f{}.xml"/>"#, i + 1) } else { String::new() };
                (name, format!("<scene {V3}>{body}</scene>"))
            })
            .collect()
    };
    let write =
        |files: &[(String, String)]| folder(&files.iter().map(|(a, b)| (a.as_str(), b.as_str())).collect::<Vec<_>>());
    // depths 0..=14 load
    let ok = write(&chain(MAX_INCLUDE_DEPTH));
    parse_in(ok.path(), &[]).unwrap();
    let deep = write(&chain(MAX_INCLUDE_DEPTH + 1));
    let e = err(parse_in(deep.path(), &[]));
    assert!(e.message.contains("maximum include depth of 15"), "{e}");
    assert_eq!(*e.location.file, deep.path().join("f14.xml"));
    let selfish = folder(&[("scene.xml", &format!(r#"<scene {V3}><include filename="scene.xml"/></scene>"#))]);
    assert!(err(parse_in(selfish.path(), &[])).message.contains("maximum include depth"));
}

#[test]
fn ids_are_unique_across_files() {
    let dir = folder(&[
        (
            "scene.xml",
            &format!("<scene {V3}>\n<bsdf type=\"diffuse\" id=\"m\"/>\n<include filename=\"inc.xml\"/></scene>"),
        ),
        ("inc.xml", &format!("<scene {V3}>\n\n<bsdf type=\"diffuse\" id=\"m\"/></scene>")),
    ]);
    let e = err(parse_in(dir.path(), &[]));
    assert_eq!((e.location.file.to_path_buf(), e.location.line), (dir.path().join("inc.xml"), 3));
    assert!(e.message.contains("duplicate id \"m\""), "{e}");
}

#[test]
fn path_prepends_folders_in_document_order() {
    let dir = folder(&[
        ("scene.xml", &format!(r#"<scene {V3}><path value="a"/><path value="b"/></scene>"#)),
        ("a/.keep", ""),
        ("b/.keep", ""),
    ]);
    let tree = parse_in(dir.path(), &[]).unwrap();
    assert_eq!(tree.resolver.dirs(), [dir.path().join("b"), dir.path().join("a"), dir.path().to_path_buf()]);
    let missing = folder(&[("scene.xml", &format!(r#"<scene {V3}><path value="nope"/></scene>"#))]);
    assert!(err(parse_in(missing.path(), &[])).message.contains("folder \"nope\" not found"));
    let nested =
        folder(&[("scene.xml", &format!(r#"<scene {V3}><shape type="sphere"><path value="."/></shape></scene>"#))]);
    assert!(err(parse_in(nested.path(), &[])).message.contains("direct child of the root"));
}

#[test]
fn path_inside_an_included_file_is_dropped_after_the_include() {
    let dir = folder(&[
        ("scene.xml", &format!(r#"<scene {V3}><include filename="sub/inc.xml"/></scene>"#)),
        ("sub/inc.xml", &format!(r#"<scene {V3}><path value="meshes"/></scene>"#)),
        ("sub/meshes/.keep", ""),
    ]);
    let tree = parse_in(dir.path(), &[]).unwrap();
    assert_eq!(tree.resolver.dirs(), [dir.path().to_path_buf()]);
}

#[test]
fn refs_resolve_forward_nested_and_through_aliases() {
    let tree = parse_str(&format!(
        r#"<scene {V3}>
            <shape type="sphere" id="s"><ref id="outer"/></shape>
            <bsdf type="twosided" id="outer"><ref id="inner" name="front"/></bsdf>
            <bsdf type="diffuse" id="inner"/>
            <alias id="inner" as="copy"/>
            <shape type="sphere"><ref id="copy"/></shape>
        </scene>"#
    ))
    .unwrap();
    let outer = &tree.elements[0].children[0];
    assert_eq!(outer.id.as_deref(), Some("outer"));
    assert_eq!(outer.children[0].id.as_deref(), Some("inner"));
    assert_eq!(outer.children[0].name.as_deref(), Some("front"));
    assert!(outer.reference.is_some());
    assert_eq!(tree.elements[3].children[0].id.as_deref(), Some("inner"));
    assert_eq!(tree.by_id("inner").map(|e| e.plugin.as_str()), Some("diffuse"));
}

#[test]
fn refs_unknown_and_cyclic_are_errors() {
    let e = err(parse_str(&format!("<scene {V3}>\n<shape type=\"sphere\">\n<ref id=\"gold\"/></shape></scene>")));
    assert_eq!(e.location.line, 3);
    assert!(e.message.contains("unknown id \"gold\""), "{e}");
    let e = err(parse_str(&format!(
        r#"<scene {V3}><bsdf type="twosided" id="a"><ref id="b"/></bsdf><bsdf type="twosided" id="b"><ref id="a"/></bsdf></scene>"#
    )));
    assert!(e.message.contains("circular reference: a -> b -> a"), "{e}");
    let e = err(parse_str(&format!(
        r#"<scene {V3}><bsdf type="twosided" id="a"><bsdf type="twosided"><ref id="a"/></bsdf></bsdf></scene>"#
    )));
    assert!(e.message.contains("circular reference: a -> a"), "{e}");
}

#[test]
fn alias_needs_an_earlier_source_and_a_new_name() {
    let e = err(parse_str(&format!(r#"<scene {V3}><alias id="m" as="n"/><bsdf type="diffuse" id="m"/></scene>"#)));
    assert!(e.message.contains("not defined before this <alias>"), "{e}");
    let e = err(parse_str(&format!(
        r#"<scene {V3}><bsdf type="diffuse" id="m"/><bsdf type="diffuse" id="n"/><alias id="m" as="n"/></scene>"#
    )));
    assert!(e.message.contains("alias \"n\" is already an id"), "{e}");
    let e = err(parse_str(&format!(
        r#"<scene {V3}><bsdf type="diffuse" id="m"/><alias id="m" as="n"/><bsdf type="diffuse" id="n"/></scene>"#
    )));
    assert!(e.message.contains("duplicate id \"n\""), "{e}");
}

fn string_value(tree: &SceneTree, index: usize) -> String {
    tree.elements[index].string("s").unwrap().unwrap().to_string()
}

#[test]
fn substitution_follows_document_order_and_caller_values() {
    let xml = |body: &str| format!(r#"<scene {V3}>{body}</scene>"#);
    // a default applies from its position on, not to the element it sits in
    let e = err(parse_str(&xml(r#"<shape type="$t"><default name="t" value="sphere"/></shape>"#)));
    assert!(e.message.contains("undefined parameter \"$t\""), "{e}");
    let e = err(parse_str(&xml(r#"<shape type="$t"/><default name="t" value="sphere"/>"#)));
    assert!(e.message.contains("undefined parameter \"$t\""), "{e}");
    // first default wins, textual and longest first, escapes kept
    let tree =
        parse_str(&xml(r#"<default name="a" value="Q"/><default name="a" value="Z"/><default name="ab" value="R"/>
           <shape type="sphere"><string name="s" value="x$ay $ab \$a"/></shape>"#))
        .unwrap();
    assert_eq!(string_value(&tree, 0), "xQy R $a");
    // the caller wins over defaults; an unused caller value is an error
    let dir = folder(&[(
        "scene.xml",
        &xml(r#"<default name="a" value="Q"/><shape type="sphere"><string name="s" value="$a"/></shape>"#),
    )]);
    assert_eq!(string_value(&parse_in(dir.path(), &[("a", "caller")]).unwrap(), 0), "caller");
    let e = err(parse_in(dir.path(), &[("a", "1"), ("spare", "2")]));
    assert!(e.message.contains("\"spare\"") && e.message.contains("not used"), "{e}");
}

#[test]
fn defaults_of_an_included_file_persist_after_it() {
    let dir = folder(&[
        (
            "scene.xml",
            &format!(
                r#"<scene {V3}><include filename="defs.xml"/><shape type="sphere"><string name="s" value="$x"/></shape></scene>"#
            ),
        ),
        ("defs.xml", &format!(r#"<scene {V3}><default name="x" value="from-include"/></scene>"#)),
    ]);
    assert_eq!(string_value(&parse_in(dir.path(), &[]).unwrap(), 0), "from-include");
}

#[test]
fn old_files_are_upgraded_on_their_own_version() {
    let dir = folder(&[
        (
            "scene.xml",
            &format!(
                r#"<scene {V3}><include filename="old.xml"/><shape type="sphere"><float name="maxDepth" value="1"/></shape></scene>"#
            ),
        ),
        (
            "old.xml",
            r#"<scene version="0.6.0"><bsdf type="diffuse"><rgb name="diffuseReflectance" value="0.5"/><float name="uscale" value="2"/></bsdf>
            <shape type="sphere"><transform name="toWorld"/></shape></scene>"#,
        ),
    ]);
    let tree = parse_in(dir.path(), &[]).unwrap();
    let names = |e: &Element| e.properties.iter().map(|p| p.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(&tree.elements[0]), ["reflectance", "to_uv"]);
    assert_eq!(names(&tree.elements[1]), ["to_world"]);
    // the main file is 3.0.0: its camelCase name stays as written
    assert_eq!(names(&tree.elements[2]), ["maxDepth"]);
}

#[test]
fn version_must_have_three_numbers() {
    assert!(err(parse_str(r#"<scene version="3.0"/>"#)).message.contains("invalid version number"));
    assert!(err(parse_str(r#"<scene/>"#)).message.contains("needs a version attribute"));
    parse_str(r#"<scene version="4.1.0"/>"#).unwrap();
}

#[test]
fn spectrum_stays_unconverted_and_files_are_recorded() {
    let dir = folder(&[
        (
            "scene.xml",
            &format!(
                r#"<scene {V3}><bsdf type="diffuse"><spectrum name="reflectance" filename="data/white.spd"/></bsdf></scene>"#
            ),
        ),
        ("data/white.spd", "# flat\n400 0.5\n700 0.5\n"),
    ]);
    let tree = parse_in(dir.path(), &[]).unwrap();
    assert!(matches!(
        &tree.elements[0].properties[0].value,
        Value::Spectrum(crate::spectrum::Spectrum::Sampled { .. })
    ));
    assert_eq!(tree.files, [dir.path().join("data/white.spd")]);
}

#[test]
fn unexpected_attributes_and_misplaced_tags_are_errors() {
    let e = err(parse_str(&format!(r#"<scene {V3}><shape type="sphere" colour="red"/></scene>"#)));
    assert!(e.message.contains("unexpected attribute \"colour\""), "{e}");
    let e = err(parse_str(&format!(r#"<scene {V3}><shape type="sphere"><translate x="1"/></shape></scene>"#)));
    assert!(e.message.contains("only appear inside a <transform>"), "{e}");
    let e = err(parse_str(&format!(
        r#"<scene {V3}><shape type="sphere"><lookAt origin="0,0,0" target="0,0,1"/></shape></scene>"#
    )));
    assert!(e.message.contains("unknown element <lookAt>"), "{e}");
}
