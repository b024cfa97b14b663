//! The ingest load generator: simulated workers that register with a real coordinator over
//! gRPC, lease tiles and upload valid results (right sizes, finite sums, the lease's sample
//! count in every pixel) as fast as the coordinator takes them, on concurrent connections.
//!
//! [`build_result`] is the one place that makes a payload; extend it when tile results grow
//! (EMIS moment buffers on full-frame payloads).

use super::calibrate::TileTimes;
use super::serve::{ServeProcess, all_cpus, pin_current_thread};
use super::{FarmArgs, generated_job, job_client, quantile};
use anyhow::{Context, bail};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tessera_common::settings::IntegratorName;
use tessera_proto::v1 as pb;
use tessera_proto::v1::worker_service_client::WorkerServiceClient;
use tonic::transport::Channel;

/// A tile result as a worker uploads it: the header, then the payload in chunks.
#[derive(Clone, Debug)]
pub struct SimResult {
    /// The first upload message.
    pub header: pb::TileResultHeader,
    /// The bytes that follow it (`TileResultHeader`'s layout).
    pub payload: Vec<u8>,
}

/// Bytes per pixel of the box-filtered sums the generated scene's tiles carry.
const BOX_BYTES_PER_PIXEL: usize = 28;

/// A valid result for `lease`: every pixel's sums finite and plausible (a smooth pattern of
/// radiance sums, so the bytes are not all equal), every count the lease's sample count; for an
/// EMIS lease that collects moments, followed by pilot data of the job's size (every
/// candidate's moment sums, statistics and guides, as a real worker sends them).
pub fn build_result(worker_id: &str, lease: &pb::TileLease) -> SimResult {
    let r = lease.rect.unwrap_or_default();
    let (w, h) = (r.x1.saturating_sub(r.x0), r.y1.saturating_sub(r.y0));
    let n = lease.sample_end.saturating_sub(lease.sample_begin);
    let pixels = w as usize * h as usize;
    let mut sum = Vec::with_capacity(pixels);
    for y in r.y0..r.y1 {
        for x in r.x0..r.x1 {
            let v = n as f64 * (0.25 + 0.5 * ((x as f64 * 0.07).sin() * (y as f64 * 0.05).cos()).abs());
            sum.push([v, 0.8 * v, 0.6 * v]);
        }
    }
    let count = vec![n; pixels];
    let mut payload = Vec::with_capacity(pixels * BOX_BYTES_PER_PIXEL);
    tessera_link::payload::write_channels(&mut payload, &sum, None, None, &count)
        .expect("invariant: writing into a Vec cannot fail");
    let pilot = pilot_data(lease, w, h, n);
    payload.extend_from_slice(&pilot);
    SimResult { header: tessera_proto::result_header(worker_id, lease, 0, 0.0, pilot.len() as u64), payload }
}

/// Encoded pilot data for an EMIS lease that collects moments (empty otherwise).
fn pilot_data(lease: &pb::TileLease, width: u32, height: u32, iterations: u32) -> Vec<u8> {
    use tessera_common::emis::cost::StatisticsSums;
    use tessera_common::emis::guides::GuideBuffer;
    use tessera_common::emis::moments::MomentBuffer;
    use tessera_common::emis::{self, PilotData};
    let samples = lease.sample_begin..lease.sample_end;
    let collects =
        |s: &pb::TileStrategy| s.collect_moments && emis::collects_moments(s.light_paths_per_pixel, &samples);
    if !lease.strategy.as_ref().is_some_and(collects) {
        return Vec::new();
    }
    let Some(settings) = lease.settings.as_ref().and_then(|s| tessera_link::convert::settings_from_pb(s).ok()) else {
        return Vec::new();
    };
    let candidates = settings.emis_config().candidates.candidates();
    let mut moments = MomentBuffer::new(width, height, candidates.len());
    moments.iterations = iterations;
    // path tracing noisier than every bidirectional candidate: updates keep light paths, so
    // that every collecting tile carries moments, as in a scene where VCM wins
    for (i, m) in moments.sums.iter_mut().enumerate() {
        let pt = candidates[i % candidates.len()].nu == 0.0;
        *m = if pt { 100.0 } else { (i % 97) as f32 * 0.01 };
    }
    let mut guides = GuideBuffer::new(width, height);
    guides.samples = iterations;
    let statistics = StatisticsSums {
        iterations: iterations as u64,
        camera_vertices: 3 * (width * height) as u64 * iterations as u64,
        light_paths: (width * height) as u64 * iterations as u64,
        light_vertices: 4 * (width * height) as u64 * iterations as u64,
        ..Default::default()
    };
    PilotData { moments, statistics, guides }.encode()
}

/// The upload stream of `r`, cut as the real worker cuts it.
pub fn upload_messages(r: &SimResult) -> Vec<pb::UploadResultRequest> {
    use pb::upload_result_request::Part;
    let mut messages = vec![pb::UploadResultRequest { part: Some(Part::Header(r.header.clone())) }];
    messages.extend(
        r.payload
            .chunks(tessera_proto::CHUNK_BYTES)
            .map(|c| pb::UploadResultRequest { part: Some(Part::Data(c.to_vec().into())) }),
    );
    messages
}

/// A worker-service client on its own connection, as a real worker has.
pub async fn connect_worker(url: &str) -> anyhow::Result<WorkerServiceClient<Channel>> {
    let channel = tonic::transport::Endpoint::from_shared(url.to_string())?
        .tcp_nodelay(true)
        .connect()
        .await
        .with_context(|| format!("connect {url}"))?;
    Ok(WorkerServiceClient::new(channel)
        .max_decoding_message_size(tessera_proto::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES))
}

/// Registers a simulated worker; returns its id.
pub async fn register(client: &mut WorkerServiceClient<Channel>, name: &str) -> anyhow::Result<String> {
    let req = pb::RegisterRequest { name: name.into(), threads: 1, ..tessera_link::build::registration() };
    Ok(client.register(req).await?.into_inner().worker_id)
}

/// One accepted upload.
struct Sample {
    /// Response time since the start.
    at_s: f64,
    latency_s: f64,
    bytes: usize,
    /// Iterations the tile covers.
    iterations: u32,
    /// Pixels of the tile.
    pixels: u64,
}

/// Leases and uploads until `stop` is set and no work is left; returns accepted uploads and
/// the number of uploads that were not accepted.
async fn sim_worker(
    mut client: WorkerServiceClient<Channel>,
    worker: String,
    batch: u32,
    start: Arc<tokio::sync::Barrier>,
    stop: Arc<AtomicBool>,
) -> anyhow::Result<(Vec<Sample>, u64)> {
    start.wait().await;
    let t0 = Instant::now();
    let (mut samples, mut refused) = (Vec::new(), 0);
    loop {
        let req = pb::LeaseTileRequest { worker_id: worker.clone(), max_tiles: batch, wait_ms: 200 };
        let leases = client.lease_tile(req).await?.into_inner().leases;
        if leases.is_empty() && stop.load(Ordering::Relaxed) {
            return Ok((samples, refused));
        }
        for lease in &leases {
            let result = build_result(&worker, lease);
            let bytes = result.payload.len();
            let iterations = lease.sample_end.saturating_sub(lease.sample_begin);
            let r = lease.rect.unwrap_or_default();
            let pixels = r.x1.saturating_sub(r.x0) as u64 * r.y1.saturating_sub(r.y0) as u64;
            let sent = Instant::now();
            let outcome = client.upload_result(tokio_stream::iter(upload_messages(&result))).await;
            let latency_s = sent.elapsed().as_secs_f64();
            match outcome {
                Ok(r) if r.get_ref().outcome == pb::UploadOutcome::Accepted as i32 => {
                    samples.push(Sample { at_s: t0.elapsed().as_secs_f64(), latency_s, bytes, iterations, pixels })
                }
                Ok(_) => refused += 1,
                Err(s) if s.code() == tonic::Code::InvalidArgument => {
                    bail!("the coordinator refused a generated result: {}", s.message())
                }
                Err(s) => return Err(s.into()),
            }
        }
    }
}

/// What one ingest case measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct IngestReport {
    /// Which case.
    pub case: String,
    /// Pixels per tile.
    pub tile_pixels: u64,
    /// Accepted uploads.
    pub tiles: u64,
    /// Uploads not accepted (stale or duplicate); should be 0.
    pub not_accepted: u64,
    /// The window: from the first lease until [`STEADY_FRACTION`] of the tiles were accepted.
    pub seconds: f64,
    /// From the end of the window until every job was done (the last tiles and the outputs).
    pub finish_s: f64,
    /// Coordinator CPU seconds in that time.
    pub finish_cpu_s: f64,
    /// `tiles / seconds`.
    pub tiles_per_s: f64,
    /// Median over whole seconds of the run (steady state, without job start and end).
    pub tiles_per_s_median_second: f64,
    /// Payload megabytes (10^6) per second.
    pub mb_per_s: f64,
    /// Upload-to-response latency percentiles.
    pub latency_p50_ms: f64,
    /// 99th percentile.
    pub latency_p99_ms: f64,
    /// Coordinator user + system CPU seconds during the run.
    pub coordinator_cpu_s: f64,
    /// `coordinator_cpu_s / seconds`: cores used.
    pub coordinator_cores: f64,
    /// Tiles per coordinator CPU-second: the rate one fully used core sustains.
    pub tiles_per_cpu_s: f64,
    /// Iterations (summed over the tiles) per coordinator CPU-second: for full-frame tiles
    /// of several iterations, the frames one core takes in.
    pub iterations_per_cpu_s: f64,
    /// Payload bytes per pixel per iteration.
    pub bytes_per_pixel_iteration: f64,
    /// `GET /healthz` latency while the case ran, 99th percentile and worst (see `probe.rs`).
    pub healthz_p99_ms: f64,
    /// Worst `/healthz` latency.
    pub healthz_max_ms: f64,
    /// Mean upload-to-response latency.
    pub latency_mean_ms: f64,
    /// CPU cores the load generator (this process) used meanwhile.
    pub generator_cores: f64,
}

/// The measurement window ends when this fraction of all tiles is accepted, so that it holds
/// the steady state (checkpoints included) but not the job's end (its last tiles trickle in,
/// and its outputs are encoded), which is reported separately.
pub const STEADY_FRACTION: f64 = 0.95;

/// Polls the jobs until [`STEADY_FRACTION`] of their tiles are done, then until all are done;
/// returns the seconds and coordinator CPU seconds since `t0` at both moments.
async fn watch(
    serve: &ServeProcess,
    client: &mut super::JobClient,
    ids: &[String],
    t0: Instant,
) -> anyhow::Result<[(f64, f64); 2]> {
    let mut steady = None;
    loop {
        let (mut done, mut total, mut finished) = (0, 0, true);
        for id in ids {
            let j = client.get_job(pb::GetJobRequest { id: id.clone() }).await?.into_inner();
            if j.state == pb::JobState::Failed as i32 || j.state == pb::JobState::Cancelled as i32 {
                bail!("job {id} ended as {}: {}", tessera_proto::state_name(j.state), j.error.unwrap_or_default());
            }
            (done, total) = (done + j.tiles_done, total + j.tiles_total);
            finished &= j.state == pb::JobState::Done as i32;
        }
        let now = (t0.elapsed().as_secs_f64(), serve.cpu_seconds()?);
        if steady.is_none() && done as f64 >= STEADY_FRACTION * total as f64 {
            steady = Some(now);
        }
        if finished {
            return Ok([steady.unwrap_or(now), now]);
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
}

/// Runs one case: submits `jobs`, lets `workers` simulated workers drain them.
pub async fn run_case(
    serve: &ServeProcess,
    case: &str,
    jobs: Vec<pb::SubmitJobRequest>,
    workers: usize,
    batch: u32,
) -> anyhow::Result<IngestReport> {
    let mut client = job_client(&serve.url).await?;
    let mut ids = Vec::new();
    for job in jobs {
        ids.push(client.submit_job(job).await.context("submit")?.into_inner().id);
    }
    let start = Arc::new(tokio::sync::Barrier::new(workers + 1));
    let stop = Arc::new(AtomicBool::new(false));
    let mut tasks = Vec::new();
    for i in 0..workers {
        let mut c = connect_worker(&serve.url).await?;
        let id = register(&mut c, &format!("sim-{i}")).await?;
        tasks.push(tokio::spawn(sim_worker(c, id, batch, start.clone(), stop.clone())));
    }
    let probe = tokio::spawn(super::probe::healthz(serve.url.clone(), stop.clone()));
    start.wait().await;
    let (t0, cpu0, gen0) = (Instant::now(), serve.cpu_seconds()?, crate::bench::cpu_seconds());
    let [(seconds, cpu1), (end, cpu2)] = watch(serve, &mut client, &ids, t0).await?;
    let generator_cores = (crate::bench::cpu_seconds() - gen0) / end;
    stop.store(true, Ordering::Relaxed);
    let mut healthz = probe.await?;
    healthz.sort_by(f64::total_cmp);
    let (mut samples, mut not_accepted) = (Vec::new(), 0);
    for t in tasks {
        let (s, r) = t.await??;
        samples.extend(s.into_iter().filter(|s| s.at_s <= seconds));
        not_accepted += r;
    }
    let report = summarise(case, &samples, not_accepted, seconds, cpu1 - cpu0);
    Ok(IngestReport {
        generator_cores,
        finish_s: end - seconds,
        finish_cpu_s: cpu2 - cpu1,
        healthz_p99_ms: quantile(&healthz, 0.99),
        healthz_max_ms: healthz.last().copied().unwrap_or(0.0),
        ..report
    })
}

fn summarise(case: &str, samples: &[Sample], not_accepted: u64, seconds: f64, cpu: f64) -> IngestReport {
    let tiles = samples.len() as u64;
    let bytes: usize = samples.iter().map(|s| s.bytes).sum();
    let iterations: u64 = samples.iter().map(|s| s.iterations as u64).sum();
    let pixel_iterations: u64 = samples.iter().map(|s| s.iterations as u64 * s.pixels).sum();
    let mut lat: Vec<f64> = samples.iter().map(|s| s.latency_s * 1e3).collect();
    lat.sort_by(f64::total_cmp);
    let whole = seconds.floor() as usize;
    let mut per_second = vec![0.0; whole];
    for s in samples {
        if let Some(b) = per_second.get_mut(s.at_s as usize) {
            *b += 1.0;
        }
    }
    per_second.sort_by(f64::total_cmp);
    IngestReport {
        case: case.into(),
        tile_pixels: samples.first().map_or(0, |s| s.pixels),
        tiles,
        not_accepted,
        seconds,
        tiles_per_s: tiles as f64 / seconds,
        tiles_per_s_median_second: quantile(&per_second, 0.5),
        mb_per_s: bytes as f64 / seconds / 1e6,
        latency_p50_ms: quantile(&lat, 0.5),
        latency_p99_ms: quantile(&lat, 0.99),
        coordinator_cpu_s: cpu,
        coordinator_cores: cpu / seconds,
        tiles_per_cpu_s: tiles as f64 / cpu.max(1e-9),
        iterations_per_cpu_s: iterations as f64 / cpu.max(1e-9),
        bytes_per_pixel_iteration: bytes as f64 / pixel_iterations.max(1) as f64,
        healthz_p99_ms: 0.0,
        healthz_max_ms: 0.0,
        finish_s: 0.0,
        finish_cpu_s: 0.0,
        latency_mean_ms: lat.iter().sum::<f64>() / lat.len().max(1) as f64,
        generator_cores: 0.0,
    }
}

fn print_report(r: &IngestReport, json: bool) {
    println!(
        "{:<28} {:>6} tiles {:>6.1} s {:>6.0} tiles/s (median 1-s {:>5.0}) {:>6.1} MB/s  latency p50 {:>5.2} p99 {:>7.2} mean {:>6.2} ms  coordinator {:>4.2} cores {:>5.0} tiles/cpu-s  generator {:>4.2} cores{}",
        r.case,
        r.tiles,
        r.seconds,
        r.tiles_per_s,
        r.tiles_per_s_median_second,
        r.mb_per_s,
        r.latency_p50_ms,
        r.latency_p99_ms,
        r.latency_mean_ms,
        r.coordinator_cores,
        r.tiles_per_cpu_s,
        r.generator_cores,
        if r.not_accepted > 0 { format!(", {} not accepted", r.not_accepted) } else { String::new() }
    );
    println!(
        "{:<28} {:.0} iterations/cpu-s, {:.1} bytes per pixel per iteration",
        "", r.iterations_per_cpu_s, r.bytes_per_pixel_iteration
    );
    println!(
        "{:<28} then {:.2} s ({:.2} coordinator CPU-s) for the last {:.0} % of the tiles and the outputs; /healthz p99 {:.1} ms, worst {:.1} ms",
        "",
        r.finish_s,
        r.finish_cpu_s,
        (1.0 - STEADY_FRACTION) * 100.0,
        r.healthz_p99_ms,
        r.healthz_max_ms
    );
    if json {
        println!("{}", serde_json::json!(r));
    }
}

/// Runs the ingest cases (64×64 pt tiles, full-frame vcm iterations) and reports them with
/// the number of real workers one coordinator core feeds.
pub fn ingest_command(args: &FarmArgs) -> anyhow::Result<()> {
    let times = super::calibrate::measure(&args.scene)?;
    let cpus = all_cpus();
    let pin = args.pin == crate::options::Switch::On && cpus.len() > 1;
    if pin {
        pin_current_thread(&cpus[1..])?;
    }
    let reports = tokio::runtime::Builder::new_multi_thread().enable_all().build()?.block_on(async {
        let (w, h) = args.pt_frame;
        let jobs = (0..args.pt_jobs).map(|i| generated_job(IntegratorName::Pt, w, h, 1, &format!("ingest-pt-{i}")));
        let serve = ServeProcess::start(pin.then_some(0))?;
        let pt = run_case(
            &serve,
            &format!("pt 64x64, {w}x{h} x{}", args.pt_jobs),
            jobs.collect(),
            args.workers,
            args.lease_batch,
        )
        .await?;
        drop(serve);
        let (w, h) = args.vcm_frame;
        let job = generated_job(IntegratorName::Vcm, w, h, args.vcm_iterations, "ingest-vcm");
        let serve = ServeProcess::start(pin.then_some(0))?;
        let vcm = run_case(&serve, &format!("vcm full frame {w}x{h}"), vec![job], args.workers, 1).await?;
        drop(serve);
        // EMIS: the same frames with every candidate's moments (updates after 1 and n - 1
        // iterations, so all but the last tile carry moment buffers)
        let n = args.vcm_iterations.max(3);
        let mut job = generated_job(IntegratorName::EmisVcm, w, h, n, "ingest-emis");
        if let Some(s) = job.settings.as_mut() {
            s.emis_updates = Some(pb::EmisUpdates { iterations: vec![1, n - 1] });
        }
        let serve = ServeProcess::start(pin.then_some(0))?;
        let emis =
            run_case(&serve, &format!("emis-vcm full frame {w}x{h} with moments"), vec![job], args.workers, 1).await?;
        anyhow::Ok(([pt, vcm], emis))
    });
    if pin {
        pin_current_thread(&cpus)?;
    }
    let (reports, emis) = reports?;
    println!(
        "ingest: {} simulated workers, lease batch {} (pt), coordinator {}",
        args.workers,
        args.lease_batch,
        if pin { "pinned to CPU 0, generator on the others" } else { "not pinned" }
    );
    for r in reports.iter().chain([&emis]) {
        print_report(r, args.json);
    }
    print_feeding(&reports, &times);
    println!(
        "emis-vcm pilot: one coordinator core feeds {:.0} worker threads ({:.1} iterations per upload)",
        emis.iterations_per_cpu_s * times.vcm_iteration_s,
        emis.iterations_per_cpu_s / emis.tiles_per_cpu_s.max(1e-9)
    );
    Ok(())
}

/// How many real workers the measured rates feed, from the calibrated tile render times.
fn print_feeding(reports: &[IngestReport; 2], t: &TileTimes) {
    let [pt, vcm] = reports;
    println!(
        "worker tile times ({}, 1 thread): 64x64 pt tile at {} spp {:.3} s ({:.2} M samples/s); {}x{} vcm iteration {:.3} s",
        t.scene,
        t.pt_spp,
        t.pt_tile_s,
        t.samples_per_s / 1e6,
        t.width,
        t.height,
        t.vcm_iteration_s
    );
    let feed = |rate: f64, tile_s: f64| rate * tile_s;
    println!(
        "one coordinator core feeds: pt {:.0} worker threads at {} spp ({:.1} per spp of the job); vcm {:.0} worker threads",
        feed(pt.tiles_per_cpu_s, pt_tile_seconds(t, t.pt_spp)),
        t.pt_spp,
        feed(pt.tiles_per_cpu_s, pt_tile_seconds(t, 1)),
        feed(vcm.tiles_per_cpu_s, t.vcm_iteration_s),
    );
    println!(
        "at the measured wall rates: pt {:.0}, vcm {:.0} worker threads",
        feed(pt.tiles_per_s, pt_tile_seconds(t, t.pt_spp)),
        feed(vcm.tiles_per_s, t.vcm_iteration_s)
    );
    // a small frame's few tiles measure the start-up, not the steady ingest the target is about
    let target = if pt.tiles < TARGET_MIN_TILES {
        format!("not judged on {} tiles (judge it on a large frame: --pt-frame 7680x4320)", pt.tiles)
    } else if pt.tiles_per_cpu_s >= 1000.0 {
        "met".to_string()
    } else {
        "MISSED".to_string()
    };
    println!(
        "target >= 1000 64x64 tiles/s on one core: {target} ({:.0} tiles per coordinator CPU-second)",
        pt.tiles_per_cpu_s
    );
}

/// Fewest pt tiles the ingest target is judged on: fewer tiles are few large frames, whose
/// rate says little of the per-tile cost (an 8K frame has 8160).
const TARGET_MIN_TILES: u64 = 1000;

/// Seconds one thread needs for a 64×64 pt tile at `spp`.
fn pt_tile_seconds(t: &TileTimes, spp: u32) -> f64 {
    64.0 * 64.0 * spp as f64 / t.samples_per_s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::grpc::convert::{grant_to_pb, lease_from_pb, rect_from_pb, settings_from_pb};
    use crate::serve::job::model::{JobState, ResultOutcome};
    use crate::serve::job::service::{Bundle, DEFAULT_MAX_PIXELS, JobService, ServiceConfig};
    use crate::serve::job::validate::ResultClaim;

    /// Drains a generated job through the service with generated results; every one must be
    /// accepted and the job must finish.
    fn drain_with_generated_results(integrator: IntegratorName, width: u32, height: u32, spp: u32) -> usize {
        let dir = tempfile::tempdir().unwrap();
        let cfg = ServiceConfig {
            lease_timeout_ms: 60_000,
            lease_lifetime: crate::serve::job::service::LeaseLifetime { floor_ms: 600_000, factor: 8.0 },
            checkpoint_interval_ms: 0,
            scene_limits: Default::default(),
            work_limits: Default::default(),
            max_pixels: DEFAULT_MAX_PIXELS,
            max_tiles: u64::MAX,
            retain_finished_ms: None,
            result_file_bytes: crate::serve::storage::blobs::RESULT_FILE_BYTES,
            max_workers: crate::serve::job::service::DEFAULT_MAX_WORKERS,
            forget_workers_ms: 3_600_000,
            min_free_bytes: 0,
        };
        let svc = JobService::open(dir.path(), cfg, 0).unwrap();
        let req = generated_job(integrator, width, height, spp, "t");
        let b = req.bundle.unwrap();
        let bundle = Bundle {
            scene_path: b.scene_path,
            files: b.files.into_iter().map(|f| (f.path, f.data.to_vec())).collect(),
        };
        let job = svc.submit(bundle, settings_from_pb(req.settings).unwrap(), 0, None, 1).unwrap();
        assert_eq!((job.width, job.height), (width, height), "the -D size overrides reach the scene");
        let worker = svc.register("sim", 1, &[], None, None, 1).unwrap();
        let mut tiles = 0;
        loop {
            let grants = svc.lease(&worker, 3, 2).unwrap();
            if grants.is_empty() {
                break;
            }
            for g in grants {
                let r = build_result(&worker, &grant_to_pb(&g));
                let h = r.header;
                let claim = ResultClaim {
                    rect: rect_from_pb(h.rect).unwrap(),
                    samples: h.sample_begin..h.sample_end,
                    non_finite: h.non_finite,
                    pilot_bytes: h.pilot_bytes,
                };
                let lease = lease_from_pb(h.lease).unwrap();
                assert_eq!(svc.upload(&worker, &lease, &claim, r.payload.clone(), 3).unwrap(), ResultOutcome::Accepted);
                tiles += 1;
            }
        }
        assert_eq!(svc.get(&job.id, 4).unwrap().state, JobState::Done);
        tiles
    }

    #[test]
    fn loadgen_pt_results_are_accepted_including_partial_edge_tiles() {
        assert_eq!(drain_with_generated_results(IntegratorName::Pt, 130, 70, 3), 3 * 2);
    }

    #[test]
    fn loadgen_full_frame_vcm_results_are_accepted() {
        assert_eq!(drain_with_generated_results(IntegratorName::Vcm, 40, 30, 3), 3);
    }

    /// The pilot data the generator appends to EMIS results is accepted, the coordinator
    /// optimises on it at the barriers (1, 4) and the job finishes.
    #[test]
    fn loadgen_emis_results_with_moments_are_accepted() {
        // tiles: the pilot, then iterations 1..4 as one (the generated moments make path
        // tracing the worst candidate, so the update keeps light paths and every iteration
        // records), then 4..6 as one final tile
        assert_eq!(drain_with_generated_results(IntegratorName::EmisVcm, 40, 30, 6), 3);
    }
}
