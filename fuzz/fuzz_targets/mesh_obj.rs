//! Fuzzes the Wavefront OBJ mesh loader, `tessera_common::scene::load::obj::load_obj` (Tessera's
//! line checks, then tobj). The input is the file, written to a scratch folder on a tmpfs
//! because the loader takes a path.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_common::scene::load::obj::load_obj;

fuzz_target!(|data: &[u8]| {
    let path = tessera_fuzz::write("mesh.obj", data);
    let _ = load_obj(&path);
});
