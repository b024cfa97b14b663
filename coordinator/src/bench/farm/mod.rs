//! `tessera bench farm`: measures the farm coordinator as a separate, real `tessera serve`
//! process (loopback, ephemeral port, temporary `--data-dir`).
//!
//! * `--ingest`: simulated workers ([`loadgen`]) register over gRPC, lease tiles and upload
//!   valid results as fast as the coordinator takes them; reports tiles/s, MB/s, upload latency
//!   and the coordinator's CPU use (from `/proc/PID/stat`), for 64×64 pt tiles and full-frame
//!   vcm iterations, and how many real workers that would feed ([`calibrate`]).
//! * `--scaling`: wall time of one job with real `tessera-worker` processes: one worker with one
//!   thread, two workers with one thread each, one worker with two threads ([`scaling`]).
//! * `--wire`: bytes on the wire per pixel per pass, computed from the protocol and measured
//!   through a byte-counting TCP proxy ([`wire`]).
//!
//! ```text
//! tessera bench farm --ingest --scaling --wire
//! ```

pub mod calibrate;
pub mod loadgen;
pub mod probe;
pub mod scaling;
pub mod serve;
pub mod wire;

use anyhow::{Context, bail};
use std::path::PathBuf;
use std::time::Duration;
use tessera_common::settings::{IntegratorName, RenderSettings};
use tessera_proto::v1 as pb;
use tessera_proto::v1::job_service_client::JobServiceClient;
use tonic::transport::Channel;

/// Arguments of `tessera bench farm`.
#[derive(clap::Args, Debug, Clone)]
pub struct FarmArgs {
    /// Measure result ingest with simulated workers.
    #[arg(long)]
    pub ingest: bool,
    /// Measure the wall time of a job with one and two real workers.
    #[arg(long)]
    pub scaling: bool,
    /// Measure bytes on the wire per pixel per pass.
    #[arg(long)]
    pub wire: bool,
    /// Simulated workers (concurrent connections) of the ingest cases.
    #[arg(long, default_value_t = 4)]
    pub workers: usize,
    /// Image tiles each simulated worker leases at once (as a real worker with this many threads).
    #[arg(long, default_value_t = 2)]
    pub lease_batch: u32,
    /// Frame size of the pt ingest case (64×64 tiles), WIDTHxHEIGHT.
    #[arg(long, default_value = "7680x4320", value_parser = parse_size)]
    pub pt_frame: (u32, u32),
    /// Jobs of that size submitted at once in the pt ingest case.
    #[arg(long, default_value_t = 1)]
    pub pt_jobs: u32,
    /// Frame size of the vcm ingest case (one full-frame tile per iteration).
    #[arg(long, default_value = "256x256", value_parser = parse_size)]
    pub vcm_frame: (u32, u32),
    /// Iterations (tiles) of the vcm ingest case.
    #[arg(long, default_value_t = 1000)]
    pub vcm_iterations: u32,
    /// Pin the coordinator to CPU 0 and the load generator to the other CPUs during ingest.
    #[arg(long, default_value = "on", value_enum)]
    pub pin: crate::options::Switch,
    /// Scene of the scaling run and of the tile render-time calibration.
    #[arg(long, default_value = "scenes/cornell-box/scene.xml")]
    pub scene: PathBuf,
    /// Samples per pixel of the scaling job [default: about --scaling-seconds with one 1-thread worker].
    #[arg(long)]
    pub scaling_spp: Option<u32>,
    /// Target wall time of the scaling job with one 1-thread worker, when --scaling-spp is unset.
    #[arg(long, default_value_t = 30.0)]
    pub scaling_seconds: f64,
    /// The `tessera-worker` binary [default: beside this executable].
    #[arg(long)]
    pub worker_bin: Option<PathBuf>,
    /// Also print the results as one JSON object per case.
    #[arg(long)]
    pub json: bool,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s.split_once('x').ok_or_else(|| format!("expected WIDTHxHEIGHT, got \"{s}\""))?;
    let p = |v: &str| v.parse::<u32>().ok().filter(|&n| n > 0).ok_or_else(|| format!("bad size \"{s}\""));
    Ok((p(w)?, p(h)?))
}

/// A self-contained scene whose film size is a parameter (`-D width=... -D height=...`): a
/// diffuse box lit by a ceiling light. The coordinator loads it to validate a job; the ingest
/// cases never render it.
pub const GENERATED_SCENE: &str = r#"<?xml version="1.0" encoding="utf-8"?>
<scene version="3.0.0">
    <default name="width" value="256"/>
    <default name="height" value="256"/>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 3.9" target="0, 0, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="1"/></sampler>
        <film type="hdrfilm">
            <integer name="width" value="$width"/>
            <integer name="height" value="$height"/>
            <rfilter type="box"/>
        </film>
    </sensor>
    <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf>
    <shape type="rectangle">
        <transform name="to_world"><rotate x="1" y="0" z="0" angle="-90"/><translate x="0" y="-1" z="0"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><translate x="0" y="0" z="-1"/></transform>
        <ref id="white"/>
    </shape>
    <shape type="rectangle">
        <transform name="to_world"><scale x="0.25" y="0.25" z="1"/><rotate x="1" y="0" z="0" angle="90"/><translate x="0" y="0.99" z="0"/></transform>
        <emitter type="area"><rgb name="radiance" value="17, 12, 4"/></emitter>
    </shape>
</scene>
"#;

/// A submit request for [`GENERATED_SCENE`] at `width`×`height`.
pub fn generated_job(
    integrator: IntegratorName,
    width: u32,
    height: u32,
    spp: u32,
    name: &str,
) -> pb::SubmitJobRequest {
    let settings = RenderSettings {
        integrator,
        spp: Some(spp),
        seed: Some(1),
        defines: [("width".to_string(), width.to_string()), ("height".to_string(), height.to_string())].into(),
        // an emis-* job measures the heaviest uploads: the bidirectional pilot's full set
        emis_pilot: tessera_common::emis::PilotStart::Bidirectional,
        ..RenderSettings::default()
    };
    let bundle = tessera_common::bundle::Bundle {
        scene_path: "scene.xml".into(),
        files: vec![("scene.xml".into(), GENERATED_SCENE.as_bytes().to_vec())],
    };
    pb::SubmitJobRequest {
        settings: Some(tessera_link::convert::settings_to_pb(&settings)),
        bundle: Some(tessera_link::bundle::to_pb(&bundle)),
        priority: 0,
        name: name.into(),
        ..Default::default()
    }
}

/// A job-service client.
pub type JobClient = JobServiceClient<Channel>;

/// A job-service client for `url` with the farm's message limits.
pub async fn job_client(url: &str) -> anyhow::Result<JobClient> {
    let channel = Channel::from_shared(url.to_string())?.connect().await.with_context(|| format!("connect {url}"))?;
    Ok(JobServiceClient::new(channel)
        .max_decoding_message_size(tessera_proto::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(tessera_proto::MAX_MESSAGE_BYTES))
}

/// Waits until every job in `ids` is done (polling every `poll`); fails if one fails or is
/// cancelled.
pub async fn wait_done(jobs: &mut JobServiceClient<Channel>, ids: &[String], poll: Duration) -> anyhow::Result<()> {
    loop {
        let mut all = true;
        for id in ids {
            let j = jobs.get_job(pb::GetJobRequest { id: id.clone() }).await?.into_inner();
            if j.state == pb::JobState::Failed as i32 || j.state == pb::JobState::Cancelled as i32 {
                bail!("job {id} ended as {}: {}", tessera_proto::state_name(j.state), j.error.unwrap_or_default());
            }
            all &= j.state == pb::JobState::Done as i32;
        }
        if all {
            return Ok(());
        }
        tokio::time::sleep(poll).await;
    }
}

/// The `q`-quantile of sorted `v` (nearest rank).
pub fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() as f64 * q).ceil() as usize).clamp(1, v.len()) - 1]
}

/// `uptime`'s load averages and the busiest other processes, to say what else was running.
pub fn machine_load() -> String {
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().take(3).collect::<Vec<_>>().join(" ");
    format!("load average {load} on {} CPUs", std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// Runs `tessera bench farm`.
pub fn run(args: &FarmArgs) -> anyhow::Result<()> {
    if !(args.ingest || args.scaling || args.wire) {
        bail!("say what to measure: --ingest, --scaling and/or --wire");
    }
    println!("machine before: {}", machine_load());
    if args.ingest {
        loadgen::ingest_command(args)?;
    }
    if args.wire {
        wire::wire_command(args)?;
    }
    if args.scaling {
        scaling::scaling_command(args)?;
    }
    println!("machine after: {}", machine_load());
    Ok(())
}
