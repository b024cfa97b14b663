//! Fuzzes the Mitsuba XML scene parser, `tessera_common::scene::xml::parse_confined`, as a farm
//! job's bundle is parsed: the input is `scene.xml` in a scratch folder holding one small file
//! of every kind a scene names (so `<include>`, `<path>` and spectrum files resolve), with
//! every file confined to that folder. No `$name` values are passed.
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::collections::HashMap;
use tessera_common::scene::xml;

fuzz_target!(|data: &[u8]| {
    // the scene loader reads files with read_to_string: text that is not UTF-8 is refused there
    let Ok(text) = std::str::from_utf8(data) else { return };
    let dir = tessera_fuzz::scene_folder();
    // an <include> of scene.xml reads the input again
    let path = tessera_fuzz::write("scene.xml", data);
    let _ = xml::parse_confined(text, &path, &HashMap::new(), Some(dir));
});
