//! A hand-driven worker uploads malformed results: each is refused with INVALID_ARGUMENT, its
//! tile re-queued with the next epoch, and the finished image is still bit-identical to a
//! local render. Duplicates and stale epochs are ignored.

use super::*;
use tessera_common::film::{Rect, TileAccum};
use tessera_common::integrator::TileRequest;
use tessera_common::settings::{IntegratorName, RenderSettings, Renderer};
use tessera_proto::v1 as pb;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;
use tonic::transport::Channel;

async fn upload(
    client: &mut WorkerServiceClient<Channel>,
    worker: &str,
    lease: &pb::TileLease,
    payload: Vec<u8>,
) -> Result<pb::UploadResultResponse, tonic::Status> {
    use pb::upload_result_request::Part;
    let header = tessera_proto::result_header(worker, lease, 0, 0.0, 0);
    let messages = vec![
        pb::UploadResultRequest { part: Some(Part::Header(header)) },
        pb::UploadResultRequest { part: Some(Part::Data(payload.into())) },
    ];
    client.upload_result(tokio_stream::iter(messages)).await.map(|r| r.into_inner())
}

async fn lease_one(client: &mut WorkerServiceClient<Channel>, worker: &str) -> pb::TileLease {
    let req = pb::LeaseTileRequest { worker_id: worker.to_string(), max_tiles: 1, wait_ms: 5000 };
    client.lease_tile(req).await.unwrap().into_inner().leases.pop().expect("a lease")
}

#[test]
fn malformed_results_are_refused_and_the_tile_requeued() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let (_, job) =
        rest::submit(&c.url, None, ("scene.xml", xml), vec![], json!({"integrator": "pt", "spp": 1, "seed": 6}));
    let id = job["id"].as_str().unwrap().to_string();
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut client = WorkerServiceClient::connect(c.url.clone()).await.unwrap();
        let reg = pb::RegisterRequest { name: "hand".into(), threads: 1, ..tessera_link::build::registration() };
        let worker = client.register(reg).await.unwrap().into_inner().worker_id;

        let first = lease_one(&mut client, &worker).await;
        let r = first.rect.unwrap();
        let pixels = ((r.x1 - r.x0) * (r.y1 - r.y0)) as usize;
        let e = upload(&mut client, &worker, &first, vec![0u8; 10]).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().contains("bytes"), "{}", e.message());

        let second = lease_one(&mut client, &worker).await;
        assert_eq!(
            second.lease.as_ref().unwrap().tile,
            first.lease.as_ref().unwrap().tile,
            "the refused tile comes back"
        );
        assert_eq!(second.lease.as_ref().unwrap().epoch, 1);
        let mut sums = vec![[0.5f64; 3]; pixels];
        sums[7][1] = f64::NAN;
        let mut nan = Vec::new();
        tessera_link::payload::write_channels(&mut nan, &sums, None, None, &vec![1; pixels]).unwrap();
        let e = upload(&mut client, &worker, &second, nan).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument);
        assert!(e.message().contains("not finite"), "{}", e.message());

        // the honest result of the third lease is accepted once; old epochs are stale
        let third = lease_one(&mut client, &worker).await;
        assert_eq!(third.lease.as_ref().unwrap().epoch, 2);
        let scene = tessera_common::scene::Scene::load(&scene("cornell-box")).unwrap();
        let settings =
            RenderSettings { integrator: IntegratorName::Pt, spp: Some(1), seed: Some(6), ..Default::default() };
        let Ok(Renderer::Tiles(integrator)) = settings.make_renderer(&scene) else { panic!("a tile integrator") };
        let rect = Rect { x0: r.x0, y0: r.y0, x1: r.x1, y1: r.y1 };
        let mut accum = TileAccum::new(rect, &scene.film);
        integrator.render_tile(&scene, &TileRequest::new(rect, 0..1, 6), &mut accum);
        let payload = tessera_link::payload::encode_tile(&accum);
        let ok = upload(&mut client, &worker, &third, payload.clone()).await.unwrap();
        assert_eq!(ok.outcome, pb::UploadOutcome::Accepted as i32);
        let again = upload(&mut client, &worker, &third, payload.clone()).await.unwrap();
        assert_eq!(again.outcome, pb::UploadOutcome::Duplicate as i32);
        let stale = upload(&mut client, &worker, &first, payload).await.unwrap();
        assert_eq!(stale.outcome, pb::UploadOutcome::Stale as i32);
    });
    let (_, metrics) = rest::get(&format!("{}/metrics", c.url), None);
    assert!(String::from_utf8(metrics).unwrap().contains("tessera_results_refused_total 2"));
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    wait_done(&c, &id, None);
    let out = dir.path().join("farm.exr");
    download(&format!("{}/result.exr", job_url(&c, &id)), None, &out);
    assert_same_image(&out, &local_render(dir.path(), &scene("cornell-box"), "pt", 1, 6));
}

/// A hostile worker: uploads under another worker's lease or a lease that does not exist are
/// stale before anything is buffered, a claimed rectangle far larger than the lease buys no
/// room (the leased tile's size bounds what is read), and a 1 GiB message is refused by the
/// length it announces.
#[test]
fn a_hostile_worker_cannot_make_the_coordinator_buffer_past_a_lease() {
    use pb::upload_result_request::Part;
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let (status, _) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], json!({"integrator": "pt", "spp": 1}));
    assert_eq!(status, 201);
    let huge = Some(pb::Rect { x0: 0, y0: 0, x1: 65535, y1: 65535 });
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut client = WorkerServiceClient::connect(c.url.clone()).await.unwrap();
        let register = async |name: &str| {
            let reg = pb::RegisterRequest { name: name.into(), threads: 1, ..tessera_link::build::registration() };
            client.clone().register(reg).await.unwrap().into_inner().worker_id
        };
        let (honest, thief) = (register("honest").await, register("thief").await);
        let lease = lease_one(&mut client, &honest).await;
        // 256 MiB in 1 MiB messages behind a header that claims 65535² pixels
        let flood = |worker: &str, lease: &pb::TileLease| {
            let mut header = tessera_proto::result_header(worker, lease, 0, 0.0, 0);
            header.rect = huge;
            let data = (0..256).map(|_| pb::UploadResultRequest { part: Some(Part::Data(vec![0u8; 1 << 20].into())) });
            let first = pb::UploadResultRequest { part: Some(Part::Header(header)) };
            tokio_stream::iter(std::iter::once(first).chain(data))
        };
        let stolen = client.upload_result(flood(&thief, &lease)).await.map(|r| r.into_inner().outcome);
        assert_eq!(stolen.ok(), Some(pb::UploadOutcome::Stale as i32));
        let mut unknown = lease.clone();
        unknown.lease.as_mut().unwrap().job_id = "no-such-job".into();
        let nowhere = client.upload_result(flood(&honest, &unknown)).await.map(|r| r.into_inner().outcome);
        assert_eq!(nowhere.ok(), Some(pb::UploadOutcome::Stale as i32));
        let e = client.upload_result(flood(&honest, &lease)).await.unwrap_err();
        assert_eq!(e.code(), tonic::Code::InvalidArgument, "{e}");
        assert!(e.message().contains("exceeds"), "{}", e.message());
        // one 1 GiB message: refused by its length, before it is buffered
        let header = tessera_proto::result_header(&honest, &lease, 0, 0.0, 0);
        let giant = vec![
            pb::UploadResultRequest { part: Some(Part::Header(header)) },
            pb::UploadResultRequest { part: Some(Part::Data(vec![0u8; 1 << 30].into())) },
        ];
        let e = client.clone().max_encoding_message_size(usize::MAX).upload_result(tokio_stream::iter(giant)).await;
        let e = e.expect_err("a 1 GiB message is refused");
        assert!(matches!(e.code(), tonic::Code::OutOfRange | tonic::Code::ResourceExhausted), "{e}");
    });
    let peak = super::hostile::peak_rss_mib(&c);
    assert!(peak < 128, "the coordinator peaked at {peak} MiB under 1.75 GiB of hostile uploads");
    assert_eq!(rest::get(&format!("{}/healthz", c.url), None).0, 200);
}
