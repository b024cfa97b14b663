//! A liveness probe beside the ingest load: `GET /healthz` on a new connection every few
//! milliseconds, as a load balancer or Kubernetes would, to show whether the coordinator's
//! async threads stay free while uploads, merges and EMIS updates run.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tokio::io::{AsyncReadExt, AsyncWriteExt};

/// Time between probes.
const PERIOD: Duration = Duration::from_millis(10);

/// Probes `url`'s `/healthz` until `stop`; returns every answer's latency in milliseconds
/// (a failed probe counts as the time it took to fail).
pub async fn healthz(url: String, stop: Arc<AtomicBool>) -> Vec<f64> {
    let addr = url.trim_start_matches("http://").trim_end_matches('/').to_string();
    let mut latencies = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        let t = Instant::now();
        let _ = once(&addr).await;
        latencies.push(t.elapsed().as_secs_f64() * 1e3);
        tokio::time::sleep(PERIOD).await;
    }
    latencies
}

async fn once(addr: &str) -> std::io::Result<()> {
    let mut s = tokio::net::TcpStream::connect(addr).await?;
    s.write_all(format!("GET /healthz HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n").as_bytes()).await?;
    let mut answer = Vec::new();
    s.read_to_end(&mut answer).await?;
    if answer.starts_with(b"HTTP/1.1 200") { Ok(()) } else { Err(std::io::Error::other("not 200")) }
}
