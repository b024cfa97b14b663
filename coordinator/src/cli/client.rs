//! The farm client: the connection to a coordinator shared by `submit`, `status`, `cancel` and
//! `delete`, and the `status`, `cancel` and `delete` commands, all over gRPC.

use crate::options::InvalidInput;
use anyhow::{Context, bail};
use tessera_proto::state_name;
use tessera_proto::v1 as pb;
use tessera_proto::v1::job_service_client::JobServiceClient;
use tonic::transport::Channel;

/// Connection options shared by the client commands.
#[derive(clap::Args, Debug, Clone)]
pub struct ServerArgs {
    /// Coordinator URL (`https://` when it serves TLS).
    #[arg(long, env = "TESSERA_SERVER", default_value = "http://127.0.0.1:7878")]
    pub server: String,
    /// PEM file of the CA (or self-signed certificate) an https:// coordinator's certificate
    /// chains to, trusted besides the system's roots.
    #[arg(long, env = "TESSERA_CA_CERT", value_name = "PEM")]
    pub ca_cert: Option<std::path::PathBuf>,
    /// Client bearer token.
    #[arg(long, env = "TESSERA_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
}

/// A connected client plus its token.
pub struct Client {
    /// The gRPC client.
    pub jobs: JobServiceClient<Channel>,
    token: Option<String>,
}

impl Client {
    /// Connects to the coordinator.
    pub async fn connect(args: &ServerArgs) -> anyhow::Result<Client> {
        let channel = tessera_link::connect::endpoint(&args.server, args.ca_cert.as_deref())?
            .connect()
            .await
            .map_err(|source| Unreachable { url: args.server.clone(), source })?;
        if args.server.to_ascii_lowercase().starts_with("http://") {
            refuse_tls_behind_http(&args.server, channel.clone()).await?;
        }
        let jobs = JobServiceClient::new(channel)
            .max_decoding_message_size(tessera_proto::MAX_MESSAGE_BYTES)
            .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES);
        Ok(Client { jobs, token: args.token.clone() })
    }

    /// Wraps a message with the bearer token.
    pub fn request<T>(&self, message: T) -> tonic::Request<T> {
        tessera_proto::authorized(message, self.token.as_deref())
    }
}

/// What the coordinator answered to a call that failed (its code decides the exit code).
#[derive(Debug, thiserror::Error)]
#[error("{message} ({code:?})")]
pub struct Refused {
    /// The gRPC code.
    pub code: tonic::Code,
    /// The coordinator's message.
    pub message: String,
}

/// The coordinator cannot be reached.
#[derive(Debug, thiserror::Error)]
#[error("cannot connect to {url}")]
pub struct Unreachable {
    /// Its URL.
    pub url: String,
    /// Why.
    #[source]
    pub source: tonic::transport::Error,
}

/// Over `http://`, a TLS server answers with bytes that are no HTTP/2, which tonic reports as
/// "transport error (Unknown)": one request to `/healthz` finds out, and a server that then
/// completes a TLS handshake is named as one (`use https://`).
async fn refuse_tls_behind_http(url: &str, mut channel: Channel) -> anyhow::Result<()> {
    use tonic::codegen::Service;
    let request = http::Request::get("/healthz").body(tonic::body::Body::empty())?;
    let answered = async {
        std::future::poll_fn(|cx| channel.poll_ready(cx)).await?;
        channel.call(request).await
    };
    if answered.await.is_err() && tessera_link::connect::speaks_tls(url, std::time::Duration::from_secs(3)).await {
        bail!(tessera_link::connect::use_https(url));
    }
    Ok(())
}

/// A gRPC error as a one-line message.
pub fn status_error(s: tonic::Status) -> anyhow::Error {
    Refused { code: s.code(), message: s.message().to_string() }.into()
}

/// Arguments of `tessera status`.
#[derive(clap::Args, Debug, Clone)]
pub struct StatusArgs {
    /// A job id; all jobs when absent.
    pub job: Option<String>,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `tessera list`.
#[derive(clap::Args, Debug, Clone)]
pub struct ListArgs {
    /// Only jobs in this state: queued, pilot, optimizing, final, paused, blocked, done, failed
    /// or cancelled.
    #[arg(long)]
    pub state: Option<String>,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// The state names `--state` takes.
const STATES: [&str; 9] =
    ["queued", "pilot", "optimizing", "final", "paused", "blocked", "done", "failed", "cancelled"];

/// Arguments of `tessera cancel`.
#[derive(clap::Args, Debug, Clone)]
pub struct CancelArgs {
    /// The job id.
    pub job: String,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
}

/// Arguments of `tessera delete`.
#[derive(clap::Args, Debug, Clone)]
pub struct DeleteArgs {
    /// The job id.
    pub job: String,
    /// Cancel the job first if it is still active (otherwise an active job is refused).
    #[arg(long)]
    pub cancel: bool,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
}

/// A job as JSON (the REST shape's main fields).
pub fn job_json(j: &pb::Job) -> serde_json::Value {
    serde_json::json!({
        "id": j.id, "name": j.name, "state": state_name(j.state), "phase": j.phase,
        "progress": j.progress, "tiles_done": j.tiles_done, "tiles_total": j.tiles_total,
        "samples_done": j.samples_done, "eta_s": j.eta_s, "error": j.error,
        "strategy": j.strategy.as_ref().map(|s| serde_json::json!({
            "nu": s.light_paths_per_pixel, "connections": s.connections,
            "mean_connections": s.mean_connections,
            "mean_merge_probability": s.mean_merge_probability, "updates": s.updates,
        })),
        "priority": j.priority, "width": j.width, "height": j.height,
        "integrator": j.settings.as_ref().map(|s| s.integrator.clone()),
    })
}

/// Runs `tessera status`.
pub fn status_command(args: &StatusArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let jobs = match &args.job {
            Some(id) => vec![
                c.jobs
                    .get_job(c.request(pb::GetJobRequest { id: id.clone() }))
                    .await
                    .map_err(status_error)?
                    .into_inner(),
            ],
            None => c.jobs.list_jobs(c.request(pb::ListJobsRequest {})).await.map_err(status_error)?.into_inner().jobs,
        };
        if args.json && args.job.is_some() {
            println!("{}", serde_json::to_string_pretty(&job_json(&jobs[0]))?);
            return Ok(());
        }
        print_jobs(&jobs, args.json)
    })
}

/// Runs `tessera list`.
pub fn list_command(args: &ListArgs) -> anyhow::Result<()> {
    if let Some(s) = args.state.as_deref().filter(|s| !STATES.contains(s)) {
        return Err(InvalidInput(format!("--state {s}: expected one of {}", STATES.join(", "))).into());
    }
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let jobs = c.jobs.list_jobs(c.request(pb::ListJobsRequest {})).await.map_err(status_error)?.into_inner().jobs;
        let jobs: Vec<_> =
            jobs.into_iter().filter(|j| args.state.as_deref().is_none_or(|s| state_name(j.state) == s)).collect();
        print_jobs(&jobs, args.json)
    })
}

/// Prints jobs as a table, or as a JSON array.
fn print_jobs(jobs: &[pb::Job], json: bool) -> anyhow::Result<()> {
    {
        if json {
            let v: Vec<_> = jobs.iter().map(job_json).collect();
            println!("{}", serde_json::to_string_pretty(&v)?);
            return Ok(());
        }
        println!("{:<36}  {:<10}  {:>6}  {:>11}  {:<5}  name", "id", "state", "done", "tiles", "integ");
        for j in jobs {
            let integrator = j.settings.as_ref().map_or("", |s| s.integrator.as_str());
            println!(
                "{:<36}  {:<10}  {:>5.1}%  {:>5}/{:<5}  {:<5}  {}{}",
                j.id,
                state_name(j.state),
                j.progress * 100.0,
                j.tiles_done,
                j.tiles_total,
                integrator,
                j.name,
                j.error.as_ref().map(|e| format!("  error: {e}")).unwrap_or_default()
            );
        }
        Ok(())
    }
}

/// Runs `tessera cancel`.
pub fn cancel_command(args: &CancelArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let job = c
            .jobs
            .cancel_job(c.request(pb::CancelJobRequest { id: args.job.clone() }))
            .await
            .map_err(status_error)?
            .into_inner();
        println!("{}: {}", job.id, state_name(job.state));
        if job.state != pb::JobState::Cancelled as i32 {
            bail!("job {} was already {}", job.id, state_name(job.state));
        }
        Ok(())
    })
}

/// Runs `tessera delete`.
pub fn delete_command(args: &DeleteArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        if args.cancel {
            c.jobs.cancel_job(c.request(pb::CancelJobRequest { id: args.job.clone() })).await.map_err(status_error)?;
        }
        c.jobs.delete_job(c.request(pb::DeleteJobRequest { id: args.job.clone() })).await.map_err(status_error)?;
        println!("{}: deleted", args.job);
        Ok(())
    })
}

/// A small runtime for a client command.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread().enable_all().build().context("cannot start the async runtime")
}
