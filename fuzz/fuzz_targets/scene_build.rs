//! Fuzzes scene loading end to end, `tessera_common::scene::Scene::load_options` with
//! `LoadOptions { confine_to: Some(dir), .. }`: the XML parser, then the builder (plugins,
//! transforms, meshes, textures, emitters, the BVH), as the coordinator and workers load a farm
//! job's bundle. The input is `scene.xml` in a scratch folder that also holds one small file of
//! every kind a scene may name (mesh.ply, mesh-binary.ply, mesh.obj, mesh.serialized, tex.png,
//! tex16.png, tex.jpg, tex.exr, tex.hdr, tex.bmp, tex.tga, tex.pfm, tex.ppm, spec.spd,
//! part.xml); textures get a 16 MiB budget and shapes 10⁵ triangles (the defaults are far larger
//! than libFuzzer's 1 GiB allows). After a NUL byte the input holds up to three more
//! XML files, `inc1.xml` to `inc3.xml` (`tessera_fuzz::write_scene`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use tessera_common::scene::{LoadOptions, Scene, SceneLimits};

fuzz_target!(|data: &[u8]| {
    let dir = tessera_fuzz::scene_folder();
    let path = tessera_fuzz::write_scene(data);
    let options = LoadOptions {
        limits: SceneLimits { textures: tessera_fuzz::texture_limits(), max_triangles: 100_000 },
        confine_to: Some(dir.to_path_buf()),
        ..LoadOptions::default()
    };
    // the image decoders turn their own panics into errors, as on a worker
    tessera_fuzz::tolerate_caught_panics(data, || {
        let _ = Scene::load_options(&path, &options);
    });
});
