//! `tessera submit`: packs a scene and every file it references into a bundle, submits it,
//! and with `--wait` follows the job with a progress bar and writes the result EXR and PNG (and
//! for EMIS the strategy PNG and JSON report), named as `tessera render` names them.

use super::client::{Client, ServerArgs, runtime, status_error};
use crate::options::{JobArgs, scene_name};
use crate::output::OutputPaths;
use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use tessera_common::settings::IntegratorName;
use tessera_proto::state_name;
use tessera_proto::v1 as pb;
use tokio_stream::StreamExt;
use tonic::Code;

/// Arguments of `tessera submit`.
#[derive(clap::Args, Debug, Clone)]
pub struct SubmitArgs {
    /// The Mitsuba 3 scene file; every file it references is uploaded with it.
    pub scene: PathBuf,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
    /// Integrator, samples or time, seed, options and scene parameters.
    #[command(flatten)]
    pub job: JobArgs,
    /// Higher priorities run first.
    #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
    pub priority: i32,
    /// Job name [default: the scene's name].
    #[arg(long)]
    pub name: Option<String>,
    /// Wait for the job, showing progress, and download the result.
    #[arg(long)]
    pub wait: bool,
    /// Where --wait writes the EXR (a PNG goes beside it, and for EMIS NAME.strategy.png and
    /// NAME.emis.json; a NAME.png names the PNG, and the EXR goes to NAME.exr) [default: the
    /// scene's name].
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// Runs `tessera submit`.
pub fn submit_command(args: &SubmitArgs) -> anyhow::Result<()> {
    let settings = args.job.settings()?;
    let bundle = tessera_common::bundle::pack(&args.scene, &settings.define_map())?;
    let output = OutputPaths::new(
        &args.output.clone().unwrap_or_else(|| PathBuf::from(format!("{}.exr", scene_name(&args.scene)))),
    );
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let header = pb::SubmitJobRequest {
            settings: Some(tessera_link::convert::settings_to_pb(&settings)),
            bundle: Some(pb::SceneBundle { scene_path: bundle.scene_path.clone(), files: vec![] }),
            priority: args.priority,
            name: args.name.clone().unwrap_or_else(|| scene_name(&args.scene)),
        };
        let parts = tokio_stream::iter(submission_parts(header, bundle));
        let job = c.jobs.submit_job_stream(c.request(parts)).await.map_err(status_error)?.into_inner();
        println!("{}", job.id);
        if !args.wait {
            return Ok(());
        }
        let last = follow(&mut c, &job.id).await?;
        if last.state != pb::JobState::Done as i32 {
            bail!(
                "job {} {}{}",
                last.id,
                state_name(last.state),
                last.error.map(|e| format!(": {e}")).unwrap_or_default()
            );
        }
        download(&mut c, &job.id, pb::ResultFormat::Exr, &output.exr).await?;
        download(&mut c, &job.id, pb::ResultFormat::Png, &output.png).await?;
        if is_emis(&last) {
            for (format, path) in
                [(pb::ResultFormat::StrategyPng, &output.strategy_png), (pb::ResultFormat::EmisJson, &output.emis_json)]
            {
                // a coordinator from before these formats (INVALID_ARGUMENT), or a job it
                // finished (NOT_FOUND), has none: the image is what was asked for
                match download(&mut c, &job.id, format, path).await {
                    Err(Download::Status(s)) if matches!(s.code(), Code::NotFound | Code::InvalidArgument) => {
                        eprintln!("warning: no {} for job {}: {}", path.display(), job.id, s.message());
                    }
                    done => done?,
                }
            }
        }
        eprintln!("{}: done -> {}", job.id, output.exr.display());
        Ok(())
    })
}

/// A streamed submission: the header, then each file in chunks, its first chunk naming it.
fn submission_parts(header: pb::SubmitJobRequest, bundle: tessera_common::bundle::Bundle) -> Vec<pb::SubmitJobPart> {
    let mut parts = vec![pb::SubmitJobPart { header: Some(header), ..Default::default() }];
    for (path, data) in bundle.files {
        let data = prost::bytes::Bytes::from(data);
        // an empty file still gets its one part, which names it
        let starts = (0..data.len().max(1)).step_by(tessera_proto::CHUNK_BYTES);
        for (i, start) in starts.enumerate() {
            let end = data.len().min(start + tessera_proto::CHUNK_BYTES);
            let path = if i == 0 { path.clone() } else { String::new() };
            parts.push(pb::SubmitJobPart { header: None, path, data: data.slice(start..end) });
        }
    }
    parts
}

/// Watches a job with a progress bar until it ends; returns its last state.
async fn follow(c: &mut Client, id: &str) -> anyhow::Result<pb::Job> {
    let bar = ProgressBar::new(1000);
    bar.set_style(
        ProgressStyle::with_template("{spinner} [{elapsed_precise}] {wide_bar} {percent:>3}% {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // a coordinator restart resumes the job, so a lost connection is retried for a while
    let mut lost_since: Option<std::time::Instant> = None;
    loop {
        let watched = async {
            let req = c.request(pb::GetJobRequest { id: id.to_string() });
            let mut stream = c.jobs.watch_job(req).await?.into_inner();
            let mut last = None;
            while let Some(job) = stream.next().await {
                let job = job?;
                lost_since = None;
                bar.set_position((job.progress * 1000.0) as u64);
                let eta = job.eta_s.map(|e| format!(" eta {e:.0}s")).unwrap_or_default();
                bar.set_message(format!("{} {}/{} tiles{eta}", job.phase, job.tiles_done, job.tiles_total));
                last = Some(job);
            }
            Ok::<_, tonic::Status>(last)
        }
        .await;
        match watched {
            Ok(Some(job)) if is_final(&job) => {
                bar.finish_and_clear();
                return Ok(job);
            }
            Ok(_) => {}
            Err(s) if !lost_connection(&s) => {
                bar.finish_and_clear();
                return Err(status_error(s));
            }
            Err(s) if lost_since.is_some_and(|t| t.elapsed() > RECONNECT_FOR) => {
                bar.finish_and_clear();
                return Err(status_error(s).context("lost the coordinator"));
            }
            Err(_) => {}
        }
        lost_since.get_or_insert_with(std::time::Instant::now);
        bar.set_message("coordinator unreachable, retrying");
        tokio::time::sleep(std::time::Duration::from_secs(1)).await;
    }
}

/// How long `--wait` keeps retrying an unreachable coordinator.
const RECONNECT_FOR: std::time::Duration = std::time::Duration::from_secs(120);

/// Whether the job renders with EMIS, so has a strategy PNG and report (the server's settings:
/// the integrator may come from the scene file).
fn is_emis(job: &pb::Job) -> bool {
    let integrator = job.settings.as_ref().and_then(|s| s.integrator.parse::<IntegratorName>().ok());
    integrator.and_then(IntegratorName::emis_method).is_some()
}

fn is_final(job: &pb::Job) -> bool {
    [pb::JobState::Done, pb::JobState::Failed, pb::JobState::Cancelled].iter().any(|s| *s as i32 == job.state)
}

/// Why a download failed: the coordinator's answer (kept, for the caller to tell a missing
/// output from a failure), or anything else.
enum Download {
    Status(tonic::Status),
    Other(anyhow::Error),
}

impl From<Download> for anyhow::Error {
    fn from(e: Download) -> Self {
        match e {
            Download::Status(s) => status_error(s),
            Download::Other(e) => e,
        }
    }
}

/// Whether a call failed for want of the coordinator (a lost connection, a restart) rather than
/// by its answer: such calls are tried again for [`RECONNECT_FOR`].
fn lost_connection(s: &tonic::Status) -> bool {
    matches!(s.code(), Code::Unavailable | Code::Unknown | Code::Internal)
}

/// Downloads a result, trying again while the coordinator is unreachable.
async fn download(c: &mut Client, id: &str, format: pb::ResultFormat, path: &Path) -> Result<(), Download> {
    let start = std::time::Instant::now();
    loop {
        match download_once(c, id, format, path).await {
            Err(Download::Status(s)) if lost_connection(&s) && start.elapsed() < RECONNECT_FOR => {
                tracing::debug!(status = %s, "download interrupted, retrying");
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
            }
            done => return done,
        }
    }
}

async fn download_once(c: &mut Client, id: &str, format: pb::ResultFormat, path: &Path) -> Result<(), Download> {
    let req = c.request(pb::GetResultRequest { id: id.to_string(), format: format as i32 });
    let mut stream = c.jobs.get_result(req).await.map_err(Download::Status)?.into_inner();
    let mut bytes = Vec::new();
    while let Some(chunk) = stream.next().await {
        bytes.extend_from_slice(&chunk.map_err(Download::Status)?.data);
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create {}", dir.display()))
            .map_err(Download::Other)?;
    }
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display())).map_err(Download::Other)
}
