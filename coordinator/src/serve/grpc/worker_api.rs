//! `tessera.v1.WorkerService`: registration, heartbeats, long-poll leasing, result upload
//! (client stream) and blob download (server stream).

use super::convert::{grant_to_pb, lease_from_pb, lease_to_pb, rect_from_pb};
use crate::serve::conn::Peer;
use crate::serve::job::model::ResultOutcome;
use crate::serve::job::validate::ResultClaim;
use crate::serve::state::{AppState, blocking, now_ms};
use std::pin::Pin;
use std::sync::Arc;
use std::time::Duration;
use tessera_proto::v1 as pb;
use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};

/// The service implementation.
pub struct WorkerApi(pub Arc<AppState>);

/// The longest build version a worker may send.
const MAX_VERSION_BYTES: usize = 128;

/// Longest long poll.
const MAX_WAIT: Duration = Duration::from_secs(30);

#[tonic::async_trait]
impl pb::worker_service_server::WorkerService for WorkerApi {
    async fn register(&self, req: Request<pb::RegisterRequest>) -> Result<Response<pb::RegisterResponse>, Status> {
        // the address it registers from: failures count against its host too
        let peer = req.extensions().get::<axum::extract::ConnectInfo<Peer>>().map(|c| c.0.addr.ip());
        let req = req.into_inner();
        if req.version.len() > MAX_VERSION_BYTES || req.renderer_revision.len() > MAX_VERSION_BYTES {
            return Err(Status::invalid_argument(format!(
                "fields \"version\" and \"renderer_revision\" are at most {MAX_VERSION_BYTES} bytes"
            )));
        }
        if let Some(why) = tessera_link::build::mismatch(&req) {
            tracing::warn!(name = %req.name, version = %req.version, revision = %req.renderer_revision, "worker of another build refused");
            return Err(Status::failed_precondition(why));
        }
        let svc = self.0.svc.clone();
        let id = blocking(move || {
            let identity = (!req.worker_id.is_empty()).then_some((req.worker_id.as_str(), req.worker_secret.as_str()));
            svc.register(&req.name, req.threads, &req.tags, identity, peer, now_ms())
        })
        .await?;
        let ttl = self.0.svc.lease_timeout_ms();
        Ok(Response::new(pb::RegisterResponse {
            worker_id: id,
            heartbeat_interval_ms: (ttl / 4).max(50) as u32,
            lease_timeout_ms: ttl as u32,
        }))
    }

    async fn heartbeat(&self, req: Request<pb::HeartbeatRequest>) -> Result<Response<pb::HeartbeatResponse>, Status> {
        let req = req.into_inner();
        let leases = req.leases.into_iter().map(|l| lease_from_pb(Some(l))).collect::<Result<Vec<_>, _>>()?;
        let svc = self.0.svc.clone();
        let lost = blocking(move || svc.heartbeat(&req.worker_id, &leases, now_ms())).await?;
        Ok(Response::new(pb::HeartbeatResponse { lost: lost.iter().map(lease_to_pb).collect() }))
    }

    async fn lease_tile(&self, req: Request<pb::LeaseTileRequest>) -> Result<Response<pb::LeaseTileResponse>, Status> {
        let req = req.into_inner();
        let deadline = tokio::time::Instant::now() + Duration::from_millis(req.wait_ms as u64).min(MAX_WAIT);
        let max = req.max_tiles.clamp(1, 256) as usize;
        loop {
            // register interest before looking, so a notification in between is not lost
            let notified = self.0.svc.work.notified();
            tokio::pin!(notified);
            notified.as_mut().enable();
            let started = std::time::Instant::now();
            let (svc, worker) = (self.0.svc.clone(), req.worker_id.clone());
            let grants = blocking(move || svc.lease(&worker, max, now_ms())).await?;
            self.0.telemetry.lease_seconds.observe(started.elapsed().as_secs_f64());
            // a drained worker hears it at once, so that it can stop when it holds nothing
            let drain = grants.is_empty() && self.0.svc.draining(&req.worker_id);
            if !grants.is_empty() || drain || tokio::time::Instant::now() >= deadline {
                let leases = grants.iter().map(grant_to_pb).collect();
                return Ok(Response::new(pb::LeaseTileResponse { leases, drain }));
            }
            let _ = tokio::time::timeout_at(deadline, notified).await;
        }
    }

    async fn upload_result(
        &self,
        req: Request<Streaming<pb::UploadResultRequest>>,
    ) -> Result<Response<pb::UploadResultResponse>, Status> {
        use pb::upload_result_request::Part;
        let mut stream = req.into_inner();
        let header = match stream.next().await {
            Some(Ok(pb::UploadResultRequest { part: Some(Part::Header(h)) })) => h,
            Some(Err(e)) => return Err(e),
            _ => return Err(Status::invalid_argument("the first upload message must be a header")),
        };
        let rect = rect_from_pb(header.rect)?;
        let lease = lease_from_pb(header.lease)?;
        let _slot = self.0.upload_slot(&lease)?;
        // the lease is checked before anything is buffered, and bounds what may arrive: never
        // more than the leased tile can need, whatever rectangle the header claims
        let svc = self.0.svc.clone();
        let (worker, held) = (header.worker_id.clone(), lease.clone());
        let Some((leased, result_bytes)) = blocking(move || Ok(svc.upload_limit(&worker, &held))).await? else {
            let message = "lease no longer current".to_string();
            return Ok(Response::new(pb::UploadResultResponse { outcome: pb::UploadOutcome::Stale as i32, message }));
        };
        let pilot_limit = leased.area() as u64 * tessera_proto::MAX_PILOT_BYTES_PER_PIXEL + 4096;
        if header.pilot_bytes > pilot_limit {
            return Err(Status::invalid_argument(format!(
                "field \"pilot_bytes\" ({}) exceeds {pilot_limit} for the leased {leased:?}",
                header.pilot_bytes
            )));
        }
        let limit = result_bytes + header.pilot_bytes as usize;
        let mut payload = Vec::with_capacity(limit.min(1 << 28));
        while let Some(msg) = stream.next().await {
            match msg?.part {
                Some(Part::Data(d)) => {
                    if payload.len() + d.len() > limit {
                        return Err(Status::invalid_argument(format!(
                            "result payload exceeds {limit} bytes for {rect:?}"
                        )));
                    }
                    payload.extend_from_slice(&d);
                }
                _ => return Err(Status::invalid_argument("only data may follow the upload header")),
            }
        }
        let claim = ResultClaim {
            rect,
            samples: header.sample_begin..header.sample_end,
            non_finite: header.non_finite,
            pilot_bytes: header.pilot_bytes,
        };
        let svc = self.0.svc.clone();
        let worker = header.worker_id;
        let started = std::time::Instant::now();
        let outcome = blocking(move || svc.upload(&worker, &lease, &claim, payload, now_ms())).await?;
        self.0.telemetry.upload_seconds.observe(started.elapsed().as_secs_f64());
        let (outcome, message) = match outcome {
            ResultOutcome::Accepted => (pb::UploadOutcome::Accepted, "accepted"),
            ResultOutcome::Duplicate => (pb::UploadOutcome::Duplicate, "already accepted"),
            ResultOutcome::Stale | ResultOutcome::Refused(_) => (pb::UploadOutcome::Stale, "lease no longer current"),
        };
        Ok(Response::new(pb::UploadResultResponse { outcome: outcome as i32, message: message.into() }))
    }

    async fn report_failure(
        &self,
        req: Request<pb::ReportFailureRequest>,
    ) -> Result<Response<pb::ReportFailureResponse>, Status> {
        let req = req.into_inner();
        let lease = lease_from_pb(req.lease)?;
        let svc = self.0.svc.clone();
        blocking(move || svc.report_failure(&req.worker_id, &lease, &req.message, now_ms())).await?;
        Ok(Response::new(pb::ReportFailureResponse {}))
    }

    type FetchBlobStream = Pin<Box<dyn Stream<Item = Result<pb::Chunk, Status>> + Send>>;

    async fn fetch_blob(&self, req: Request<pb::FetchBlobRequest>) -> Result<Response<Self::FetchBlobStream>, Status> {
        let svc = self.0.svc.clone();
        let digest = req.into_inner().digest;
        let d = digest.clone();
        let file = blocking(move || svc.blob_file(&d)).await?;
        Ok(Response::new(Box::pin(super::stream_blob(file, digest))))
    }
}
