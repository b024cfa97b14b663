//! `/metrics` in the Prometheus text format (prometheus-client): the service's figures, read at
//! each scrape (jobs per state, queued and leased tiles, live workers, result, lease, sample and
//! failure counters, a series per worker), the build and the process
//! ([`super::metrics_process`]), and latency histograms of the service calls behind the worker
//! API's uploads and leases, which the gRPC layer observes. Per-worker series are bounded by
//! the workers the coordinator keeps (`--max-workers`, `--forget-workers-after`).

use super::clock::now_ms;
use super::job::service::{JobService, WorkerView};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::{Registry, Unit};
use std::sync::Arc;

/// Job states in the order `/metrics` lists them.
const STATES: [&str; 7] = ["queued", "pilot", "optimizing", "final", "done", "failed", "cancelled"];

/// A worker counts as live if it was seen this recently.
const LIVE_WORKER_S: f64 = 60.0;

/// The registry and the histograms the API layers observe.
pub struct Telemetry {
    registry: Registry,
    /// Seconds the service took to validate, store and merge an upload.
    pub upload_seconds: Histogram,
    /// Seconds the service took to grant leases (one long-poll round, without the wait).
    pub lease_seconds: Histogram,
}

impl Telemetry {
    /// A registry reporting `svc`.
    pub fn new(svc: Arc<JobService>) -> Self {
        let mut registry = Registry::default();
        // 0.5 ms .. 16 s: an upload waits for its group commit's fsync; a 4K EMIS update can
        // hold the service for seconds
        let upload_seconds = Histogram::new(exponential_buckets(0.0005, 2.0, 16));
        let lease_seconds = Histogram::new(exponential_buckets(0.0005, 2.0, 16));
        registry.register_with_unit(
            "tessera_upload",
            "Service time of tile result uploads.",
            Unit::Seconds,
            upload_seconds.clone(),
        );
        registry.register_with_unit(
            "tessera_lease",
            "Service time of lease requests.",
            Unit::Seconds,
            lease_seconds.clone(),
        );
        registry.register_collector(Box::new(ServiceCollector(svc)));
        Telemetry { registry, upload_seconds, lease_seconds }
    }

    /// The text exposition of every metric.
    pub fn encode(&self) -> String {
        let mut out = String::new();
        // writing into a String cannot fail
        let _ = prometheus_client::encoding::text::encode(&mut out, &self.registry);
        out
    }
}

/// Reads the service's figures at each scrape.
struct ServiceCollector(Arc<JobService>);

impl std::fmt::Debug for ServiceCollector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ServiceCollector")
    }
}

fn gauge(encoder: &mut DescriptorEncoder, name: &str, help: &str, value: usize) -> Result<(), std::fmt::Error> {
    let metric = ConstGauge::new(value as i64);
    metric.encode(encoder.encode_descriptor(name, help, None, metric.metric_type())?)
}

impl Collector for ServiceCollector {
    fn encode(&self, mut encoder: DescriptorEncoder) -> Result<(), std::fmt::Error> {
        let m = self.0.metrics();
        let workers = self.0.workers(now_ms());
        {
            let mut family = encoder.encode_descriptor(
                "tessera_jobs",
                "Jobs by state.",
                None,
                ConstGauge::new(0i64).metric_type(),
            )?;
            for state in STATES {
                let n = m.jobs_by_state.get(state).copied().unwrap_or(0);
                ConstGauge::new(n as i64).encode(family.encode_family(&[("state", state)])?)?;
            }
        }
        build_info(&mut encoder)?;
        process(&mut encoder)?;
        per_worker(&mut encoder, &workers)?;
        gauge(&mut encoder, "tessera_tiles_queued", "Tiles waiting for a worker (the backlog).", m.tiles_queued)?;
        gauge(&mut encoder, "tessera_tiles_leased", "Tiles leased to workers.", m.tiles_leased)?;
        let live = workers.iter().filter(|w| w.last_seen_s_ago < LIVE_WORKER_S).count();
        gauge(&mut encoder, "tessera_workers", "Workers seen in the last minute.", live)?;
        let c = &m.counters;
        for (name, help, value) in [
            ("tessera_results_accepted", "Tile results accepted.", c.results_accepted),
            ("tessera_results_refused", "Tile results refused by validation.", c.results_refused),
            ("tessera_results_ignored", "Stale or duplicate tile results.", c.results_ignored),
            ("tessera_leases_expired", "Leases that expired.", c.leases_expired),
            ("tessera_coordinator_stalls", "Times the coordinator found itself stalled (leases postponed).", c.stalls),
            ("tessera_tiles_merged", "Tiles merged into films.", c.tiles_merged),
            ("tessera_samples_merged", "Pixel samples merged into films (rate: samples per second).", c.samples_merged),
            ("tessera_tile_failures", "Tiles a worker reported it could not render.", c.tile_failures),
        ] {
            let counter = ConstCounter::new(value);
            counter.encode(encoder.encode_descriptor(name, help, None, counter.metric_type())?)?;
        }
        Ok(())
    }
}

/// `tessera_build_info{version, renderer}` 1: which build serves (workers must match it).
fn build_info(encoder: &mut DescriptorEncoder) -> Result<(), std::fmt::Error> {
    let metric = ConstGauge::new(1i64);
    let mut family = encoder.encode_descriptor(
        "tessera_build_info",
        "This build: version and renderer revision.",
        None,
        metric.metric_type(),
    )?;
    let labels = [("version", env!("CARGO_PKG_VERSION")), ("renderer", tessera_common::RENDERER_REVISION)];
    metric.encode(family.encode_family(&labels)?)
}

/// The `process_*` figures, where `/proc` has them.
fn process(encoder: &mut DescriptorEncoder) -> Result<(), std::fmt::Error> {
    let Some(p) = super::metrics_process::read() else { return Ok(()) };
    let cpu = ConstCounter::new(p.cpu_seconds);
    cpu.encode(encoder.encode_descriptor(
        "process_cpu",
        "User and system CPU time.",
        Some(&Unit::Seconds),
        cpu.metric_type(),
    )?)?;
    let figures = [
        ("process_resident_memory", "Resident memory.", Some(Unit::Bytes), p.resident_bytes as f64),
        ("process_open_fds", "Open file descriptors.", None, p.open_fds as f64),
        ("process_start_time", "Start time since the Unix epoch.", Some(Unit::Seconds), p.start_time_seconds),
    ];
    for (name, help, unit, value) in figures {
        let g = ConstGauge::new(value);
        g.encode(encoder.encode_descriptor(name, help, unit.as_ref(), g.metric_type())?)?;
    }
    Ok(())
}

/// One figure of a worker.
type WorkerFigure = fn(&WorkerView) -> i64;

/// A series per worker the coordinator keeps: its leases, threads and whether it is up.
fn per_worker(encoder: &mut DescriptorEncoder, workers: &[WorkerView]) -> Result<(), std::fmt::Error> {
    let series: [(&str, &str, WorkerFigure); 3] = [
        ("tessera_worker_leases", "Tiles leased to the worker.", |w| w.leases as i64),
        ("tessera_worker_threads", "The worker's render threads.", |w| i64::from(w.threads)),
        ("tessera_worker_up", "1 unless the worker is offline.", |w| i64::from(w.state != "offline")),
    ];
    for (name, help, value) in series {
        let mut family = encoder.encode_descriptor(name, help, None, ConstGauge::new(0i64).metric_type())?;
        for w in workers {
            let labels = [("worker", w.id.as_str()), ("name", w.name.as_str())];
            ConstGauge::new(value(w)).encode(family.encode_family(&labels)?)?;
        }
    }
    Ok(())
}
