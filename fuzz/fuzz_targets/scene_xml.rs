//! Fuzzes the Mitsuba XML scene parser, `tessera_common::scene::xml::parse_confined`, as a farm
//! job's bundle is parsed: the input is `scene.xml` in a scratch folder holding one small file
//! of every kind a scene names (so `<include>`, `<path>` and spectrum files resolve), with
//! every file confined to that folder. No `$name` values are passed.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::collections::HashMap;
use tessera_common::scene::xml;

fuzz_target!(|data: &[u8]| {
    let dir = tessera_fuzz::scene_folder();
    // written first: an <include> of scene.xml reads it again
    let path = tessera_fuzz::write_scene(data);
    let scene = data.split(|&b| b == 0).next().unwrap_or_default();
    // the scene loader reads files with read_to_string: text that is not UTF-8 is refused there
    let Ok(text) = std::str::from_utf8(scene) else { return };
    let _ = xml::parse_confined(text, &path, &HashMap::new(), Some(dir));
});
