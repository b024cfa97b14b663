//! Hostile scenes submitted to a real coordinator: each is refused with its reason before the
//! coordinator reads outside the bundle or allocates for it, and the coordinator stays up with
//! its memory bounded; an honest scene reaching outside its folder still renders.

use super::*;

/// The coordinator's peak resident memory so far, in MiB (`VmHWM` of `/proc/PID/status`).
pub(crate) fn peak_rss_mib(c: &Coordinator) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", c.child.id())).expect("proc status");
    let kib: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmHWM");
    kib >> 10
}

#[test]
fn hostile_scenes_are_refused_and_the_coordinator_stays_small() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let xml = String::from_utf8(std::fs::read(scene("cornell-box")).unwrap()).unwrap();
    let settings = json!({"integrator": "pt", "spp": 1});
    let with = |extra: &str| xml.replacen("</scene>", &format!("{extra}\n</scene>"), 1);
    let mut chain = String::from("<default name=\"p0\" value=\"xxxxxxxxxx\"/>");
    for i in 1..10 {
        chain += &format!("<default name=\"p{i}\" value=\"{}\"/>", format!("$p{}", i - 1).repeat(10));
    }
    let chained = xml.replacen("<sensor", &format!("{chain}<sensor"), 1).replacen(
        "<sensor type=\"perspective\">",
        "<sensor type=\"perspective\"><string name=\"label\" value=\"$p9\"/>",
        1,
    );
    let cases = [
        (
            "a mesh that is /dev/zero",
            with("<shape type=\"obj\"><string name=\"filename\" value=\"/dev/zero\"/></shape>"),
            "absolute path",
        ),
        (
            "a mesh outside the bundle",
            with("<shape type=\"ply\"><string name=\"filename\" value=\"../../../etc/passwd\"/></shape>"),
            "outside the job's bundle",
        ),
        ("an included system file", with("<include filename=\"/etc/passwd\"/>"), "absolute path"),
        ("a 65535² film", xml.replacen("value=\"256\"", "value=\"65535\"", 2), "--max-pixels"),
        ("geometric <default> expansion", chained, "grows past"),
    ];
    for (what, scene_xml, needle) in cases {
        let (status, body) =
            rest::submit(&c.url, None, ("scene.xml", scene_xml.into_bytes()), vec![], settings.clone());
        let message = body["error"].as_str().unwrap_or_default();
        assert_eq!(status, 400, "{what}: {body}");
        assert!(message.contains(needle), "{what}: {message}");
        assert_eq!(rest::get(&format!("{}/healthz", c.url), None).0, 200, "{what}: coordinator alive");
    }
    let peak = peak_rss_mib(&c);
    assert!(peak < 512, "the coordinator peaked at {peak} MiB refusing hostile scenes");
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml.into_bytes()), vec![], settings);
    assert_eq!(status, 201, "an honest scene is still accepted: {job}");
}

/// The other side of confinement: a scene that reaches a sibling folder (`../meshes`) ships
/// unchanged in a bundle rooted at their common folder and renders on the farm as locally.
#[test]
fn a_scene_reaching_a_sibling_folder_renders_on_the_farm_as_locally() {
    let dir = tempfile::tempdir().unwrap();
    let (c, _w) = farm(dir.path(), 1);
    let project = dir.path().join("project");
    std::fs::create_dir_all(project.join("scene")).unwrap();
    std::fs::create_dir_all(project.join("meshes")).unwrap();
    std::fs::write(project.join("meshes/tri.obj"), "v -0.5 -0.5 0.2\nv 0.5 -0.5 0.2\nv 0 0.5 0.2\nf 1 2 3\n").unwrap();
    let xml = String::from_utf8(std::fs::read(scene("cornell-box")).unwrap()).unwrap().replacen(
        "</scene>",
        "<shape type=\"obj\"><string name=\"filename\" value=\"../meshes/tri.obj\"/></shape>\n</scene>",
        1,
    );
    let path = project.join("scene/scene.xml");
    std::fs::write(&path, xml).unwrap();
    let out = dir.path().join("farm.exr");
    let (ok, _, stderr) = submit_and_wait(&c.url, &path, ("pt", 2, 9), &out, &[]);
    assert!(ok, "submit failed: {stderr}\nlog: {}", c.log.display());
    assert_same_image(&out, &local_render(dir.path(), &path, "pt", 2, 9));
}

/// Issue 67's adversarial suite against this build: every case is refused with its reason or
/// served within bounded memory, no process dies or passes 1 GiB, and the canary equals
/// `tessera render` bit for bit (`tessera_tests::hostile`; `hostile-suite` prints the table).
#[test]
fn adversarial_suite() {
    use tessera_tests::hostile::{self, Bins, TABLE_HEADER};
    let dir = tempfile::tempdir().unwrap();
    let scratch = dir.path().to_path_buf();
    // the suite's own clients (reqwest, tonic, the exr writer) run deep in a debug build
    let suite = std::thread::Builder::new().stack_size(16 << 20);
    let reports = suite.spawn(move || hostile::run(&Bins::this_build(), &scratch, &[])).unwrap().join().unwrap();
    let table: Vec<String> = reports.iter().map(|r| r.row()).collect();
    let table = format!("{TABLE_HEADER}\n{}", table.join("\n"));
    println!("{table}");
    for r in &reports {
        // a full disk needs a file system the suite can mount: without root it says so
        if r.case == "full-disk" && r.answer.starts_with("skipped") {
            eprintln!("full-disk: {}", r.answer);
            continue;
        }
        assert!(r.passed && r.survived(), "case {} failed: {}\n{table}", r.case, r.answer);
    }
}
