//! `tessera pause`, `resume`, `requeue` and `priority`: the job controls of a coordinator
//! (besides `cancel` and `delete`), and `tessera workers` and `tessera worker
//! disable|enable|drain`, over gRPC. Each prints the id and state after it.

use super::client::{Client, ServerArgs, runtime, status_error};
use tessera_proto::state_name;
use tessera_proto::v1 as pb;

/// Arguments of `tessera pause`, `resume` and `requeue`.
#[derive(clap::Args, Debug, Clone)]
pub struct JobControlArgs {
    /// The job id.
    pub job: String,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
}

/// Arguments of `tessera priority`.
#[derive(clap::Args, Debug, Clone)]
pub struct PriorityArgs {
    /// The job id.
    pub job: String,
    /// The new priority: higher runs first (equal ones in submission order).
    #[arg(allow_negative_numbers = true)]
    pub priority: i32,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
}

/// A job control.
#[derive(Clone, Copy, Debug)]
pub enum Control {
    /// No more tiles handed out until it is resumed.
    Pause,
    /// On again.
    Resume,
    /// A failed or cancelled job runs on from its last checkpoint.
    Requeue,
}

/// Runs `tessera pause`, `resume` or `requeue`.
pub fn control_command(control: Control, args: &JobControlArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let req = c.request(pb::JobRef { id: args.job.clone() });
        let job = match control {
            Control::Pause => c.jobs.pause_job(req).await,
            Control::Resume => c.jobs.resume_job(req).await,
            Control::Requeue => c.jobs.requeue_job(req).await,
        }
        .map_err(status_error)?
        .into_inner();
        println!("{}: {}", job.id, state_name(job.state));
        Ok(())
    })
}

/// Runs `tessera priority`.
pub fn priority_command(args: &PriorityArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let req = c.request(pb::UpdateJobRequest { id: args.job.clone(), priority: Some(args.priority) });
        let job = c.jobs.update_job(req).await.map_err(status_error)?.into_inner();
        println!("{}: {} priority {}", job.id, state_name(job.state), job.priority);
        Ok(())
    })
}

/// Arguments of `tessera workers`.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkersArgs {
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// What `tessera worker` does to a worker.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum WorkerCommand {
    /// Give it no more tiles; what it holds it finishes.
    Disable(WorkerArg),
    /// Give it tiles again.
    Enable(WorkerArg),
    /// Give it no more tiles and tell it to stop once it holds none (a worker started with
    /// `--exit-when-drained` exits then).
    Drain(WorkerArg),
}

/// One worker of a coordinator.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkerArg {
    /// The worker id, or a unique prefix of at least 6 characters.
    pub worker: String,
    /// Coordinator.
    #[command(flatten)]
    pub server: ServerArgs,
}

/// Runs `tessera workers`.
pub fn workers_command(args: &WorkersArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let req = c.request(pb::ListWorkersRequest {});
        let workers = c.jobs.list_workers(req).await.map_err(status_error)?.into_inner().workers;
        if args.json {
            let v: Vec<_> = workers.iter().map(worker_json).collect();
            println!("{}", serde_json::to_string_pretty(&v)?);
            return Ok(());
        }
        println!("{:<36}  {:<8}  {:>7}  {:>6}  {:<20}  name", "id", "state", "threads", "leases", "tags");
        for w in &workers {
            let tags = w.tags.join(",");
            println!("{:<36}  {:<8}  {:>7}  {:>6}  {:<20}  {}", w.id, w.state, w.threads, w.leases, tags, w.name);
        }
        Ok(())
    })
}

fn worker_json(w: &pb::Worker) -> serde_json::Value {
    serde_json::json!({
        "id": w.id, "name": w.name, "state": w.state, "threads": w.threads, "leases": w.leases,
        "tags": w.tags, "last_seen_s_ago": w.last_seen_s_ago,
    })
}

/// Runs `tessera worker disable|enable|drain`.
pub fn worker_command(command: &WorkerCommand) -> anyhow::Result<()> {
    let (arg, which) = match command {
        WorkerCommand::Disable(a) => (a, 0),
        WorkerCommand::Enable(a) => (a, 1),
        WorkerCommand::Drain(a) => (a, 2),
    };
    runtime()?.block_on(async {
        let mut c = Client::connect(&arg.server).await?;
        let req = c.request(pb::WorkerRef { id: arg.worker.clone() });
        let w = match which {
            0 => c.jobs.disable_worker(req).await,
            1 => c.jobs.enable_worker(req).await,
            _ => c.jobs.drain_worker(req).await,
        }
        .map_err(status_error)?
        .into_inner();
        println!("{}: {}", w.id, w.state);
        Ok(())
    })
}
