//! The REST API's contract on a real coordinator: server-sent events, RFC 9457 problem
//! documents for every error (the framework's rejections included) and the job list's filters.

use super::TIMEOUT;
use serde_json::{Value, json};
use std::time::{Duration, Instant};
use tessera_tests::{Coordinator, Worker, rest, scene};

fn submit(c: &Coordinator, name: &str, spp: u32) -> String {
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let settings = json!({"integrator": "pt", "spp": spp, "seed": 1, "name": name});
    let (status, job) = rest::submit(&c.url, None, ("scene.xml", xml), vec![], settings);
    assert_eq!(status, 201, "{job}");
    job["id"].as_str().unwrap().to_string()
}

/// One server-sent event: its name and JSON data.
#[derive(Debug)]
struct Sse {
    event: String,
    data: Value,
}

/// Reads the event stream at `url` until it ends or `enough` says so (or `TIMEOUT`), parsing
/// events as they arrive; `started` runs once the stream's headers are in.
fn read_events(url: &str, started: impl FnOnce(), mut enough: impl FnMut(&[Sse]) -> bool) -> (Vec<Sse>, bool) {
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut r = rest::client(None).get(url).send().await.expect("event stream");
        assert_eq!(r.status(), 200);
        let kind = r.headers()["content-type"].to_str().unwrap().to_string();
        assert!(kind.starts_with("text/event-stream"), "{kind}");
        started();
        let (mut text, mut events, deadline) = (String::new(), Vec::new(), Instant::now() + TIMEOUT);
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let chunk = tokio::time::timeout(left, r.chunk()).await.expect("events within the timeout");
            let Some(chunk) = chunk.expect("stream chunk") else { return (events, true) };
            text.push_str(std::str::from_utf8(&chunk).unwrap());
            while let Some(end) = text.find("\n\n") {
                let block: String = text.drain(..end + 2).collect();
                let field = |name: &str| block.lines().find_map(|l| l.strip_prefix(name)).map(str::to_string);
                if let (Some(event), Some(data)) = (field("event: "), field("data: ")) {
                    events.push(Sse { event, data: serde_json::from_str(&data).unwrap() });
                }
            }
            if enough(&events) {
                return (events, false);
            }
        }
    })
}

/// A job's stream opens with its state, shows its progress, ends with `done` and then closes;
/// the server-wide stream shows the same job and the worker taking tiles.
#[test]
fn event_streams_follow_a_job_to_its_end() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let all_url = format!("{}/api/v1/events", c.url);
    let (seen_tx, seen_rx) = std::sync::mpsc::channel();
    let everything = std::thread::spawn(move || {
        read_events(
            &all_url,
            || seen_tx.send(()).unwrap(),
            |e| e.iter().any(|e| e.event == "job.state" && e.data["state"] == "done"),
        )
    });
    seen_rx.recv_timeout(TIMEOUT).unwrap();
    let id = submit(&c, "watched", 64);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &[]);
    let (events, closed) = read_events(&format!("{}/api/v1/jobs/{id}/events", c.url), || {}, |_| false);
    assert!(closed, "the job's stream ends with the job");
    let names: Vec<&str> = events.iter().map(|e| e.event.as_str()).collect();
    assert_eq!(names.first(), Some(&"job.state"), "{names:?}");
    let last = events.last().unwrap();
    assert_eq!((last.event.as_str(), last.data["state"].as_str()), ("job.state", Some("done")), "{names:?}");
    assert_eq!(last.data["tiles_done"], last.data["tiles_total"]);
    assert!(events.iter().all(|e| e.data["job_id"] == id.as_str()), "{events:?}");
    let tiles: Vec<u64> = events.iter().map(|e| e.data["tiles_done"].as_u64().unwrap()).collect();
    assert!(tiles.windows(2).all(|w| w[0] <= w[1]), "progress only goes forward: {tiles:?}");
    let (all, _) = everything.join().unwrap();
    // the job appears (in whatever state it was first seen: states shorter than the stream's
    // period may be skipped) before it is done
    let first = all.iter().position(|e| e.event == "job.state" && e.data["job_id"] == id.as_str()).unwrap();
    assert_ne!(all[first].data["state"], "done", "{all:?}");
    assert!(all.iter().any(|e| e.event == "worker" && e.data["state"] == "busy"), "{all:?}");
}

/// A stream of a job that already ended is its one state; an unknown job is a 404 problem.
#[test]
fn streams_of_ended_and_unknown_jobs_answer_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let id = submit(&c, "cancelled", 64);
    assert_eq!(rest::post(&format!("{}/api/v1/jobs/{id}/cancel", c.url), None).0, 200);
    let (events, closed) = read_events(&format!("{}/api/v1/jobs/{id}/events", c.url), || {}, |_| false);
    assert!(closed);
    assert_eq!(events.len(), 1, "{events:?}");
    assert_eq!(events[0].data["state"], "cancelled");
    let (status, body, kind) = request(reqwest::Method::GET, &format!("{}/api/v1/jobs/nope/events", c.url), None);
    assert_eq!((status, kind.as_str()), (404, "application/problem+json"), "{body}");
}

/// (status, JSON body, content type) of a request with an optional JSON body.
fn request(method: reqwest::Method, url: &str, body: Option<&str>) -> (u16, Value, String) {
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let mut req = rest::client(None).request(method, url).timeout(Duration::from_secs(60));
        if let Some(body) = body {
            req = req.header("content-type", "application/json").body(body.to_string());
        }
        let r = req.send().await.unwrap();
        let status = r.status().as_u16();
        let kind = r.headers().get("content-type").map(|v| v.to_str().unwrap().to_string()).unwrap_or_default();
        let allow = r.headers().get("allow").is_some();
        let bytes = r.bytes().await.unwrap();
        let mut body: Value = serde_json::from_slice(&bytes).unwrap_or(Value::Null);
        if allow {
            body["allow_header"] = json!(true);
        }
        (status, body, kind)
    })
}

/// Every error is a problem document, the framework's rejections (a bad query, a bad JSON
/// body, a wrong method, an unknown route) as much as the service's own.
#[test]
fn every_error_is_a_problem_document() {
    use reqwest::Method;
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let id = submit(&c, "problems", 64);
    let job = format!("{}/api/v1/jobs/{id}", c.url);
    let cases = [
        (Method::GET, format!("{}/api/v1/nothing", c.url), None, 404, "not_found", "no such route"),
        (Method::GET, format!("{}/api/v1/jobs?limit=many", c.url), None, 400, "invalid_argument", "limit"),
        (Method::GET, format!("{}/api/v1/jobs?state=finished", c.url), None, 400, "invalid_argument", "finished"),
        (Method::PATCH, job.clone(), Some("{\"priority\": \"high\"}"), 400, "invalid_argument", "priority"),
        (Method::PATCH, job.clone(), Some("{not json"), 400, "invalid_argument", "JSON"),
        (Method::PUT, job.clone(), None, 405, "method_not_allowed", "Method Not Allowed"),
        (Method::DELETE, job, None, 409, "failed_precondition", "cancel it"),
    ];
    for (method, url, body, status, code, needle) in cases {
        let (got, problem, kind) = request(method.clone(), &url, body);
        let what = format!("{method} {url}: {problem}");
        assert_eq!((got, kind.as_str()), (status, "application/problem+json"), "{what}");
        assert_eq!((problem["status"].as_u64(), problem["code"].as_str()), (Some(status as u64), Some(code)), "{what}");
        assert!(problem["title"].is_string() && problem["type"] == "about:blank", "{what}");
        assert!(problem["detail"].as_str().unwrap().contains(needle), "{what}");
        if status == 405 {
            assert_eq!(problem["allow_header"], true, "a 405 keeps its Allow header: {what}");
        }
    }
}

/// `?state=` and `?name=` select jobs; the total and the next page's link follow the filter.
#[test]
fn the_job_list_filters_by_state_and_name() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let ids: Vec<String> = ["Shot 10 key", "shot 11 fill", "other"].iter().map(|n| submit(&c, n, 64)).collect();
    assert_eq!(rest::post(&format!("{}/api/v1/jobs/{}/cancel", c.url, ids[1]), None).0, 200);
    let list = |query: &str| {
        let (status, jobs) = rest::get_json(&format!("{}/api/v1/jobs?{query}", c.url), None);
        assert_eq!(status, 200, "{jobs}");
        jobs.as_array().unwrap().iter().map(|j| j["id"].as_str().unwrap().to_string()).collect::<Vec<_>>()
    };
    assert_eq!(list("name=SHOT%201"), [ids[1].clone(), ids[0].clone()]);
    assert_eq!(list("state=cancelled"), [ids[1].clone()]);
    assert_eq!(list("state=queued,cancelled&name=shot"), [ids[1].clone(), ids[0].clone()]);
    assert_eq!(list("state=queued&name=shot"), [ids[0].clone()]);
    assert!(list("state=done").is_empty());
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let r = rt.block_on(rest::client(None).get(format!("{}/api/v1/jobs?name=shot&limit=1", c.url)).send()).unwrap();
    assert_eq!(r.headers()["x-total-count"], "2");
    let link = r.headers()["link"].to_str().unwrap();
    assert!(link.contains("offset=1") && link.contains("name=shot"), "{link}");
}

/// The OpenAPI document is public and lists the routes; the data behind it is not public, and
/// a missing token is a problem document too.
#[test]
fn the_openapi_document_is_public_and_the_api_is_not() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--client-token", "t0ken", "--worker-token", "w"],
    );
    let (status, doc) = rest::get_json(&format!("{}/api/v1/openapi.json", c.url), None);
    assert_eq!((status, doc["openapi"].as_str()), (200, Some("3.1.0")));
    for path in ["/api/v1/jobs", "/api/v1/jobs/{id}/events", "/api/v1/events", "/api/v1/workers/{id}/{action}"] {
        assert!(doc["paths"][path].is_object(), "{path} is documented");
    }
    let (status, problem, kind) = request(reqwest::Method::GET, &format!("{}/api/v1/jobs", c.url), None);
    assert_eq!(
        (status, kind.as_str(), problem["code"].as_str()),
        (401, "application/problem+json", Some("unauthenticated"))
    );
}

/// gRPC server reflection lists Tessera's services (so grpcurl needs no .proto files), behind
/// the client token like the services themselves.
#[test]
fn grpc_reflection_lists_the_services() {
    use tonic_reflection::pb::v1::ServerReflectionRequest;
    use tonic_reflection::pb::v1::server_reflection_client::ServerReflectionClient;
    use tonic_reflection::pb::v1::server_reflection_request::MessageRequest;
    use tonic_reflection::pb::v1::server_reflection_response::MessageResponse;
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(
        &dir.path().join("data"),
        "127.0.0.1:0",
        &["--client-token", "t0ken", "--worker-token", "w"],
    );
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    let list = |token: &'static str| {
        rt.block_on(async {
            let channel = tonic::transport::Channel::from_shared(c.url.clone()).unwrap().connect().await.unwrap();
            let auth = move |mut req: tonic::Request<()>| {
                req.metadata_mut().insert("authorization", format!("Bearer {token}").parse().unwrap());
                Ok(req)
            };
            let mut client = ServerReflectionClient::with_interceptor(channel, auth);
            let ask = ServerReflectionRequest {
                host: String::new(),
                message_request: Some(MessageRequest::ListServices(String::new())),
            };
            let mut answers = client.server_reflection_info(tokio_stream::iter([ask])).await?.into_inner();
            let Some(MessageResponse::ListServicesResponse(list)) = answers.message().await?.unwrap().message_response
            else {
                panic!("not a list of services")
            };
            Ok::<_, tonic::Status>(list.service.into_iter().map(|s| s.name).collect::<Vec<_>>())
        })
    };
    let names = list("t0ken").unwrap();
    assert!(
        names.contains(&"tessera.v1.JobService".to_string()) && names.contains(&"tessera.v1.WorkerService".to_string()),
        "{names:?}"
    );
    assert_eq!(list("wrong").unwrap_err().code(), tonic::Code::Unauthenticated);
}

/// The viewer token reads jobs, events and metrics over REST and gRPC, and writes nothing: a
/// submission, a cancel and a worker's call are refused, 403 / PERMISSION_DENIED.
#[test]
fn a_viewer_reads_and_cannot_write() {
    use tessera_proto::v1::job_service_client::JobServiceClient;
    use tessera_proto::v1::{CancelJobRequest, ListJobsRequest};
    let dir = tempfile::tempdir().unwrap();
    let flags = ["--client-token", "writer", "--worker-token", "w", "--viewer-token", "reader"];
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &flags);
    let xml = std::fs::read(scene("cornell-box")).unwrap();
    let settings = json!({"integrator": "pt", "spp": 4096, "seed": 1});
    let (status, job) = rest::submit(&c.url, Some("writer"), ("scene.xml", xml.clone()), vec![], settings.clone());
    assert_eq!(status, 201, "{job}");
    let id = job["id"].as_str().unwrap();
    for path in ["/api/v1/jobs", &format!("/api/v1/jobs/{id}"), "/api/v1/workers", "/metrics"] {
        assert_eq!(rest::get(&format!("{}{path}", c.url), Some("reader")).0, 200, "{path}");
    }
    let (status, problem) = rest::submit(&c.url, Some("reader"), ("scene.xml", xml), vec![], settings);
    assert_eq!((status, problem["code"].as_str()), (403, Some("permission_denied")), "{problem}");
    assert!(problem["detail"].as_str().unwrap().contains("only reads"), "{problem}");
    assert_eq!(rest::post(&format!("{}/api/v1/jobs/{id}/cancel", c.url), Some("reader")).0, 403);
    assert_eq!(rest::get(&format!("{}/api/v1/jobs", c.url), Some("guess")).0, 401);
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap();
    rt.block_on(async {
        let channel = tonic::transport::Channel::from_shared(c.url.clone()).unwrap().connect().await.unwrap();
        let auth = |mut req: tonic::Request<()>| {
            req.metadata_mut().insert("authorization", "Bearer reader".parse().unwrap());
            Ok(req)
        };
        let mut client = JobServiceClient::with_interceptor(channel, auth);
        assert_eq!(client.list_jobs(ListJobsRequest {}).await.unwrap().into_inner().jobs.len(), 1);
        let cancel = client.cancel_job(CancelJobRequest { id: id.to_string() }).await.unwrap_err();
        assert_eq!(cancel.code(), tonic::Code::PermissionDenied, "{cancel:?}");
    });
    assert_eq!(rest::get_json(&format!("{}/api/v1/jobs/{id}", c.url), Some("writer")).1["state"], "queued");
}

/// `/metrics` names the build, the process, each worker, and counts the samples merged (equal
/// to the job's own count) and the tile failures.
#[test]
fn metrics_show_the_build_the_process_workers_and_samples() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(&dir.path().join("data"), "127.0.0.1:0", &[]);
    let _w = Worker::start(&c.url, &dir.path().join("cache"), &["--name", "w-metrics"]);
    let id = submit(&c, "counted", 4);
    let (events, _) = read_events(&format!("{}/api/v1/jobs/{id}/events", c.url), || {}, |_| false);
    let done = &events.last().unwrap().data;
    assert_eq!(done["state"], "done", "{events:?}");
    let (status, text) = rest::get(&format!("{}/metrics", c.url), None);
    assert_eq!(status, 200);
    let text = String::from_utf8(text).unwrap();
    let value = |name: &str| -> f64 {
        let line = text.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("no {name} in\n{text}"));
        line.rsplit(' ').next().unwrap().parse().unwrap()
    };
    assert_eq!(value("tessera_samples_merged_total"), done["samples_done"].as_f64().unwrap());
    assert_eq!(value("tessera_tile_failures_total"), 0.0);
    assert_eq!(value("tessera_build_info{version=\"0.1.0\""), 1.0);
    assert!(value("process_resident_memory_bytes") > 1e6 && value("process_open_fds") > 3.0);
    assert!(value("process_start_time_seconds") > 1.6e9 && value("process_cpu_seconds_total") > 0.0);
    let up = text.lines().find(|l| l.starts_with("tessera_worker_up{") && l.contains("name=\"w-metrics\"")).unwrap();
    assert!(up.ends_with(" 1"), "{up}");
}
