//! Workers a coordinator must not take: one of another build (refused at registration, naming
//! both builds) and one with a wrong token (it exits with a clear error instead of retrying
//! forever as if the coordinator were down).

use super::*;
use std::process::{Command, Stdio};
use tessera_proto::v1 as pb;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;

/// A registration from another build is FAILED_PRECONDITION with both builds named; this
/// build's is accepted.
#[test]
fn a_worker_of_another_build_is_refused_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut client = WorkerServiceClient::connect(c.url.clone()).await.unwrap();
        let ours = tessera_link::build::registration();
        for (version, revision) in [("0.0.1", ours.renderer_revision.as_str()), (&ours.version, "0123456789ab")] {
            let reg = pb::RegisterRequest {
                name: "old".into(),
                threads: 1,
                version: version.into(),
                renderer_revision: revision.into(),
                ..Default::default()
            };
            let e = client.register(reg).await.unwrap_err();
            assert_eq!(e.code(), tonic::Code::FailedPrecondition, "{e:?}");
            let (theirs, mine) = (format!("{version} (renderer {revision})"), tessera_common::build_id());
            assert!(e.message().contains(&theirs) && e.message().contains(&mine), "{}", e.message());
        }
        let reg = pb::RegisterRequest { name: "same".into(), threads: 1, ..ours };
        client.register(reg).await.unwrap();
    });
    let (_, workers) = rest::get_json(&format!("{}/api/v1/workers", c.url), None);
    assert_eq!(workers.as_array().map(Vec::len), Some(1), "{workers}");
    let (ok, out, _) = tessera(&["version"]);
    assert!(ok && out.contains(&tessera_common::build_id()), "{out}");
}

/// A worker started with a wrong token exits with an error that says so.
#[test]
fn a_worker_with_a_wrong_token_exits_saying_so() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &["--worker-token", "right-token-0123"]);
    let mut child = Command::new(tessera_tests::bin("tessera-worker"))
        .args(["--coordinator", &c.url, "--token", "wrong-token-0123", "--cache-dir"])
        .arg(dir.path().join("cache"))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let status = wait_for(TIMEOUT, "the worker to exit", || child.try_wait().unwrap());
    assert!(!status.success());
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(err.contains("refused this worker's token"), "{err}");
}
