//! The gRPC side of the coordinator: `JobService` for clients ([`job_api`]) and
//! `WorkerService` for workers ([`worker_api`]), plus server reflection, as one axum router
//! that `app.rs` merges with the REST API on the same port.

pub mod convert;
pub mod job_api;
pub mod worker_api;

use crate::serve::state::AppState;
use std::sync::Arc;
use tessera_proto::v1::job_service_server::JobServiceServer;
use tessera_proto::v1::worker_service_server::WorkerServiceServer;

/// Both services as an axum router.
pub fn router(state: Arc<AppState>) -> axum::Router {
    // every message is decoded whole in memory before a handler sees it
    let max = state.max_upload_bytes.min(tessera_proto::MAX_INLINE_BUNDLE_BYTES);
    let jobs = JobServiceServer::new(job_api::JobApi(state.clone()))
        .max_decoding_message_size(max)
        .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES);
    let workers = WorkerServiceServer::new(worker_api::WorkerApi(state))
        .max_decoding_message_size(tessera_proto::MAX_WORKER_MESSAGE_BYTES)
        .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES);
    // server reflection (v1 and the v1alpha that older grpcurl builds ask for) describes
    // tessera.v1, so tools can call the services without the .proto files
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(tessera_proto::FILE_DESCRIPTOR_SET)
        .build_v1()
        .expect("invariant: the compiled descriptors are valid");
    let reflection_alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(tessera_proto::FILE_DESCRIPTOR_SET)
        .build_v1alpha()
        .expect("invariant: the compiled descriptors are valid");
    tonic::service::Routes::new(jobs)
        .add_service(workers)
        .add_service(reflection)
        .add_service(reflection_alpha)
        .into_axum_router()
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

/// Streams a blob from disk in [`tessera_proto::CHUNK_BYTES`] chunks, a few chunks ahead of
/// the client at most, hashing as it reads: bytes that no longer match `digest` end the
/// stream with `DATA_LOSS` (a worker checks the digest too, and drops what it got).
pub fn stream_blob(
    file: std::fs::File,
    digest: String,
) -> impl tokio_stream::Stream<Item = Result<tessera_proto::v1::Chunk, tonic::Status>> {
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    tokio::task::spawn_blocking(move || {
        use sha2::Digest;
        use std::io::Read;
        let (mut file, mut hash) = (file, sha2::Sha256::new());
        loop {
            let mut chunk = Vec::with_capacity(tessera_proto::CHUNK_BYTES);
            let read = (&mut file).take(tessera_proto::CHUNK_BYTES as u64).read_to_end(&mut chunk);
            let item = match read {
                Ok(0) if hex::encode(hash.finalize_reset()) == digest => return,
                Ok(0) => Err(tonic::Status::data_loss(format!("blob {digest} is corrupt on disk"))),
                Ok(_) => {
                    hash.update(&chunk);
                    Ok(tessera_proto::v1::Chunk { data: chunk.into() })
                }
                Err(e) => Err(tonic::Status::internal(format!("reading blob {digest}: {e}"))),
            };
            let last = item.is_err();
            if tx.blocking_send(item).is_err() || last {
                return;
            }
        }
    });
    tokio_stream::wrappers::ReceiverStream::new(rx)
}

#[cfg(test)]
mod tests {
    use tokio_stream::StreamExt;

    async fn fetch(bytes: &[u8], digest: &str) -> (Vec<u8>, Option<tonic::Status>) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("blob");
        std::fs::write(&path, bytes).unwrap();
        let mut stream = Box::pin(super::stream_blob(std::fs::File::open(&path).unwrap(), digest.to_string()));
        let (mut got, mut error) = (Vec::new(), None);
        while let Some(item) = stream.next().await {
            match item {
                Ok(chunk) => got.extend_from_slice(&chunk.data),
                Err(e) => error = Some(e),
            }
        }
        (got, error)
    }

    #[tokio::test]
    async fn blobs_stream_in_chunks_and_corruption_ends_the_stream() {
        let bytes: Vec<u8> = (0..(2 * tessera_proto::CHUNK_BYTES + 17)).map(|i| (i % 251) as u8).collect();
        let digest = tessera_proto::blob_digest(&bytes);
        let (got, error) = fetch(&bytes, &digest).await;
        assert!(got == bytes && error.is_none(), "{error:?}");
        let mut corrupt = bytes.clone();
        corrupt[tessera_proto::CHUNK_BYTES + 5] ^= 1;
        let (_, error) = fetch(&corrupt, &digest).await;
        assert_eq!(error.map(|e| e.code()), Some(tonic::Code::DataLoss));
    }
}
