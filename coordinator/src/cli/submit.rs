//! `tessera submit`: packs a scene and every file it references into a bundle, submits it,
//! and with `--wait` follows the job with a progress bar and writes the result EXR and PNG (and
//! for EMIS the strategy PNG and JSON report), named as `tessera render` names them.

use super::client::{Client, ServerArgs, runtime, status_error};
use crate::options::JobArgs;
use std::path::PathBuf;
use tessera_proto::v1 as pb;

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
    /// Start only once these jobs are done (ids or unique prefixes, comma-separated); until
    /// then the job is queued, and blocked if one of them fails or is cancelled.
    #[arg(long, value_delimiter = ',', value_name = "JOB")]
    pub after: Vec<String>,
    /// Render only on workers that have all these tags (`tessera-worker --tags`),
    /// comma-separated; until one is up the job waits.
    #[arg(long, value_delimiter = ',', value_name = "TAG")]
    pub require_tags: Vec<String>,
    /// Job name [default: the scene's name].
    #[arg(long)]
    pub name: Option<String>,
    /// Wait for the job, showing progress, and download the result.
    #[arg(long)]
    pub wait: bool,
    /// Print the files that would be uploaded (their paths in the bundle, the scene first) and
    /// exit without contacting the coordinator.
    #[arg(long, conflicts_with = "wait")]
    pub list_files: bool,
    /// Where --wait writes the EXR (a PNG goes beside it, and for EMIS NAME.strategy.png and
    /// NAME.emis.json; a NAME.png names the PNG, and the EXR goes to NAME.exr) [default: the
    /// scene's name].
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Frames: one job of them.
    #[command(flatten)]
    pub frames: super::frames::FrameArgs,
}

/// Runs `tessera submit`.
pub fn submit_command(args: &SubmitArgs) -> anyhow::Result<()> {
    let settings = args.job.settings()?;
    let frames = args.frames.numbers()?;
    let bundle = match &frames {
        None => tessera_common::bundle::pack(&args.scene, &settings.define_map())?,
        Some(numbers) => pack_frames(&args.scene, &settings, &args.frames, numbers)?,
    };
    if args.list_files {
        for (path, _) in &bundle.files {
            println!("{path}");
        }
        return Ok(());
    }
    let name = super::frames::job_name(&args.scene);
    let output = args.output.clone().unwrap_or_else(|| super::frames::default_output(&args.scene, frames.is_some()));
    runtime()?.block_on(async {
        let mut c = Client::connect(&args.server).await?;
        let header = pb::SubmitJobRequest {
            settings: Some(tessera_link::convert::settings_to_pb(&settings)),
            bundle: Some(pb::SceneBundle { scene_path: bundle.scene_path.clone(), files: vec![] }),
            priority: args.priority,
            after: args.after.clone(),
            require_tags: args.require_tags.clone(),
            name: args.name.clone().unwrap_or(name),
            frames: args.frames.frames.clone().unwrap_or_default(),
            frame_param: args.frames.frame_param.clone(),
            seed_per_frame: args.frames.seed_per_frame,
            warm_start: args.frames.warm_start,
        };
        let parts = tokio_stream::iter(submission_parts(header, bundle));
        let job = c.jobs.submit_job_stream(c.request(parts)).await.map_err(status_error)?.into_inner();
        println!("{}", job.id);
        if !args.wait {
            return Ok(());
        }
        super::fetch::wait_and_download(&mut c, &job.id, &output).await
    })
}

/// One bundle of every frame's scene and what each references, each file once: each frame
/// made as the coordinator will make it ([`tessera_link::frames::FrameRule`]), so a file name
/// that depends on the frame parameter is packed for every frame.
fn pack_frames(
    scene: &std::path::Path,
    settings: &tessera_common::settings::RenderSettings,
    frames: &super::frames::FrameArgs,
    numbers: &[u32],
) -> anyhow::Result<tessera_common::bundle::Bundle> {
    let pattern = scene.to_string_lossy();
    let rule = frames.rule(&pattern);
    let scenes: Vec<_> = numbers
        .iter()
        .map(|&n| {
            let (path, settings) = rule.frame(settings, n);
            (PathBuf::from(path), settings.define_map())
        })
        .collect();
    Ok(tessera_common::bundle::pack_many(&scenes, scene)?)
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
