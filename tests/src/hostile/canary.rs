//! The canary: a coordinator and a worker take the cheap hostile requests one after another,
//! then render a real job, which must equal `tessera render` bit for bit.

use super::inputs;
use super::procs::{Bins, peak, settle};
use super::{Case, Report, timed};
use crate::rest;
use serde_json::json;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

pub(super) fn all() -> Vec<Case> {
    vec![Case { name: "canary", class: "afterwards", run: canary }]
}

/// The hostile submissions the canary's coordinator takes first: (scene, assets, settings).
fn hostile_submissions() -> Vec<(Vec<u8>, Vec<(String, Vec<u8>)>, serde_json::Value)> {
    let pt = json!({"integrator": "pt", "spp": 1});
    vec![
        (inputs::nested(600), vec![], pt.clone()),
        (inputs::scene(""), vec![], json!({"integrator": "lt", "spp": 1, "light_paths_per_pixel": 1e6})),
        (inputs::many_paths(4000), vec![], pt.clone()),
        (inputs::many_elements(50_000), vec![], pt.clone()),
        (inputs::scene(&inputs::textured(".")), vec![], pt.clone()),
        (
            inputs::scene(&inputs::textured("big.png")),
            vec![("big.png".into(), inputs::png_claiming(16384))],
            pt.clone(),
        ),
        (
            inputs::scene(&inputs::mesh_shape("serialized", "m.serialized")),
            vec![("m.serialized".into(), inputs::serialized_bomb(4_000_000))],
            pt,
        ),
    ]
}

fn canary(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let mut w = bins.worker(&c, dir);
    let refused = hostile_submissions()
        .into_iter()
        .filter(|(scene, assets, settings)| {
            rest::try_submit(&c.url, ("scene.xml", scene.clone()), assets.clone(), settings.clone()).0 == 400
        })
        .count();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/cornell-box/scene.xml");
    let farm = dir.join("farm.exr");
    let local = dir.join("local.exr");
    let run = |args: &[&str]| Command::new(&bins.tessera).args(args).output().is_ok_and(|o| o.status.success());
    let (rendered, seconds) = timed(|| {
        let s = scene.to_str().expect("utf-8");
        let common = ["--integrator", "pt", "--spp", "3", "--seed", "5"];
        let submitted =
            run(&[&["submit", s, "--server", &c.url, "--wait", "-o", farm.to_str().expect("utf-8")], &common[..]]
                .concat());
        let rendered =
            run(&[&["render", s, "--threads", "1", "-o", local.to_str().expect("utf-8")], &common[..]].concat());
        submitted && rendered
    });
    let same = rendered && same_image(&farm, &local);
    Report {
        case: "canary",
        class: "afterwards",
        answer: format!(
            "{refused} of 7 hostile submissions refused; canary {}",
            if same { "equals tessera render bit for bit" } else { "differs or failed" }
        ),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: Some(peak(&mut w.child)),
        passed: refused == 7 && same,
    }
}

/// Whether two EXRs have bit-identical RGB and sample counts.
fn same_image(a: &Path, b: &Path) -> bool {
    use tessera_common::film::exr::{read_rgb, read_sample_counts};
    let (Ok(x), Ok(y)) = (read_rgb(a), read_rgb(b)) else { return false };
    let bits = |p: &[[f32; 3]]| p.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
    (x.width, x.height) == (y.width, y.height)
        && bits(&x.pixels) == bits(&y.pixels)
        && read_sample_counts(a).ok() == read_sample_counts(b).ok()
}
