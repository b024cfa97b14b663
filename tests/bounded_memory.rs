//! The coordinator's memory stays bounded, measured on the real process (its peak RSS): a
//! large scene bundle is written to disk as it arrives, over REST and over the streamed gRPC
//! submission, and a stalled first tile of a 1080p vcm pass holds back at most the lease
//! window's results, however many tiles the pass has.

use super::hostile::peak_rss_mib;
use super::*;
use tessera_common::film::{Rect, TileAccum};
use tessera_common::settings::{IntegratorName, RenderSettings};
use tessera_proto::v1 as pb;
use tessera_proto::v1::job_service_client::JobServiceClient;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;

const MIB: usize = 1 << 20;

/// The parts of a streamed submission of `scene.xml` and a `big.bin` of `big` bytes.
fn streamed_parts(xml: Vec<u8>, big: usize) -> Vec<pb::SubmitJobPart> {
    let settings = RenderSettings { integrator: IntegratorName::Pt, spp: Some(1), ..Default::default() };
    let header = pb::SubmitJobRequest {
        settings: Some(tessera_link::convert::settings_to_pb(&settings)),
        bundle: Some(pb::SceneBundle { scene_path: "scene.xml".into(), files: vec![] }),
        priority: 0,
        name: "big".into(),
        ..Default::default()
    };
    let mut parts = vec![
        pb::SubmitJobPart { header: Some(header), ..Default::default() },
        pb::SubmitJobPart { header: None, path: "scene.xml".into(), data: xml.into() },
    ];
    let chunk = prost::bytes::Bytes::from(vec![7u8; MIB]);
    for i in 0..big / MIB {
        let path = if i == 0 { "big.bin".to_string() } else { String::new() };
        parts.push(pb::SubmitJobPart { header: None, path, data: chunk.clone() });
    }
    parts
}

/// 256 MiB bundles, over REST and over gRPC, leave the coordinator under 96 MiB (it used to
/// hold about four copies); one over `--max-upload-mb` on the stream is refused naming the
/// flag, and its staging folder is gone.
#[test]
fn large_bundles_are_streamed_to_disk() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let c = Coordinator::start(&data, "127.0.0.1:0", &["--max-upload-mb", "300"]);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let big = 256 * MIB;
    let settings = json!({"integrator": "pt", "spp": 1});
    let (status, job) =
        rest::submit(&c.url, None, ("scene.xml", xml.clone()), vec![("big.bin".into(), vec![7u8; big])], settings);
    assert_eq!(status, 201, "{job}");
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let refused = rt.block_on(async {
        let mut client = JobServiceClient::connect(c.url.clone()).await.unwrap();
        let job = client.submit_job_stream(tokio_stream::iter(streamed_parts(xml.clone(), big))).await.unwrap();
        assert_eq!(job.into_inner().state, pb::JobState::Queued as i32);
        client.submit_job_stream(tokio_stream::iter(streamed_parts(xml, 320 * MIB))).await.unwrap_err()
    });
    assert_eq!(refused.code(), tonic::Code::ResourceExhausted, "{refused}");
    assert!(refused.message().contains("--max-upload-mb") && refused.message().contains("big.bin"), "{refused}");
    let peak = peak_rss_mib(&c);
    assert!(peak < 96, "the coordinator peaked at {peak} MiB receiving 256 MiB bundles");
    // both accepted bundles are the same blob, unpacked once; nothing is left staged
    let scenes: Vec<_> = std::fs::read_dir(data.join("scenes")).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(scenes.len(), 1, "{scenes:?}");
    let unpacked = data.join("scenes").join(&scenes[0]).join("big.bin");
    assert_eq!(std::fs::metadata(unpacked).unwrap().len(), big as u64);
}

/// A 1080p vcm pass whose tile 0 is held by a worker that heartbeats but never returns: the
/// rest of the pass arrives from another worker as fast as it can upload, and is leased no
/// further than the window past tile 0, so the coordinator's memory does not grow with the
/// pass. Once tile 0 comes back, the job finishes.
#[test]
fn a_stalled_first_tile_holds_back_only_the_lease_window() {
    const SPP: u32 = 24;
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let xml = std::fs::read_to_string(scene("cornell-box")).unwrap();
    let xml = xml
        .replace("name=\"width\" value=\"256\"", "name=\"width\" value=\"1920\"")
        .replace("name=\"height\" value=\"256\"", "name=\"height\" value=\"1080\"");
    let settings = json!({"integrator": "vcm", "spp": SPP, "seed": 4});
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml.clone().into_bytes()), vec![], settings);
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap().to_string();
    // a zero frame is a valid result of any iteration; the coordinator cannot tell
    let path = dir.path().join("scene.xml");
    std::fs::write(&path, &xml).unwrap();
    let film = tessera_common::scene::Scene::load(&path).unwrap().film;
    let full = Rect { x0: 0, y0: 0, x1: 1920, y1: 1080 };
    let mut frame = TileAccum::new(full, &film);
    frame.count.fill(1);
    let payload = prost::bytes::Bytes::from(tessera_link::payload::encode_tile(&frame));
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let (held, peak_stalled) = rt.block_on(async {
        let client = WorkerServiceClient::connect(c.url.clone())
            .await
            .unwrap()
            .max_decoding_message_size(tessera_proto::MAX_MESSAGE_BYTES);
        let register = async |name: &str| {
            let reg = pb::RegisterRequest { name: name.into(), threads: 1, ..tessera_link::build::registration() };
            client.clone().register(reg).await.unwrap().into_inner().worker_id
        };
        let (staller, fast) = (register("staller").await, register("fast").await);
        let lease = |worker: String| {
            let mut client = client.clone();
            async move {
                let req = pb::LeaseTileRequest { worker_id: worker, max_tiles: 1, wait_ms: 1500 };
                client.lease_tile(req).await.unwrap().into_inner().leases.pop()
            }
        };
        let first = lease(staller.clone()).await.expect("tile 0");
        assert_eq!(first.lease.as_ref().unwrap().tile, 0);
        // the staller keeps its lease alive
        let beat = {
            let (mut client, worker, held) = (client.clone(), staller.clone(), first.lease.clone().unwrap());
            tokio::spawn(async move {
                loop {
                    let req = pb::HeartbeatRequest { worker_id: worker.clone(), leases: vec![held.clone()] };
                    let lost = client.heartbeat(req).await.unwrap().into_inner().lost;
                    assert!(lost.is_empty(), "the stalled lease was lost: {lost:?}");
                    tokio::time::sleep(Duration::from_millis(500)).await;
                }
            })
        };
        let upload = |worker: String, lease: pb::TileLease| {
            use pb::upload_result_request::Part;
            let (mut client, payload) = (client.clone(), payload.clone());
            async move {
                let header = tessera_proto::result_header(&worker, &lease, 0, 0.0, 0);
                let mut parts = vec![pb::UploadResultRequest { part: Some(Part::Header(header)) }];
                for at in (0..payload.len()).step_by(tessera_proto::CHUNK_BYTES) {
                    let end = payload.len().min(at + tessera_proto::CHUNK_BYTES);
                    parts.push(pb::UploadResultRequest { part: Some(Part::Data(payload.slice(at..end))) });
                }
                let outcome = client.upload_result(tokio_stream::iter(parts)).await.unwrap().into_inner().outcome;
                assert_eq!(outcome, pb::UploadOutcome::Accepted as i32);
            }
        };
        let mut held = 0;
        while let Some(next) = lease(fast.clone()).await {
            upload(fast.clone(), next).await;
            held += 1;
            assert!(held < SPP - 1, "the whole pass was leased while tile 0 stalled");
        }
        let peak_stalled = peak_rss_mib(&c);
        beat.abort();
        upload(staller, first).await;
        while let Some(next) = lease(fast.clone()).await {
            upload(fast.clone(), next).await;
        }
        (held, peak_stalled)
    });
    let done = wait_for(TIMEOUT, "the job to finish", || {
        let (_, job) = rest::get_json(&job_url(&c, &id), None);
        (job["state"] == "done").then_some(job)
    });
    assert_eq!(done["samples_done"], 1920 * 1080 * SPP as u64, "{done}");
    let frame_mib = (1920 * 1080 * 28) >> 20;
    let peak = peak_rss_mib(&c);
    eprintln!("{held} results held behind tile 0; peak RSS {peak_stalled} MiB then, {peak} MiB in all");
    // the window's results, the film, and a frame or two in flight, whatever the pass's length
    let bound = 512 + 4 * frame_mib + 96;
    assert!(peak < bound as u64, "the coordinator peaked at {peak} MiB (bound {bound} MiB)");
}
