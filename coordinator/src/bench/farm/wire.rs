//! Bytes on the wire: a byte-counting TCP proxy between workers and the coordinator, and the
//! `--wire` case, which drives one simulated worker through the proxy one phase at a time
//! (register, lease, fetch the bundle, upload) and compares each phase's measured bytes with
//! what the protocol predicts: the protobuf encoding of every message plus gRPC's 5-byte
//! message prefix. The difference is HTTP/2 (frame headers, HPACK headers, trailers, pings).

use super::loadgen::{build_result, connect_worker, register, upload_messages};
use super::serve::ServeProcess;
use super::{FarmArgs, generated_job, job_client, wait_done};
use anyhow::Context;
use prost::Message;
use std::net::SocketAddr;
use std::os::fd::AsRawFd;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use tessera_common::settings::IntegratorName;
use tessera_proto::v1 as pb;
use tokio::net::{TcpListener, TcpStream};

/// Forwards every connection to a target and counts the bytes each way.
pub struct CountingProxy {
    /// `http://127.0.0.1:PORT` of the proxy.
    pub url: String,
    /// Bytes from clients (workers) to the target.
    pub up: Arc<AtomicU64>,
    /// Bytes from the target to clients.
    pub down: Arc<AtomicU64>,
    accept: tokio::task::JoinHandle<()>,
}

impl CountingProxy {
    /// Listens on a loopback port and forwards to `target_url` (`http://HOST:PORT`).
    pub async fn start(target_url: &str) -> anyhow::Result<CountingProxy> {
        let target: SocketAddr =
            target_url.trim_start_matches("http://").parse().with_context(|| format!("bad address {target_url}"))?;
        let listener = TcpListener::bind("127.0.0.1:0").await?;
        let url = format!("http://{}", listener.local_addr()?);
        let (up, down) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
        let (u, d) = (up.clone(), down.clone());
        let accept = tokio::spawn(async move {
            while let Ok((inbound, _)) = listener.accept().await {
                let Ok(outbound) = TcpStream::connect(target).await else { continue };
                let _ = (inbound.set_nodelay(true), outbound.set_nodelay(true));
                let (a, b) = (Arc::new(inbound), Arc::new(outbound));
                tokio::spawn(pump(a.clone(), b.clone(), u.clone()));
                tokio::spawn(pump(b, a, d.clone()));
            }
        });
        Ok(CountingProxy { url, up, down, accept })
    }

    /// (up, down) bytes so far.
    pub fn bytes(&self) -> (u64, u64) {
        (self.up.load(Ordering::SeqCst), self.down.load(Ordering::SeqCst))
    }
}

impl Drop for CountingProxy {
    fn drop(&mut self) {
        self.accept.abort();
    }
}

/// Copies `from` to `to` until EOF or an error, counting bytes.
async fn pump(from: Arc<TcpStream>, to: Arc<TcpStream>, counter: Arc<AtomicU64>) {
    let mut buf = vec![0u8; 64 << 10];
    loop {
        if from.readable().await.is_err() {
            break;
        }
        let n = match from.try_read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => continue,
            Err(_) => break,
        };
        let mut sent = 0;
        while sent < n {
            if to.writable().await.is_err() {
                return;
            }
            match to.try_write(&buf[sent..n]) {
                Ok(k) => sent += k,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(_) => return,
            }
        }
        counter.fetch_add(n as u64, Ordering::SeqCst);
    }
    // SAFETY: the descriptor is owned by `to`, which outlives this call
    unsafe { libc::shutdown(to.as_raw_fd(), libc::SHUT_WR) };
}

/// Protocol bytes of one gRPC message: its protobuf encoding plus the 5-byte prefix.
pub fn grpc_bytes<M: Message>(m: &M) -> u64 {
    m.encoded_len() as u64 + 5
}

/// One measured phase.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Phase {
    /// What was done.
    pub name: String,
    /// RPCs made.
    pub rpcs: u64,
    /// Pixels the phase concerns (for per-pixel figures).
    pub pixels: u64,
    /// gRPC message bytes (both directions) computed from the messages.
    pub computed: u64,
    /// Bytes counted by the proxy (both directions).
    pub measured: u64,
}

impl Phase {
    fn print(&self) {
        let per_px = |b: u64| match self.pixels {
            0 => "-".to_string(),
            n => format!("{:.4}", b as f64 / n as f64),
        };
        println!(
            "{:<34} {:>4} rpcs {:>10} B computed {:>10} B measured ({:>+6.2} %, {:>5.0} B/rpc HTTP/2) {:>9} B/px computed {:>9} B/px measured",
            self.name,
            self.rpcs,
            self.computed,
            self.measured,
            (self.measured as f64 / self.computed.max(1) as f64 - 1.0) * 100.0,
            (self.measured as f64 - self.computed as f64) / self.rpcs.max(1) as f64,
            per_px(self.computed),
            per_px(self.measured),
        );
    }
}

/// Drives one simulated worker through one job phase by phase.
async fn job_phases(
    serve: &ServeProcess,
    proxy: &CountingProxy,
    job: pb::SubmitJobRequest,
    label: &str,
    batch: u32,
) -> anyhow::Result<Vec<Phase>> {
    let mut jobs = job_client(&serve.url).await?;
    let id = jobs.submit_job(job).await?.into_inner().id;
    let snapshot = || {
        let (u, d) = proxy.bytes();
        u + d
    };
    let mut phases = Vec::new();
    let b0 = snapshot();
    let mut client = connect_worker(&proxy.url).await?;
    let reg = pb::RegisterRequest { name: "wire".into(), threads: 1, ..tessera_link::build::registration() };
    let worker = register(&mut client, "wire").await?;
    let reg_resp =
        pb::RegisterResponse { worker_id: worker.clone(), heartbeat_interval_ms: 7500, lease_timeout_ms: 30000 };
    phases.push(Phase {
        name: format!("{label}: connect + register"),
        rpcs: 1,
        pixels: 0,
        computed: grpc_bytes(&reg) + grpc_bytes(&reg_resp),
        measured: snapshot() - b0,
    });
    let (b0, mut leases, mut computed, mut rpcs) = (snapshot(), Vec::new(), 0, 0);
    loop {
        let req = pb::LeaseTileRequest { worker_id: worker.clone(), max_tiles: batch, wait_ms: 0 };
        let resp = client.lease_tile(req.clone()).await?.into_inner();
        (computed, rpcs) = (computed + grpc_bytes(&req) + grpc_bytes(&resp), rpcs + 1);
        if resp.leases.is_empty() {
            break;
        }
        leases.extend(resp.leases);
    }
    let area = |l: &pb::TileLease| l.rect.map_or(0, |r| (r.x1 - r.x0) as u64 * (r.y1 - r.y0) as u64);
    let pixels: u64 = leases.iter().map(area).sum();
    let measured = snapshot() - b0;
    phases.push(Phase { name: format!("{label}: lease {} tiles", leases.len()), rpcs, pixels, computed, measured });
    let digest = leases.first().context("no tiles leased")?.bundle_digest.clone();
    let b0 = snapshot();
    let req = pb::FetchBlobRequest { digest };
    let mut stream = client.fetch_blob(req.clone()).await?.into_inner();
    let mut computed = grpc_bytes(&req);
    while let Some(chunk) = tokio_stream::StreamExt::next(&mut stream).await {
        computed += grpc_bytes(&chunk?);
    }
    phases.push(Phase { name: format!("{label}: fetch bundle"), rpcs: 1, pixels, computed, measured: snapshot() - b0 });
    let (b0, mut computed) = (snapshot(), 0);
    for lease in &leases {
        let messages = upload_messages(&build_result(&worker, lease));
        computed += messages.iter().map(grpc_bytes).sum::<u64>();
        let resp = client.upload_result(tokio_stream::iter(messages)).await?.into_inner();
        computed += grpc_bytes(&resp);
    }
    let measured = snapshot() - b0;
    phases.push(Phase { name: format!("{label}: upload"), rpcs: leases.len() as u64, pixels, computed, measured });
    wait_done(&mut jobs, &[id], Duration::from_millis(20)).await?;
    Ok(phases)
}

/// Runs `--wire`: a 256×256 pt job (16 tiles of 64×64, leased `--lease-batch` at a time) and a
/// 256×256 vcm job of 4 iterations, each drained by one simulated worker through the proxy.
pub fn wire_command(args: &FarmArgs) -> anyhow::Result<()> {
    let runtime = tokio::runtime::Builder::new_multi_thread().enable_all().build()?;
    let phases = runtime.block_on(async {
        let serve = ServeProcess::start(None)?;
        let proxy = CountingProxy::start(&serve.url).await?;
        let pt = generated_job(IntegratorName::Pt, 256, 256, 16, "wire-pt");
        let mut phases = job_phases(&serve, &proxy, pt, "pt 256x256", args.lease_batch).await?;
        let vcm = generated_job(IntegratorName::Vcm, 256, 256, 4, "wire-vcm");
        phases.extend(job_phases(&serve, &proxy, vcm, "vcm 256x256 x4", 1).await?);
        anyhow::Ok(phases)
    })?;
    println!(
        "wire: one simulated worker through a counting proxy; B/px = bytes per pixel per pass (per iteration for vcm)"
    );
    for p in &phases {
        p.print();
        if args.json {
            println!("{}", serde_json::json!(p));
        }
    }
    Ok(())
}
