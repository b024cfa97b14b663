//! A scene bundle arriving in pieces (multipart parts over REST, messages of the gRPC
//! `SubmitJobStream`) fed to a [`BundleUpload`] off the async threads, about a MiB at a time,
//! so that a submission holds at most that much of its bundle in memory.

use crate::serve::error::ApiError;
use crate::serve::job::service::{BundleUpload, JobService, JobView};
use crate::serve::state::{blocking, now_ms};
use std::sync::Arc;
use tessera_common::settings::RenderSettings;

/// Bytes gathered before they are written out.
const FLUSH_BYTES: usize = 1 << 20;

/// A bundle being received; see the module's documentation.
pub struct StreamedBundle {
    svc: Arc<JobService>,
    /// `None` only while a blocking call holds it.
    upload: Option<BundleUpload>,
    pending: Vec<u8>,
}

impl StreamedBundle {
    /// Starts receiving a bundle of at most `limit` bytes of file data.
    pub async fn begin(svc: Arc<JobService>, limit: u64) -> Result<Self, ApiError> {
        let s = svc.clone();
        let upload = blocking(move || s.begin_upload(limit)).await?;
        Ok(StreamedBundle { svc, upload: Some(upload), pending: Vec::new() })
    }

    /// Runs `f` on the upload on a blocking thread. On an error the upload is dropped there
    /// (removing its staging folder) and this bundle is spent.
    async fn with_upload(
        &mut self,
        f: impl FnOnce(&mut BundleUpload) -> Result<(), crate::serve::job::service::ServiceError> + Send + 'static,
    ) -> Result<(), ApiError> {
        let mut upload = self.upload.take().ok_or_else(|| ApiError::from(spent()))?;
        let upload = blocking(move || f(&mut upload).map(|()| upload)).await?;
        self.upload = Some(upload);
        Ok(())
    }

    async fn flush(&mut self) -> Result<(), ApiError> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let data = std::mem::take(&mut self.pending);
        self.with_upload(move |u| u.write(&data)).await
    }

    /// Starts the next file, at `path` in the bundle.
    pub async fn start_file(&mut self, path: String) -> Result<(), ApiError> {
        self.flush().await?;
        self.with_upload(move |u| u.start_file(&path)).await
    }

    /// Appends `data` to the current file.
    pub async fn write(&mut self, mut data: &[u8]) -> Result<(), ApiError> {
        while !data.is_empty() {
            let n = data.len().min(FLUSH_BYTES - self.pending.len());
            self.pending.extend_from_slice(&data[..n]);
            data = &data[n..];
            if self.pending.len() >= FLUSH_BYTES {
                self.flush().await?;
            }
        }
        Ok(())
    }

    /// Submits the job: the bundle's scene is `scene_path`.
    pub async fn submit(
        mut self,
        scene_path: String,
        settings: RenderSettings,
        placement: crate::serve::job::spec::Placement,
        name: Option<String>,
        frames: Option<crate::serve::job::service::FramesRequest>,
    ) -> Result<JobView, ApiError> {
        self.flush().await?;
        let upload = self.upload.take().ok_or_else(|| ApiError::from(spent()))?;
        let svc = self.svc.clone();
        blocking(move || match frames {
            None => svc.submit_upload(upload, &scene_path, settings, placement, name, now_ms()),
            Some(frames) => svc.submit_frames(upload, &scene_path, settings, placement, name, frames, now_ms()),
        })
        .await
    }
}

fn spent() -> crate::serve::job::service::ServiceError {
    crate::serve::job::service::ServiceError::InvalidArgument("the upload failed earlier".into())
}
