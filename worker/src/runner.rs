//! The worker loop: register → (lease → fetch scene → render → upload)*, with a heartbeat task
//! beside it, reconnection with backoff when the coordinator is unreachable, and draining on
//! SIGTERM/SIGINT (no new leases; the tiles in hand are finished and uploaded).

use crate::Args;
use crate::client::{Backoff, Client};
use crate::convert;
use crate::render::{EmisWork, TileOutput, TileWork, render_batch};
use crate::scene_cache::{MaskCache, SceneCache};
use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tessera_common::emis::{CandidateSet, Strategy};
use tessera_common::integrator::Stop;
use tessera_common::integrator::path::connections::{self, Connections};
use tessera_common::integrator::path::merge::MergeMask;
use tessera_common::settings::Renderer;
use tessera_proto::v1 as pb;
use tokio::sync::watch;

/// How long a lease request waits for work (and so the longest a drain waits for one).
const LEASE_WAIT_MS: u32 = 5_000;
/// How long an upload is retried while the coordinator is unreachable.
const UPLOAD_RETRY: Duration = Duration::from_secs(120);

/// Leases in hand, shared with the heartbeat task; `lost` collects those the coordinator says
/// are no longer current, whose results are not worth uploading.
#[derive(Default)]
struct Held {
    leases: Vec<pb::LeaseRef>,
    lost: HashSet<(String, u32, u64)>,
    /// The stop flag of each held lease's render, requested when the lease is lost.
    stops: HashMap<(String, u32, u64), Stop>,
}

/// An error retrying cannot mend.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Fatal(String);

fn key(l: &pb::LeaseRef) -> (String, u32, u64) {
    (l.job_id.clone(), l.tile, l.epoch)
}

/// Why registering failed; what retrying cannot mend is [`Fatal`].
async fn registration_error(s: tonic::Status, url: &str) -> anyhow::Error {
    match s.code() {
        // another worker's identity, another build: retrying cannot help
        tonic::Code::FailedPrecondition | tonic::Code::InvalidArgument => {
            anyhow::Error::new(Fatal(s.message().to_string()))
        }
        tonic::Code::Unauthenticated | tonic::Code::PermissionDenied => anyhow::Error::new(Fatal(format!(
            "the coordinator refused this worker's token ({}): check --token (TESSERA_TOKEN)",
            s.message()
        ))),
        // an http:// URL of a TLS coordinator answers with bytes that are no HTTP/2
        tonic::Code::Internal | tonic::Code::Unknown
            if tessera_link::connect::speaks_tls(url, Duration::from_secs(3)).await =>
        {
            anyhow::Error::new(Fatal(tessera_link::connect::use_https(url)))
        }
        _ => s.into(),
    }
}

/// Runs until drained.
pub async fn run(args: Args) -> anyhow::Result<()> {
    // a bad URL or CA file is fatal at once; only connecting is retried
    let endpoint = tessera_link::connect::endpoint(&args.coordinator, args.ca_cert.as_deref())?;
    let threads = args.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = Arc::new(rayon::ThreadPoolBuilder::new().num_threads(threads).build()?);
    let cache_dir = args.cache_dir.clone().unwrap_or_else(|| std::env::temp_dir().join("tessera-worker-cache"));
    std::fs::create_dir_all(&cache_dir)?;
    let identity = crate::identity::Identity::keep(&cache_dir)?;
    let mut cache =
        SceneCache::new(cache_dir, args.texture_budget, args.max_triangles, args.cache_limit.saturating_mul(1 << 20));
    cache.work_limits = crate::work_limits(args.max_tile_memory);
    let name = args.name.clone().unwrap_or_else(|| std::env::var("HOSTNAME").unwrap_or_else(|_| "worker".into()));
    let max_tiles = args.max_tiles.unwrap_or(threads as u32).max(1);
    let (drain_tx, drain) = watch::channel(false);
    tokio::spawn(async move {
        wait_for_signal().await;
        tracing::info!("draining: finishing the tiles in hand");
        let _ = drain_tx.send(true);
    });
    let mut backoff = Backoff::default();
    while !*drain.borrow() {
        let session = async {
            let mut client = Client::connect(&endpoint, args.token.clone()).await?;
            let reg = client
                .inner
                .register(client.request(pb::RegisterRequest {
                    name: name.clone(),
                    threads: threads as u32,
                    worker_id: identity.id.clone(),
                    worker_secret: identity.secret.clone(),
                    tags: args.tags.clone(),
                    ..tessera_link::build::registration()
                }))
                .await;
            let reg = match reg {
                Ok(reg) => reg.into_inner(),
                Err(s) => return Err(registration_error(s, &args.coordinator).await),
            };
            tracing::info!(worker_id = %reg.worker_id, coordinator = %args.coordinator, threads, "registered");
            backoff.reset();
            let held = Arc::new(Mutex::new(Held::default()));
            let heartbeat = tokio::spawn(heartbeat_loop(
                client.clone(),
                reg.worker_id.clone(),
                reg.heartbeat_interval_ms,
                held.clone(),
            ));
            let until = Until { drain: drain.clone(), exit_when_drained: args.exit_when_drained };
            let result = work_loop(&mut client, &reg.worker_id, max_tiles, &pool, &mut cache, &held, until).await;
            heartbeat.abort();
            result
        };
        match session.await {
            Ok(()) => break,
            Err(e) if e.is::<Fatal>() => return Err(e.context("registration refused")),
            Err(e) => {
                let delay = backoff.next_delay();
                tracing::warn!(error = %format!("{e:#}"), retry_in_ms = delay.as_millis() as u64, "coordinator unavailable");
                let mut d = drain.clone();
                tokio::select! {
                    _ = tokio::time::sleep(delay) => {}
                    _ = d.wait_for(|v| *v) => {}
                }
            }
        }
    }
    tracing::info!("worker stopped");
    Ok(())
}

/// When the work loop stops: on SIGTERM (`drain`), and when the coordinator drains this worker
/// if it was started with `--exit-when-drained`.
struct Until {
    drain: watch::Receiver<bool>,
    exit_when_drained: bool,
}

/// How often a worker the coordinator drained asks whether it may work again.
const DRAINED_POLL: Duration = Duration::from_secs(2);

/// Leases, renders and uploads until draining (Ok) or the connection fails (Err).
async fn work_loop(
    client: &mut Client,
    worker: &str,
    max_tiles: u32,
    pool: &Arc<rayon::ThreadPool>,
    cache: &mut SceneCache,
    held: &Arc<Mutex<Held>>,
    until: Until,
) -> anyhow::Result<()> {
    loop {
        if *until.drain.borrow() {
            return Ok(());
        }
        let req =
            client.request(pb::LeaseTileRequest { worker_id: worker.to_string(), max_tiles, wait_ms: LEASE_WAIT_MS });
        // a lease request is never abandoned, not even to drain: the coordinator may already
        // have granted it, and a dropped grant would sit idle until its lease expires
        let timeout = Duration::from_millis(LEASE_WAIT_MS as u64) + Duration::from_secs(10);
        let answer = tokio::time::timeout(timeout, client.inner.lease_tile(req))
            .await
            .map_err(|_| anyhow::anyhow!("lease request timed out"))??
            .into_inner();
        let leases = answer.leases;
        if answer.drain && leases.is_empty() {
            // it holds nothing: this worker is drained
            if until.exit_when_drained {
                tracing::info!("drained by the coordinator: exiting");
                return Ok(());
            }
            let mut d = until.drain.clone();
            tokio::select! {
                _ = tokio::time::sleep(DRAINED_POLL) => {}
                _ = d.wait_for(|v| *v) => {}
            }
            continue;
        }
        if leases.is_empty() {
            continue;
        }
        {
            let mut h = held.lock().unwrap_or_else(|p| p.into_inner());
            h.leases = leases.iter().filter_map(|l| l.lease.clone()).collect();
            h.stops = h.leases.iter().map(|l| (key(l), Stop::new())).collect();
        }
        let outcome = render_and_upload(client, worker, pool, cache, held, &leases).await;
        {
            let mut h = held.lock().unwrap_or_else(|p| p.into_inner());
            h.leases.clear();
            h.lost.clear();
            h.stops.clear();
        }
        outcome?;
    }
}

/// The strategy of an EMIS lease, with its merge mask fetched (or cached).
async fn emis_work(
    client: &mut Client,
    masks: &mut MaskCache,
    s: &pb::TileStrategy,
    pixels: usize,
) -> anyhow::Result<EmisWork> {
    use pb::tile_strategy::Merge;
    let merge = match &s.merge {
        None => None,
        Some(Merge::MergeConstant(c)) => Some(MergeMask::Constant(*c)),
        Some(Merge::MergeMaskDigest(d)) => {
            Some(MergeMask::PerPixel(masks.get(client, d, pixels, "merge mask", 0.0..=1.0).await?))
        }
    };
    let connections = if s.connection_mask_digest.is_empty() {
        Connections::Fixed(s.connections)
    } else {
        let range = 0.0..=connections::MAX_PER_PIXEL;
        Connections::PerPixel(masks.get(client, &s.connection_mask_digest, pixels, "connection mask", range).await?)
    };
    if !(s.light_paths_per_pixel >= 0.0 && s.light_paths_per_pixel.is_finite()) {
        anyhow::bail!("lease strategy has light_paths_per_pixel {}", s.light_paths_per_pixel);
    }
    let strategy = Strategy { nu: s.light_paths_per_pixel, connections, merge };
    let set = if s.reduced_candidates { CandidateSet::Reduced } else { CandidateSet::Full };
    Ok(EmisWork { strategy, collect: s.collect_moments.then_some(set) })
}

/// Renders one batch of leases (all of one job) and uploads the results.
#[tracing::instrument(skip_all, fields(job_id = %leases[0].lease.as_ref().map_or("", |l| l.job_id.as_str()), tiles = leases.len()))]
async fn render_and_upload(
    client: &mut Client,
    worker: &str,
    pool: &Arc<rayon::ThreadPool>,
    cache: &mut SceneCache,
    held: &Arc<Mutex<Held>>,
    leases: &[pb::TileLease],
) -> anyhow::Result<()> {
    let first = &leases[0];
    let prepared = async {
        let settings = convert::settings(first.settings.as_ref()).map_err(anyhow::Error::msg)?;
        let scene = cache.get(client, &first.bundle_digest, &first.scene_path, &settings.define_map()).await?;
        // the coordinator checked the settings; this worker checks them against itself before
        // it allocates anything for the tile
        settings.check_work(scene.camera.width, scene.camera.height, &cache.work_limits)?;
        let renderer = settings.make_renderer(&scene)?;
        let emis = match (&renderer, &first.strategy) {
            (Renderer::Emis(..), Some(s)) => {
                let pixels = scene.camera.width as usize * scene.camera.height as usize;
                Some(emis_work(client, &mut cache.masks, s, pixels).await?)
            }
            (Renderer::Emis(..), None) => anyhow::bail!("an EMIS lease came without a strategy"),
            (Renderer::Tiles(_), _) => None,
        };
        let stops = held.lock().unwrap_or_else(|p| p.into_inner()).stops.clone();
        let tiles = leases
            .iter()
            .map(|l| {
                Ok(TileWork {
                    job_id: l.lease.as_ref().map_or_else(String::new, |l| l.job_id.clone()),
                    tile: l.lease.as_ref().map_or(0, |l| l.tile),
                    rect: convert::rect(l.rect.as_ref())?,
                    samples: l.sample_begin..l.sample_end,
                    seed: settings.seed.unwrap_or(0),
                    stop: l.lease.as_ref().and_then(|l| stops.get(&key(l)).cloned()).unwrap_or_default(),
                })
            })
            .collect::<Result<Vec<_>, String>>()
            .map_err(anyhow::Error::msg)?;
        anyhow::Ok((scene, renderer, emis, tiles))
    }
    .await;
    let (scene, renderer, emis, tiles) = match prepared {
        Ok(p) => p,
        Err(e) => {
            // cannot render these leases (bad bundle, scene, settings): say so, so the tiles go
            // back to the queue now instead of after the lease timeout
            let message = format!("{e:#}");
            for l in leases {
                if let Some(lease) = &l.lease {
                    tracing::error!(job_id = %lease.job_id, tile = lease.tile, error = %message, "tile failed: cannot render it");
                }
                let req = pb::ReportFailureRequest {
                    worker_id: worker.to_string(),
                    lease: l.lease.clone(),
                    message: message.clone(),
                };
                client.inner.report_failure(client.request(req)).await?;
            }
            return Ok(());
        }
    };
    let pool = pool.clone();
    let work = tiles.clone();
    let results =
        match tokio::task::spawn_blocking(move || render_batch(&pool, &scene, &renderer, emis.as_ref(), &work)).await {
            Ok(results) => results,
            Err(e) => {
                // a panic in the renderer: the session ends, and registering again re-queues them
                for t in &tiles {
                    tracing::error!(job_id = %t.job_id, tile = t.tile, error = %e, "tile failed: the render panicked");
                }
                return Err(e.into());
            }
        };
    for (l, TileOutput { accum, seconds, pilot }) in leases.iter().zip(results) {
        let Some(lease) = l.lease.clone() else { continue };
        if held.lock().unwrap_or_else(|p| p.into_inner()).lost.contains(&key(&lease)) {
            tracing::debug!(job_id = %lease.job_id, tile = lease.tile, "lease lost while rendering: result dropped");
            continue;
        }
        let header = pb::TileResultHeader {
            worker_id: worker.to_string(),
            lease: Some(lease.clone()),
            rect: Some(convert::rect_to_pb(accum.rect)),
            sample_begin: l.sample_begin,
            sample_end: l.sample_end,
            non_finite: accum.non_finite,
            render_seconds: seconds,
            pilot_bytes: pilot.len() as u64,
        };
        let mut payload = tessera_link::payload::encode_tile(&accum);
        payload.extend_from_slice(&pilot);
        upload(client, header, payload, &lease).await?;
        tracing::debug!(job_id = %lease.job_id, tile = lease.tile, seconds, non_finite = accum.non_finite, "tile uploaded");
    }
    Ok(())
}

/// Uploads one result, retrying while the coordinator is unreachable (a restarted coordinator
/// still accepts results for leases it persisted).
async fn upload(
    client: &mut Client,
    header: pb::TileResultHeader,
    payload: Vec<u8>,
    lease: &pb::LeaseRef,
) -> anyhow::Result<()> {
    use pb::upload_result_request::Part;
    let started = tokio::time::Instant::now();
    let mut backoff = Backoff::default();
    loop {
        let mut messages = vec![pb::UploadResultRequest { part: Some(Part::Header(header.clone())) }];
        messages.extend(
            payload
                .chunks(tessera_proto::CHUNK_BYTES)
                .map(|c| pb::UploadResultRequest { part: Some(Part::Data(c.to_vec().into())) }),
        );
        match client.inner.upload_result(client.request(tokio_stream::iter(messages))).await {
            Ok(r) => {
                let r = r.into_inner();
                if r.outcome != pb::UploadOutcome::Accepted as i32 {
                    tracing::info!(job_id = %lease.job_id, tile = lease.tile, message = %r.message, "result not merged");
                }
                return Ok(());
            }
            Err(s) if s.code() == tonic::Code::InvalidArgument => {
                tracing::error!(job_id = %lease.job_id, tile = lease.tile, message = %s.message(), "tile failed: result refused by the coordinator");
                return Ok(());
            }
            Err(s)
                if started.elapsed() < UPLOAD_RETRY
                    && matches!(s.code(), tonic::Code::Unavailable | tonic::Code::Unknown | tonic::Code::Internal) =>
            {
                let delay = backoff.next_delay();
                tracing::warn!(job_id = %lease.job_id, tile = lease.tile, message = %s.message(), retry_in_ms = delay.as_millis() as u64, "upload failed, retrying");
                // the channel reconnects by itself on the next call
                tokio::time::sleep(delay).await;
            }
            Err(s) => return Err(s.into()),
        }
    }
}

/// Extends the held leases every `interval_ms`, recording those the coordinator reports lost.
async fn heartbeat_loop(mut client: Client, worker: String, interval_ms: u32, held: Arc<Mutex<Held>>) {
    let mut tick = tokio::time::interval(Duration::from_millis(interval_ms.max(50) as u64));
    loop {
        tick.tick().await;
        let leases = held.lock().unwrap_or_else(|p| p.into_inner()).leases.clone();
        let req = client.request(pb::HeartbeatRequest { worker_id: worker.clone(), leases });
        match client.inner.heartbeat(req).await {
            Ok(r) => {
                let mut h = held.lock().unwrap_or_else(|p| p.into_inner());
                for l in r.into_inner().lost {
                    // cancelled, expired or past its lifetime: stop rendering it now
                    if let Some(stop) = h.stops.get(&key(&l)) {
                        stop.request();
                        tracing::info!(job_id = %l.job_id, tile = l.tile, "lease lost: render stopped");
                    }
                    h.lost.insert(key(&l));
                }
            }
            Err(s) => tracing::debug!(message = %s.message(), "heartbeat failed"),
        }
    }
}

async fn wait_for_signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match (signal(SignalKind::terminate()), signal(SignalKind::interrupt())) {
            (Ok(mut term), Ok(mut int)) => {
                tokio::select! {
                    _ = term.recv() => {}
                    _ = int.recv() => {}
                }
            }
            _ => std::future::pending::<()>().await,
        }
    }
    #[cfg(not(unix))]
    let _ = tokio::signal::ctrl_c().await;
}
