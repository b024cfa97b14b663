//! What the gRPC and REST layers share: the domain service and limits, the clock the pure job
//! model is fed with, and how a synchronous service call runs off the async threads.

pub use super::clock::now_ms;
use super::error::{ApiError, ErrorCode};
use super::events::Hub;
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
    /// The event stream's subscriptions (fed by [`super::events::spawn_publisher`]).
    pub events: Arc<Hub>,
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
        let telemetry = Telemetry::new(svc.clone());
        AppState { telemetry, svc, max_upload_bytes, events: Arc::default(), uploads: Mutex::default() }
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
