//! The gRPC side of the coordinator: `JobService` for clients ([`job_api`]) and
//! `WorkerService` for workers ([`worker_api`]), as one axum router that `app.rs` merges with
//! the REST API on the same port.

pub mod convert;
pub mod job_api;
pub mod worker_api;

use crate::serve::state::AppState;
use std::sync::Arc;
use tessera_proto::v1::job_service_server::JobServiceServer;
use tessera_proto::v1::worker_service_server::WorkerServiceServer;

/// Both services as an axum router.
pub fn router(state: Arc<AppState>) -> axum::Router {
    let max = state.max_upload_bytes;
    let jobs = JobServiceServer::new(job_api::JobApi(state.clone()))
        .max_decoding_message_size(max)
        .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES);
    let workers = WorkerServiceServer::new(worker_api::WorkerApi(state))
        .max_decoding_message_size(tessera_proto::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES);
    tonic::service::Routes::new(jobs).add_service(workers).into_axum_router()
}

/// Streams `bytes` as chunks.
pub fn chunk_stream(
    bytes: Vec<u8>,
) -> impl tokio_stream::Stream<Item = Result<tessera_proto::v1::Chunk, tonic::Status>> {
    let chunks: Vec<_> = bytes
        .chunks(tessera_proto::CHUNK_BYTES)
        .map(|c| Ok(tessera_proto::v1::Chunk { data: c.to_vec().into() }))
        .collect();
    tokio_stream::iter(chunks)
}
