//! What the gRPC and REST layers share: the domain service and limits, the clock the pure job
//! model is fed with, and how a synchronous service call runs off the async threads.

use super::error::{ApiError, ErrorCode};
use super::job::model::LeaseRef;
use super::job::service::{JobService, ServiceError};
use super::metrics::Telemetry;
use std::collections::HashSet;
use std::sync::{Arc, Mutex};

/// What the API layers share.
pub struct AppState {
    /// The domain service.
    pub svc: Arc<JobService>,
    /// Upload limit in bytes.
    pub max_upload_bytes: usize,
    /// `/metrics` and the latencies the API layers observe.
    pub telemetry: Telemetry,
    /// Leases with an upload stream open: one at a time, since each buffers up to its tile's
    /// result (twenty streams on one lease once held 576 MB).
    uploads: Mutex<HashSet<LeaseRef>>,
}

/// The one upload stream of a lease, closed when dropped.
pub struct UploadSlot<'a> {
    state: &'a AppState,
    lease: LeaseRef,
}

impl Drop for UploadSlot<'_> {
    fn drop(&mut self) {
        self.state.uploads.lock().unwrap_or_else(|p| p.into_inner()).remove(&self.lease);
    }
}

impl AppState {
    /// The state of a coordinator serving `svc`.
    pub fn new(svc: Arc<JobService>, max_upload_bytes: usize) -> Self {
        AppState { telemetry: Telemetry::new(svc.clone()), svc, max_upload_bytes, uploads: Mutex::default() }
    }

    /// The upload slot of `lease`, or an error while another stream holds it.
    pub fn upload_slot(&self, lease: &LeaseRef) -> Result<UploadSlot<'_>, ApiError> {
        if !self.uploads.lock().unwrap_or_else(|p| p.into_inner()).insert(lease.clone()) {
            return Err(ApiError::new(
                ErrorCode::ResourceExhausted,
                format!("an upload for lease {}/{}@{} is already in progress", lease.job, lease.tile, lease.epoch),
            ));
        }
        Ok(UploadSlot { state: self, lease: lease.clone() })
    }
}

/// Milliseconds since the Unix epoch, read once, then advanced by a monotonic clock: the clock
/// the pure model is fed with. Lease deadlines and time budgets must not jump when the wall
/// clock is stepped (NTP, an operator), and times stored for jobs stay close to wall time.
pub fn now_ms() -> u64 {
    use std::sync::OnceLock;
    use std::time::{Instant, SystemTime, UNIX_EPOCH};
    static ANCHOR: OnceLock<(Instant, u64)> = OnceLock::new();
    let (start, wall) = ANCHOR.get_or_init(|| {
        (Instant::now(), SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_millis() as u64))
    });
    wall + start.elapsed().as_millis() as u64
}

/// Runs a synchronous service call on a blocking thread.
pub async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, ServiceError> + Send + 'static,
) -> Result<T, ApiError> {
    match tokio::task::spawn_blocking(f).await {
        Ok(r) => r.map_err(ApiError::from),
        Err(e) => {
            tracing::error!(error = %e, "blocking task failed");
            Err(ApiError::new(ErrorCode::Internal, "internal error (see the coordinator's log)"))
        }
    }
}
