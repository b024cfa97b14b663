//! The cases of a worker token in hostile hands: registrations with huge names, many upload
//! streams on one lease, fake failures from fresh registrations, and finite but impossible
//! sums.

use super::inputs;
use super::procs::{Bins, peak, settle};
use super::{Case, Report, timed};
use crate::{Coordinator, rest};
use serde_json::json;
use std::path::Path;
use std::time::Duration;
use tessera_proto::v1 as pb;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;
use tonic::transport::{Channel, Endpoint};

pub(super) fn all() -> Vec<Case> {
    vec![
        Case { name: "register-1mib-names", class: "a worker token can do too much", run: big_names },
        Case { name: "20-upload-streams", class: "a worker token can do too much", run: upload_streams },
        Case { name: "failures-by-reregistering", class: "a worker token can do too much", run: fake_failures },
        Case { name: "sums-1e300", class: "a worker token can do too much", run: huge_sums },
    ]
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime")
}

/// A gRPC client of `c` whose connections come from the loopback address `source` (so that a
/// hand-driven worker is another host than the real one on 127.0.0.1).
async fn client_from(c: &Coordinator, source: [u8; 4]) -> Option<WorkerServiceClient<Channel>> {
    let connector = tower::service_fn(move |uri: http::Uri| async move {
        let socket = tokio::net::TcpSocket::new_v4()?;
        socket.bind((source, 0).into())?;
        let port = uri.port_u16().unwrap_or(80);
        let stream = socket.connect(([127, 0, 0, 1], port).into()).await?;
        Ok::<_, std::io::Error>(hyper_util::rt::TokioIo::new(stream))
    });
    let channel = Endpoint::from_shared(c.url.clone()).ok()?.connect_with_connector(connector).await.ok()?;
    Some(WorkerServiceClient::new(channel).max_decoding_message_size(64 << 20).max_encoding_message_size(64 << 20))
}

async fn register(client: &mut WorkerServiceClient<Channel>, name: String) -> Result<String, tonic::Status> {
    let req = pb::RegisterRequest { name, threads: 1, ..tessera_link::build::registration() };
    client.register(req).await.map(|r| r.into_inner().worker_id)
}

async fn lease(client: &mut WorkerServiceClient<Channel>, worker: &str) -> Option<pb::TileLease> {
    let req = pb::LeaseTileRequest { worker_id: worker.to_string(), max_tiles: 1, wait_ms: 5000 };
    client.lease_tile(req).await.ok()?.into_inner().leases.pop()
}

/// 300 registrations with 1 MiB names, then `GET /api/v1/workers`.
fn big_names(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let rt = runtime();
    let (refused, seconds) = timed(|| {
        rt.block_on(async {
            let Some(mut client) = client_from(&c, [127, 0, 0, 1]).await else { return 0 };
            let mut refused = 0;
            for _ in 0..300 {
                match register(&mut client, "n".repeat(1 << 20)).await {
                    Err(e) if e.code() == tonic::Code::InvalidArgument => refused += 1,
                    Err(_) => break,
                    Ok(_) => {}
                }
            }
            refused
        })
    });
    let (status, workers) = rest::try_get(&format!("{}/api/v1/workers", c.url));
    Report {
        case: "register-1mib-names",
        class: "a worker token can do too much",
        answer: format!("{refused} of 300 refused; GET /workers {status}, {} KB", workers.len() / 1024),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed: refused == 300,
    }
}

/// One full-frame 1920×1080 `vcm` tile leased, then 20 upload streams on its lease, each
/// sending about half of what its result may have (50 MB) and holding on.
fn upload_streams(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let film = inputs::HEAD.replace(
        "value=\"64\"/><integer name=\"height\" value=\"64\"",
        "value=\"1920\"/><integer name=\"height\" value=\"1080\"",
    );
    let scene = format!("{film}</scene>\n").into_bytes();
    rest::try_submit(&c.url, ("scene.xml", scene), vec![], json!({"integrator": "vcm", "spp": 1}));
    let rt = runtime();
    let (refused, seconds) = timed(|| rt.block_on(streams(&c)));
    Report {
        case: "20-upload-streams",
        class: "a worker token can do too much",
        answer: format!("{} of 20 streams refused", refused.map_or("?".into(), |n| n.to_string())),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed: refused == Some(19),
    }
}

async fn streams(c: &Coordinator) -> Option<usize> {
    use pb::upload_result_request::Part;
    let mut client = client_from(c, [127, 0, 0, 1]).await?;
    let worker = register(&mut client, "streams".into()).await.ok()?;
    let tile = lease(&mut client, &worker).await?;
    let r = tile.rect?;
    // the RGB sums of every pixel: less than the whole result (weights, counts, splats)
    let bytes = ((r.x1 - r.x0) * (r.y1 - r.y0)) as usize * 24;
    let mut held = Vec::new();
    let mut refused = 0;
    for _ in 0..20 {
        let (tx, rx) = tokio::sync::mpsc::channel(4);
        let header = tessera_proto::result_header(&worker, &tile, 0, 0.0, 0);
        tx.send(pb::UploadResultRequest { part: Some(Part::Header(header)) }).await.ok()?;
        let mut client = client.clone();
        let call =
            tokio::spawn(async move { client.upload_result(tokio_stream::wrappers::ReceiverStream::new(rx)).await });
        let feed = tokio::spawn(async move {
            for _ in 0..bytes.saturating_sub(1) / (1 << 20) {
                let data = vec![0u8; 1 << 20];
                if tx.send(pb::UploadResultRequest { part: Some(Part::Data(data.into())) }).await.is_err() {
                    return;
                }
            }
            tokio::time::sleep(Duration::from_secs(5)).await;
        });
        held.push((call, feed));
    }
    tokio::time::sleep(Duration::from_secs(3)).await;
    for (call, feed) in held {
        if call.is_finished() && matches!(call.await, Ok(Err(_))) {
            refused += 1;
        } else {
            feed.abort();
        }
    }
    Some(refused)
}

/// A hand-driven worker on 127.0.0.2 registers afresh before each failure it reports: the
/// job must survive, and the real worker on 127.0.0.1 finishes it.
fn fake_failures(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    let (_, job) = rest::try_submit(&c.url, ("scene.xml", inputs::scene("")), vec![], json!({"spp": 1}));
    let id = job["id"].as_str().unwrap_or("").to_string();
    let rt = runtime();
    let (failures, _) = timed(|| {
        rt.block_on(async {
            let Some(mut client) = client_from(&c, [127, 0, 0, 2]).await else { return 0 };
            let mut failures = 0;
            for _ in 0..8 {
                let Ok(worker) = register(&mut client, "liar".into()).await else { break };
                let Some(tile) = lease(&mut client, &worker).await else { break };
                let req = pb::ReportFailureRequest { worker_id: worker, lease: tile.lease, message: "fake".into() };
                failures += client.report_failure(req).await.is_ok() as usize;
            }
            failures
        })
    });
    let (_, after_lies) = rest::try_get_json(&format!("{}/api/v1/jobs/{id}", c.url));
    let mut w = bins.worker(&c, dir);
    let (state, seconds) = timed(|| {
        let deadline = std::time::Instant::now() + Duration::from_secs(60);
        loop {
            let (_, job) = rest::try_get_json(&format!("{}/api/v1/jobs/{id}", c.url));
            let state = job["state"].as_str().unwrap_or("gone").to_string();
            if matches!(state.as_str(), "done" | "failed" | "gone") || std::time::Instant::now() > deadline {
                return state;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    });
    Report {
        case: "failures-by-reregistering",
        class: "a worker token can do too much",
        answer: format!("{failures} fake failures: job {}; then {state}", after_lies["state"].as_str().unwrap_or("-")),
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: Some(peak(&mut w.child)),
        passed: state == "done",
    }
}

/// A result of finite sums of 1e300 for a one-sample tile.
fn huge_sums(bins: &Bins, dir: &Path) -> Report {
    let mut c = bins.coordinator(dir, &[]);
    rest::try_submit(&c.url, ("scene.xml", inputs::scene("")), vec![], json!({"spp": 1}));
    let rt = runtime();
    let (outcome, seconds) = timed(|| {
        rt.block_on(async {
            use pb::upload_result_request::Part;
            let mut client = client_from(&c, [127, 0, 0, 1]).await?;
            let worker = register(&mut client, "sums".into()).await.ok()?;
            let tile = lease(&mut client, &worker).await?;
            let r = tile.rect?;
            let pixels = ((r.x1 - r.x0) * (r.y1 - r.y0)) as usize;
            let mut payload = Vec::new();
            let counts = vec![tile.sample_end - tile.sample_begin; pixels];
            tessera_link::payload::write_channels(&mut payload, &vec![[1e300; 3]; pixels], None, None, &counts).ok()?;
            let header = tessera_proto::result_header(&worker, &tile, 0, 0.0, 0);
            let parts = [Part::Header(header), Part::Data(payload.into())];
            let messages = parts.map(|p| pb::UploadResultRequest { part: Some(p) });
            Some(client.upload_result(tokio_stream::iter(messages)).await.map(|r| r.into_inner().outcome))
        })
    });
    let answer = match &outcome {
        Some(Ok(o)) => format!("accepted (outcome {o})"),
        Some(Err(e)) => format!("{:?}: {}", e.code(), e.message().chars().take(90).collect::<String>()),
        None => "no lease".into(),
    };
    Report {
        case: "sums-1e300",
        class: "a worker token can do too much",
        answer,
        seconds,
        coordinator: settle(&mut c.child, Duration::from_millis(100)),
        worker: None,
        passed: matches!(outcome, Some(Err(e)) if e.code() == tonic::Code::InvalidArgument),
    }
}
