//! `tessera.v1.JobService`: decode → call the [`JobService`](crate::serve::job::service::JobService)
//! → encode.

use super::convert::{job_to_pb, settings_from_pb};
use crate::serve::job::service::OutputKind;
use crate::serve::state::{AppState, blocking, now_ms};
use std::pin::Pin;
use std::sync::Arc;
use tessera_proto::v1 as pb;
use tokio_stream::Stream;
use tonic::{Request, Response, Status};

/// The service implementation.
pub struct JobApi(pub Arc<AppState>);

type BoxStream<T> = Pin<Box<dyn Stream<Item = Result<T, Status>> + Send>>;

#[tonic::async_trait]
impl pb::job_service_server::JobService for JobApi {
    async fn submit_job(&self, req: Request<pb::SubmitJobRequest>) -> Result<Response<pb::Job>, Status> {
        let req = req.into_inner();
        let settings = settings_from_pb(req.settings)?;
        let b = req.bundle.ok_or_else(|| Status::invalid_argument("field \"bundle\" is missing"))?;
        let bundle = tessera_proto::bundle::from_pb(b);
        let svc = self.0.svc.clone();
        let name = Some(req.name);
        let view = blocking(move || svc.submit(bundle, settings, req.priority, name, now_ms())).await?;
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
            Ok(pb::ResultFormat::Exr | pb::ResultFormat::Unspecified) => OutputKind::Exr,
            Err(_) => return Err(Status::invalid_argument(format!("field \"format\": unknown value {}", req.format))),
        };
        let svc = self.0.svc.clone();
        let bytes = blocking(move || svc.output(&req.id, kind)).await?;
        Ok(Response::new(Box::pin(super::chunk_stream(bytes))))
    }
}
