//! Tessera's gRPC protocol, package `tessera.v1`, generated from `proto/tessera/v1/*.proto`.
//!
//! * [`v1::job_service_server`] / [`v1::job_service_client`]: clients submit, watch, cancel jobs
//!   and download results.
//! * [`v1::worker_service_server`] / [`v1::worker_service_client`]: render workers register,
//!   heartbeat, lease tiles (long poll), upload tile sums and fetch scene bundles by digest.
//!
//! The crate holds the generated code plus the constants both ends must agree on. It depends
//! on nothing of Tessera's: conversions to the renderer's types, the payload and bundle codecs
//! and connecting live in `tessera-link`, settings and logging in `tessera-config`.
//!
//! ```no_run
//! use tessera_proto::v1::job_service_client::JobServiceClient;
//! # async fn f() -> Result<(), Box<dyn std::error::Error>> {
//! let mut client = JobServiceClient::connect("http://127.0.0.1:7878").await?;
//! let jobs = client.list_jobs(tessera_proto::v1::ListJobsRequest {}).await?.into_inner();
//! println!("{} jobs", jobs.jobs.len());
//! # Ok(()) }
//! ```

#![deny(missing_docs)]

/// Generated `tessera.v1` messages, clients and servers.
#[allow(missing_docs)]
pub mod v1 {
    tonic::include_proto!("tessera.v1");
}

/// The encoded `FileDescriptorSet` of `tessera.v1`, which the coordinator serves by gRPC server
/// reflection.
pub const FILE_DESCRIPTOR_SET: &[u8] = tonic::include_file_descriptor_set!("tessera_descriptor");

/// Upper bound of the EMIS pilot data per pixel a result may carry (moment sums of up to 64
/// candidates and seven guide channels, all f32); the exact size is checked on decoding.
pub const MAX_PILOT_BYTES_PER_PIXEL: u64 = (64 + 7) * 4;

/// Size of the chunks that byte streams (uploads, blobs, results) are cut into.
pub const CHUNK_BYTES: usize = 1 << 20;

/// Largest gRPC message either side accepts: a chunk plus headers, or an inline scene bundle.
pub const MAX_MESSAGE_BYTES: usize = 1 << 30;

/// Largest message the coordinator accepts from a worker: every one is a chunk of an upload
/// or smaller, so a worker cannot make it buffer more than this per request.
pub const MAX_WORKER_MESSAGE_BYTES: usize = 4 * CHUNK_BYTES;

/// Largest message the coordinator accepts from a client: a `SubmitJob` with its bundle inline
/// (larger bundles go through `SubmitJobStream`, whose parts are chunks).
pub const MAX_INLINE_BUNDLE_BYTES: usize = 64 << 20;

/// The digest that names a blob (scene bundles, merge masks, outputs): the SHA-256 of its
/// bytes in lowercase hex. The coordinator stores blobs under it and workers check what they
/// fetch against it.
pub fn blob_digest(bytes: &[u8]) -> String {
    use sha2::Digest;
    hex::encode(sha2::Sha256::digest(bytes))
}

/// Whether `s` has the form of a [`blob_digest`] (so it is safe as a file name).
pub fn is_blob_digest(s: &str) -> bool {
    s.len() == 64 && s.bytes().all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

/// A job state's lowercase name, as the REST API spells it (`unknown` for values this version
/// does not know).
pub fn state_name(state: i32) -> &'static str {
    use v1::JobState as S;
    match S::try_from(state).unwrap_or(S::Unspecified) {
        S::Queued => "queued",
        S::Pilot => "pilot",
        S::Optimizing => "optimizing",
        S::Final => "final",
        S::Done => "done",
        S::Failed => "failed",
        S::Cancelled => "cancelled",
        S::Paused => "paused",
        S::Blocked => "blocked",
        S::Unspecified => "unknown",
    }
}

/// A request carrying `token` as a bearer token (the coordinator's authentication), or none.
pub fn authorized<T>(message: T, token: Option<&str>) -> tonic::Request<T> {
    let mut req = tonic::Request::new(message);
    if let Some(t) = token
        && let Ok(v) = format!("Bearer {t}").parse()
    {
        req.metadata_mut().insert("authorization", v);
    }
    req
}

/// The header of an upload answering `lease` with exactly the leased rectangle and samples
/// (what an honest worker sends).
pub fn result_header(
    worker_id: &str,
    lease: &v1::TileLease,
    non_finite: u64,
    render_seconds: f64,
    pilot_bytes: u64,
) -> v1::TileResultHeader {
    v1::TileResultHeader {
        worker_id: worker_id.to_string(),
        lease: lease.lease.clone(),
        rect: lease.rect,
        sample_begin: lease.sample_begin,
        sample_end: lease.sample_end,
        non_finite,
        render_seconds,
        pilot_bytes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blob_digests_are_sha256_in_lowercase_hex() {
        let d = blob_digest(b"hello");
        assert_eq!(d, "2cf24dba5fb0a30e26e83b2ac5b9e29e1b161e5c1fa7425e73043362938b9824");
        assert!(is_blob_digest(&d));
        assert!(!is_blob_digest(&d.to_uppercase()) && !is_blob_digest("../x") && !is_blob_digest(&d[1..]));
    }
}
