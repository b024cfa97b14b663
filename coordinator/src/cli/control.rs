//! `tessera pause`, `resume`, `requeue` and `priority`: the job controls of a coordinator
//! (besides `cancel` and `delete`), over gRPC. Each prints the job's id and state after it.

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
