//! Following a job and fetching its outputs, for `tessera submit --wait` and for re-attaching
//! to a job later: `tessera wait JOB [-o OUT]` follows it with a progress bar and downloads
//! what it made, `tessera download JOB [-o OUT]` downloads a done job's outputs. Both name
//! the files as `tessera render` does (default: the job's name), and a job named by a unique
//! prefix of its id is found too.

use super::client::{Client, ServerArgs, runtime, status_error};
use crate::output::OutputPaths;
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use tessera_common::settings::IntegratorName;
use tessera_proto::state_name;
use tessera_proto::v1 as pb;
use tokio_stream::StreamExt;
use tonic::Code;

/// Arguments of `tessera wait` and `tessera download`.
#[derive(clap::Args, Debug, Clone)]
pub struct FetchArgs {
    /// The job: its id or a unique prefix of at least 6 characters.
    pub job: String,
    /// Where the EXR goes (a PNG beside it, and for EMIS NAME.strategy.png and NAME.emis.json;
    /// a NAME.png names the PNG) [default: the job's name].
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
}

/// A job that ended without its outputs: it failed or was cancelled.
#[derive(Debug, thiserror::Error)]
#[error("job {id} {state}{reason}")]
pub struct JobEnded {
    id: String,
    state: &'static str,
    reason: String,
}

/// Runs `tessera wait`: follows the job until it ends and downloads its outputs.
pub fn wait_command(args: &FetchArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let job = get(&mut c, &args.job).await?;
        wait_and_download(&mut c, &job.id, &output_of(args, &job)).await
    })
}

/// Runs `tessera download`: the outputs of a done job.
pub fn download_command(args: &FetchArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let job = get(&mut c, &args.job).await?;
        if job.state != pb::JobState::Done as i32 && !(job.frames_total > 0 && is_final(&job)) {
            if is_final(&job) {
                return Err(ended(job).into());
            }
            anyhow::bail!("job {} is {}, not done: `tessera wait` waits for it", job.id, state_name(job.state));
        }
        download_done(&mut c, &job, &output_of(args, &job)).await
    })
}

async fn get(c: &mut Client, id: &str) -> anyhow::Result<pb::Job> {
    let req = c.request(pb::GetJobRequest { id: id.to_string() });
    Ok(c.jobs.get_job(req).await.map_err(status_error)?.into_inner())
}

/// `-o`, or the job's name in the working directory (its id if the name is no file name).
fn output_of(args: &FetchArgs, job: &pb::Job) -> PathBuf {
    let plain = !job.name.is_empty() && !job.name.contains(['/', '\\']) && !job.name.starts_with('.');
    let name = if plain { job.name.clone() } else { job.id.clone() };
    args.output.clone().unwrap_or_else(|| PathBuf::from(format!("{name}.exr")))
}

/// Writes what a job made: a still's outputs, or each done frame's (then fails with
/// [`JobEnded`] naming the frames that did not end done).
async fn download_done(c: &mut Client, job: &pb::Job, output: &Path) -> anyhow::Result<()> {
    if job.frames_total == 0 {
        return download_all(c, job, &OutputPaths::new(output)).await;
    }
    let mut missing = Vec::new();
    for frame in &job.frames {
        if frame.state != pb::JobState::Done as i32 {
            missing.push(frame.number.to_string());
            continue;
        }
        let frame_job = get(c, &frame.job_id).await?;
        download_all(c, &frame_job, &OutputPaths::new(&super::frames::frame_path(output, frame.number))).await?;
    }
    let unplanned = job.frames_total as usize - job.frames.len();
    if missing.is_empty() && unplanned == 0 {
        return Ok(());
    }
    let reason = format!(": frames {} did not finish, {unplanned} not started", missing.join(", "));
    Err(JobEnded { id: job.id.clone(), state: state_name(job.state), reason }.into())
}

fn ended(job: pb::Job) -> JobEnded {
    let reason = job.error.map(|e| format!(": {e}")).unwrap_or_default();
    JobEnded { id: job.id, state: state_name(job.state), reason }
}

/// Follows job `id` until it ends; writes its outputs (each done frame's, for a job of
/// frames) if it is done, else fails with [`JobEnded`].
pub async fn wait_and_download(c: &mut Client, id: &str, output: &Path) -> anyhow::Result<()> {
    let last = follow(c, id).await?;
    if last.state != pb::JobState::Done as i32 && last.frames_total == 0 {
        return Err(ended(last).into());
    }
    download_done(c, &last, output).await
}

/// Writes a done job's outputs: the EXR and PNG, and for EMIS the strategy PNG and report.
async fn download_all(c: &mut Client, job: &pb::Job, output: &OutputPaths) -> anyhow::Result<()> {
    let id = job.id.as_str();
    download(c, id, pb::ResultFormat::Exr, &output.exr).await?;
    download(c, id, pb::ResultFormat::Png, &output.png).await?;
    if is_emis(job) {
        for (format, path) in
            [(pb::ResultFormat::StrategyPng, &output.strategy_png), (pb::ResultFormat::EmisJson, &output.emis_json)]
        {
            // a coordinator from before these formats (INVALID_ARGUMENT), or a job it
            // finished (NOT_FOUND), has none: the image is what was asked for
            match download(c, id, format, path).await {
                Err(Download::Status(s)) if matches!(s.code(), Code::NotFound | Code::InvalidArgument) => {
                    eprintln!("warning: no {} for job {id}: {}", path.display(), s.message());
                }
                done => done?,
            }
        }
    }
    eprintln!("{id}: done -> {}", output.exr.display());
    Ok(())
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
