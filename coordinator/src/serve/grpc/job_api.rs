//! `tessera.v1.JobService`: decode → call the [`JobService`](crate::serve::job::service::JobService)
//! → encode.

use super::convert::{job_to_pb, settings_from_pb, worker_to_pb};
use crate::serve::bundle_stream::StreamedBundle;
use crate::serve::job::service::{FramesRequest, OutputKind};
use crate::serve::job::spec::Placement;
use crate::serve::state::{AppState, blocking, now_ms};
use crate::serve::storage::WorkerMode;
use std::pin::Pin;
use std::sync::Arc;
use tessera_proto::v1 as pb;
use tokio_stream::Stream;
use tonic::{Request, Response, Status, Streaming};

/// The service implementation.
pub struct JobApi(pub Arc<AppState>);

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

#[tonic::async_trait]
impl pb::job_service_server::JobService for JobApi {
    async fn submit_job(&self, req: Request<pb::SubmitJobRequest>) -> Result<Response<pb::Job>, Status> {
        let req = req.into_inner();
        let settings = settings_from_pb(req.settings)?;
        let b = req.bundle.ok_or_else(|| Status::invalid_argument("field \"bundle\" is missing"))?;
        let mut bundle = StreamedBundle::begin(self.0.svc.clone(), self.0.max_upload_bytes as u64).await?;
        for file in b.files {
            bundle.start_file(file.path).await?;
            bundle.write(&file.data).await?;
        }
        let placement = Placement { priority: req.priority, after: req.after, require_tags: req.require_tags };
        let frames = frames_from_pb(&req.frames, &req.frame_param, (req.seed_per_frame, req.warm_start))?;
        let view = bundle.submit(b.scene_path, settings, placement, Some(req.name), frames).await?;
        Ok(Response::new(job_to_pb(&view)))
    }

    async fn submit_job_stream(&self, req: Request<Streaming<pb::SubmitJobPart>>) -> Result<Response<pb::Job>, Status> {
        let mut parts = req.into_inner();
        let header =
            parts.message().await?.and_then(|p| p.header).ok_or_else(|| {
                Status::invalid_argument("the first part of a streamed submission must carry the header")
            })?;
        let settings = settings_from_pb(header.settings)?;
        let scene_path = header.bundle.map(|b| b.scene_path).unwrap_or_default();
        let mut bundle = StreamedBundle::begin(self.0.svc.clone(), self.0.max_upload_bytes as u64).await?;
        while let Some(part) = parts.message().await? {
            if part.header.is_some() {
                return Err(Status::invalid_argument("a streamed submission carries one header, in its first part"));
            }
            if !part.path.is_empty() {
                bundle.start_file(part.path).await?;
            }
            bundle.write(&part.data).await?;
        }
        let placement = Placement { priority: header.priority, after: header.after, require_tags: header.require_tags };
        let frames = frames_from_pb(&header.frames, &header.frame_param, (header.seed_per_frame, header.warm_start))?;
        let view = bundle.submit(scene_path, settings, placement, Some(header.name), frames).await?;
        Ok(Response::new(job_to_pb(&view)))
    }

    async fn get_job(&self, req: Request<pb::GetJobRequest>) -> Result<Response<pb::Job>, Status> {
        let (svc, id) = (self.0.svc.clone(), req.into_inner().id);
        Ok(Response::new(job_to_pb(&blocking(move || svc.get(&id, now_ms())).await?)))
    }

    async fn list_jobs(&self, _: Request<pb::ListJobsRequest>) -> Result<Response<pb::ListJobsResponse>, Status> {
        let svc = self.0.svc.clone();
        let jobs = blocking(move || svc.list(now_ms())).await?.iter().map(job_to_pb).collect();
        Ok(Response::new(pb::ListJobsResponse { jobs }))
    }

    async fn cancel_job(&self, req: Request<pb::CancelJobRequest>) -> Result<Response<pb::Job>, Status> {
        let (svc, id) = (self.0.svc.clone(), req.into_inner().id);
        Ok(Response::new(job_to_pb(&blocking(move || svc.cancel(&id, now_ms())).await?)))
    }

    async fn pause_job(&self, req: Request<pb::JobRef>) -> Result<Response<pb::Job>, Status> {
        let (svc, id) = (self.0.svc.clone(), req.into_inner().id);
        Ok(Response::new(job_to_pb(&blocking(move || svc.pause(&id, now_ms())).await?)))
    }

    async fn resume_job(&self, req: Request<pb::JobRef>) -> Result<Response<pb::Job>, Status> {
        let (svc, id) = (self.0.svc.clone(), req.into_inner().id);
        Ok(Response::new(job_to_pb(&blocking(move || svc.resume_job(&id, now_ms())).await?)))
    }

    async fn requeue_job(&self, req: Request<pb::JobRef>) -> Result<Response<pb::Job>, Status> {
        let (svc, id) = (self.0.svc.clone(), req.into_inner().id);
        Ok(Response::new(job_to_pb(&blocking(move || svc.requeue(&id, now_ms())).await?)))
    }

    async fn update_job(&self, req: Request<pb::UpdateJobRequest>) -> Result<Response<pb::Job>, Status> {
        let (svc, req) = (self.0.svc.clone(), req.into_inner());
        let view = blocking(move || match req.priority {
            Some(p) => svc.set_priority(&req.id, p, now_ms()),
            None => svc.get(&req.id, now_ms()),
        })
        .await?;
        Ok(Response::new(job_to_pb(&view)))
    }

    async fn list_workers(
        &self,
        _: Request<pb::ListWorkersRequest>,
    ) -> Result<Response<pb::ListWorkersResponse>, Status> {
        let svc = self.0.svc.clone();
        let workers = blocking(move || Ok(svc.workers(now_ms()))).await?;
        Ok(Response::new(pb::ListWorkersResponse { workers: workers.iter().map(worker_to_pb).collect() }))
    }

    async fn disable_worker(&self, req: Request<pb::WorkerRef>) -> Result<Response<pb::Worker>, Status> {
        self.worker_mode(req, WorkerMode::Disabled).await
    }

    async fn enable_worker(&self, req: Request<pb::WorkerRef>) -> Result<Response<pb::Worker>, Status> {
        self.worker_mode(req, WorkerMode::Enabled).await
    }

    async fn drain_worker(&self, req: Request<pb::WorkerRef>) -> Result<Response<pb::Worker>, Status> {
        self.worker_mode(req, WorkerMode::Draining).await
    }

    async fn delete_job(&self, req: Request<pb::DeleteJobRequest>) -> Result<Response<pb::DeleteJobResponse>, Status> {
        let (svc, id) = (self.0.svc.clone(), req.into_inner().id);
        blocking(move || svc.delete(&id)).await?;
        Ok(Response::new(pb::DeleteJobResponse {}))
    }

    type WatchJobStream = BoxStream<pb::Job>;

    async fn watch_job(&self, req: Request<pb::GetJobRequest>) -> Result<Response<Self::WatchJobStream>, Status> {
        let id = req.into_inner().id;
        let svc = self.0.svc.clone();
        let first = {
            let (svc, id) = (svc.clone(), id.clone());
            blocking(move || svc.get(&id, now_ms())).await?
        };
        let mut changes = svc.changed.subscribe();
        let (tx, rx) = tokio::sync::mpsc::channel(16);
        tokio::spawn(async move {
            let mut view = first;
            loop {
                if tx.send(Ok(job_to_pb(&view))).await.is_err() || view.state.is_terminal() {
                    return;
                }
                // wake on changes, and at least every second so the ETA stays fresh
                let _ = tokio::time::timeout(std::time::Duration::from_secs(1), changes.changed()).await;
                let (s, i) = (svc.clone(), id.clone());
                match blocking(move || s.get(&i, now_ms())).await {
                    Ok(v) => view = v,
                    Err(e) => {
                        let _ = tx.send(Err(e.into())).await;
                        return;
                    }
                }
            }
        });
        Ok(Response::new(Box::pin(tokio_stream::wrappers::ReceiverStream::new(rx))))
    }

    type GetResultStream = BoxStream<pb::Chunk>;

    async fn get_result(&self, req: Request<pb::GetResultRequest>) -> Result<Response<Self::GetResultStream>, Status> {
        let req = req.into_inner();
        let kind = match pb::ResultFormat::try_from(req.format) {
            Ok(pb::ResultFormat::Png) => OutputKind::Png,
            Ok(pb::ResultFormat::StrategyPng) => OutputKind::StrategyPng,
            Ok(pb::ResultFormat::EmisJson) => OutputKind::EmisJson,
            Ok(pb::ResultFormat::Exr | pb::ResultFormat::Unspecified) => OutputKind::Exr,
            Err(_) => return Err(Status::invalid_argument(format!("field \"format\": unknown value {}", req.format))),
        };
        let svc = self.0.svc.clone();
        let bytes = blocking(move || svc.output(&req.id, kind)).await?;
        Ok(Response::new(Box::pin(super::chunk_stream(bytes))))
    }
}

impl JobApi {
    async fn worker_mode(&self, req: Request<pb::WorkerRef>, mode: WorkerMode) -> Result<Response<pb::Worker>, Status> {
        let (svc, id) = (self.0.svc.clone(), req.into_inner().id);
        Ok(Response::new(worker_to_pb(&blocking(move || svc.set_worker_mode(&id, mode, now_ms())).await?)))
    }
}

/// A submission's frames, if it asks for any (`frame_param` defaults to `frame`), with its
/// flags `seed_per_frame` and `warm_start`.
fn frames_from_pb(
    frames: &str,
    param: &str,
    (seed_per_frame, warm_start): (bool, bool),
) -> Result<Option<FramesRequest>, Status> {
    if frames.is_empty() {
        if warm_start {
            return Err(Status::invalid_argument("field \"warm_start\" needs \"frames\""));
        }
        return Ok(None);
    }
    let frames =
        tessera_link::frames::parse(frames).map_err(|e| Status::invalid_argument(format!("field \"frames\": {e}")))?;
    let param = if param.is_empty() { "frame".to_string() } else { param.to_string() };
    Ok(Some(FramesRequest { frames, param, seed_per_frame, warm_start }))
}
