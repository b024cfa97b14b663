//! Byte encodings of what crosses a process boundary in an EMIS render on the farm: the
//! [`PilotData`] a worker uploads with a tile, and the [`EmisState`] the coordinator
//! checkpoints. Little-endian and versioned; decoding checks every size against the job and
//! every value's range, so a corrupt or hostile payload is refused with a reason instead of
//! reaching the optimiser (or panicking).

use super::cost::StatisticsSums;
use super::filter::Image;
use super::guides::GuideBuffer;
use super::moments::{MomentBuffer, bf16_bits, from_bf16_bits};
use super::start::KeptStart;
use super::{CandidateSet, EmisConfig, EmisState, PilotData, PilotStart, Strategy, UpdateReport};
use crate::FORMAT_VERSION;
use crate::integrator::observer::WorkTimes;
use crate::integrator::path::connections::Connections;
use crate::integrator::path::merge::MergeMask;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Pilot data: this magic, [`FORMAT_VERSION`], then whether moment sums are f32
/// (checkpoints) or bfloat16 (uploads, whose sums [`MomentBuffer::round_for_wire`] rounded,
/// so that the encoding loses nothing).
const PILOT_MAGIC: &[u8; 4] = b"TPIL";
/// Work-time integers.
const TIMES_U64: usize = 15;
/// Bytes of the work times.
const TIMES_BYTES: usize = (TIMES_U64 + 2) * 8;
/// An EMIS state checkpoint: this magic, [`FORMAT_VERSION`], its JSON head's length.
const STATE_MAGIC: &[u8; 4] = b"TEMS";

/// Refuses data of another [`FORMAT_VERSION`], naming `what`.
fn check_version(what: &str, version: u32) -> Result<(), String> {
    if version == FORMAT_VERSION {
        return Ok(());
    }
    Err(format!(
        "{what} is format version {version}, written by another Tessera version (this one reads {FORMAT_VERSION})"
    ))
}

/// Little-endian writer.
struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32s(&mut self, v: impl IntoIterator<Item = f32>) {
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }
    fn bf16s(&mut self, v: impl IntoIterator<Item = f32>) {
        for x in v {
            self.0.extend_from_slice(&bf16_bits(x).to_le_bytes());
        }
    }
}

/// Little-endian reader that names what ran out.
struct Reader<'a>(&'a [u8]);

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        if self.0.len() < n {
            return Err(format!("pilot data ends inside {what} ({} bytes left, {n} needed)", self.0.len()));
        }
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Ok(head)
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("invariant: 4 bytes")))
    }
    fn u64(&mut self, what: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("invariant: 8 bytes")))
    }
    fn f64(&mut self, what: &str) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().expect("invariant: 8 bytes")))
    }
    fn f32s(&mut self, n: usize, what: &str) -> Result<Vec<f32>, String> {
        let bytes = n.checked_mul(4).ok_or_else(|| format!("{what} is too large"))?;
        Ok(self
            .take(bytes, what)?
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("invariant: 4 bytes")))
            .collect())
    }
    fn bf16s(&mut self, n: usize, what: &str) -> Result<Vec<f32>, String> {
        let bytes = n.checked_mul(2).ok_or_else(|| format!("{what} is too large"))?;
        Ok(self.take(bytes, what)?.chunks_exact(2).map(|c| from_bf16_bits(u16::from_le_bytes([c[0], c[1]]))).collect())
    }
}

/// How moment sums are written: exactly (checkpoints) or as bfloat16 (uploads).
#[derive(Clone, Copy, PartialEq, Eq)]
enum SumPrecision {
    F32,
    Bf16,
}

fn triples(v: Vec<f32>) -> Vec<[f32; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn write_pilot(
    w: &mut Writer,
    precision: SumPrecision,
    moments: &MomentBuffer,
    statistics: &StatisticsSums,
    guides: &GuideBuffer,
) {
    w.0.extend_from_slice(PILOT_MAGIC);
    w.u32(FORMAT_VERSION);
    w.u32(match precision {
        SumPrecision::F32 => 0,
        SumPrecision::Bf16 => 1,
    });
    w.u32(moments.width);
    w.u32(moments.height);
    w.u32(moments.candidates as u32);
    w.u32(moments.iterations);
    match precision {
        SumPrecision::F32 => w.f32s(moments.sums.iter().copied()),
        SumPrecision::Bf16 => w.bf16s(moments.sums.iter().copied()),
    }
    w.u64(statistics.iterations);
    w.u64(statistics.camera_vertices);
    w.u64(statistics.light_paths);
    w.u64(statistics.light_vertices);
    w.u64(statistics.merge_queries);
    w.f64(statistics.photons_per_path);
    write_times(w, &statistics.times);
    w.u32(guides.samples);
    // calls past the guide iterations carry no guides: uploads leave out their zeros
    let empty = guides.is_zero();
    if precision == SumPrecision::Bf16 {
        w.u32(u32::from(!empty));
        if empty {
            return;
        }
    }
    w.f32s(guides.albedo.iter().flatten().copied());
    w.f32s(guides.normal.iter().flatten().copied());
    w.f32s(guides.depth.iter().copied());
}

fn write_times(w: &mut Writer, t: &WorkTimes) {
    for v in [
        t.iterations,
        t.light_vertices,
        t.light_ns,
        t.photons_built,
        t.build_ns,
        t.camera_vertices,
        t.camera_ns,
        t.connections,
        t.connection_ns,
        t.queries,
        t.photons,
        t.merge_ns,
        t.observer_ns,
        t.path_tracing_vertices,
        t.path_tracing_ns,
    ] {
        w.u64(v);
    }
    w.f64(t.photons_squared);
    w.f64(t.merge_ns_photons);
}

/// Reads work times.
fn read_times(r: &mut Reader) -> Result<WorkTimes, String> {
    let mut u = [0u64; TIMES_U64];
    for v in &mut u {
        *v = r.u64("the work times")?;
    }
    let (photons_squared, merge_ns_photons) = (r.f64("the work times")?, r.f64("the work times")?);
    if !(photons_squared >= 0.0
        && photons_squared.is_finite()
        && merge_ns_photons >= 0.0
        && merge_ns_photons.is_finite())
    {
        return Err(format!("work time sums {photons_squared}, {merge_ns_photons} are out of range"));
    }
    let [
        iterations,
        light_vertices,
        light_ns,
        photons_built,
        build_ns,
        camera_vertices,
        camera_ns,
        connections,
        connection_ns,
        queries,
        photons,
        merge_ns,
        observer_ns,
        path_tracing_vertices,
        path_tracing_ns,
    ] = u;
    Ok(WorkTimes {
        iterations,
        light_vertices,
        light_ns,
        photons_built,
        build_ns,
        camera_vertices,
        camera_ns,
        connections,
        connection_ns,
        queries,
        photons,
        photons_squared,
        merge_ns,
        merge_ns_photons,
        observer_ns,
        path_tracing_vertices,
        path_tracing_ns,
    })
}

fn read_pilot(r: &mut Reader, width: u32, height: u32, candidates: usize) -> Result<PilotData, String> {
    if r.take(4, "the header")? != PILOT_MAGIC {
        return Err("pilot data has an unknown format".into());
    }
    check_version("pilot data", r.u32("the format version")?)?;
    let precision = match r.u32("the precision")? {
        0 => SumPrecision::F32,
        1 => SumPrecision::Bf16,
        other => return Err(format!("pilot data precision {other} is neither 0 (f32) nor 1 (bfloat16)")),
    };
    let (w, h, c) = (r.u32("the width")?, r.u32("the height")?, r.u32("the candidate count")? as usize);
    if (w, h, c) != (width, height, candidates) {
        return Err(format!("pilot data is {w}×{h} with {c} candidates, expected {width}×{height} with {candidates}"));
    }
    let pixels = width as usize * height as usize;
    let iterations = r.u32("the iteration count")?;
    let sums = match precision {
        SumPrecision::F32 => r.f32s(pixels * candidates, "the moment sums")?,
        SumPrecision::Bf16 => r.bf16s(pixels * candidates, "the moment sums")?,
    };
    // +∞ flags a candidate that cannot sample some path; NaN or negative sums are corrupt
    if let Some(i) = sums.iter().position(|s| s.is_nan() || *s < 0.0) {
        return Err(format!("moment sum {i} (pixel {}) is {}", i / candidates.max(1), sums[i]));
    }
    let mut statistics = StatisticsSums {
        iterations: r.u64("the statistics")?,
        camera_vertices: r.u64("the statistics")?,
        light_paths: r.u64("the statistics")?,
        light_vertices: r.u64("the statistics")?,
        merge_queries: r.u64("the statistics")?,
        photons_per_path: r.f64("the statistics")?,
        times: WorkTimes::default(),
    };
    statistics.times = read_times(r)?;
    if !(statistics.photons_per_path >= 0.0 && statistics.photons_per_path.is_finite()) {
        return Err(format!("photons per path {} is out of range", statistics.photons_per_path));
    }
    let samples = r.u32("the guide sample count")?;
    let present = match precision {
        SumPrecision::F32 => true,
        SumPrecision::Bf16 => match r.u32("the guide flag")? {
            0 => false,
            1 => true,
            other => return Err(format!("guide flag {other} is neither 0 nor 1")),
        },
    };
    if !present {
        let guides = GuideBuffer { samples, ..GuideBuffer::new(width, height) };
        return Ok(PilotData {
            moments: MomentBuffer { width, height, candidates, sums, iterations },
            statistics,
            guides,
        });
    }
    let albedo = r.f32s(pixels * 3, "the albedo guide")?;
    let normal = r.f32s(pixels * 3, "the normal guide")?;
    let depth = r.f32s(pixels, "the depth guide")?;
    if !albedo.iter().chain(&normal).chain(&depth).all(|v| v.is_finite()) {
        return Err("a denoiser guide value is not finite".into());
    }
    Ok(PilotData {
        moments: MomentBuffer { width, height, candidates, sums, iterations },
        statistics,
        guides: GuideBuffer { width, height, albedo: triples(albedo), normal: triples(normal), depth, samples },
    })
}

impl PilotData {
    /// The bytes a worker uploads after the image sums. Moment sums are written as bfloat16:
    /// exact for sums that [`MomentBuffer::round_for_wire`] rounded, as `render_iterations`
    /// rounds them locally and on workers alike.
    pub fn encode(&self) -> Vec<u8> {
        let mut w = Writer(Vec::with_capacity(self.encoded_len()));
        write_pilot(&mut w, SumPrecision::Bf16, &self.moments, &self.statistics, &self.guides);
        w.0
    }

    /// Bytes of [`PilotData::encode`].
    pub fn encoded_len(&self) -> usize {
        let pixels = self.moments.width as usize * self.moments.height as usize;
        28 + self.moments.sums.len() * 2 + 48 + TIMES_BYTES + 8 + if self.guides.is_zero() { 0 } else { pixels * 7 * 4 }
    }

    /// Decodes pilot data of a `width`×`height` image with `candidates` candidates; the error
    /// says what is wrong (size, format, or a value out of range).
    pub fn decode(bytes: &[u8], width: u32, height: u32, candidates: usize) -> Result<PilotData, String> {
        let mut r = Reader(bytes);
        let pilot = read_pilot(&mut r, width, height, candidates)?;
        if !r.0.is_empty() {
            return Err(format!("pilot data has {} bytes too many", r.0.len()));
        }
        Ok(pilot)
    }
}

/// The strategy in force and every update's report, from a checkpoint's head.
#[derive(Clone, Debug)]
pub struct Decisions {
    /// Light paths per pixel per iteration.
    pub nu: f32,
    /// Connections per camera vertex (0 with per-pixel connections: see the reports).
    pub connections: u32,
    /// Every update so far.
    pub reports: Vec<UpdateReport>,
}

/// The longest checkpoint header [`EmisState::read_decisions`] reads.
const MAX_META_BYTES: u64 = 64 << 20;

/// The small part of a checkpointed state.
#[derive(Serialize, Deserialize)]
struct StateMeta {
    nu: f32,
    connections: u32,
    merge: MergeKind,
    updates_done: usize,
    collecting: bool,
    relative_moment: bool,
    reports: Vec<UpdateReport>,
    /// The path-tracing start's reduced candidate set is still in use.
    reduced: bool,
    /// The first iteration the image keeps.
    kept_from: u32,
    /// Connections per pixel follow the merge mask (`connections` is then 0).
    connection_mask: bool,
    /// A kept path-tracing start: its iterations and the bits of its weight (JSON numbers
    /// need not read back to the same f64); its image follows the buffers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    start: Option<StartMeta>,
}

#[derive(Serialize, Deserialize)]
struct StartMeta {
    iterations: u32,
    weight_bits: Option<u64>,
}

#[derive(Serialize, Deserialize)]
enum MergeKind {
    None,
    Constant(f32),
    PerPixel,
}

impl EmisState {
    /// A checkpoint of everything merged and decided so far.
    pub fn encode(&self) -> Vec<u8> {
        let meta = StateMeta {
            nu: self.strategy.nu,
            connections: match &self.strategy.connections {
                Connections::Fixed(c) => *c,
                Connections::PerPixel(_) => 0,
            },
            merge: match &self.strategy.merge {
                None => MergeKind::None,
                Some(MergeMask::Constant(c)) => MergeKind::Constant(*c),
                Some(MergeMask::PerPixel(_)) => MergeKind::PerPixel,
            },
            updates_done: self.updates_done,
            collecting: self.collecting(),
            relative_moment: self.relative_moment.is_some(),
            reports: self.reports.clone(),
            reduced: self.candidate_set == CandidateSet::Reduced,
            kept_from: self.kept_from,
            connection_mask: matches!(self.strategy.connections, Connections::PerPixel(_)),
            start: self
                .start
                .as_ref()
                .map(|s| StartMeta { iterations: s.iterations, weight_bits: s.weight.map(f64::to_bits) }),
        };
        let json = serde_json::to_vec(&meta).expect("invariant: plain data serialises");
        let mut w = Writer(Vec::new());
        w.0.extend_from_slice(STATE_MAGIC);
        w.u32(FORMAT_VERSION);
        w.u32(json.len() as u32);
        w.0.extend_from_slice(&json);
        write_pilot(&mut w, SumPrecision::F32, &self.moments, &self.statistics, &self.guides);
        if let Some(MergeMask::PerPixel(mask)) = &self.strategy.merge {
            w.f32s(mask.iter().copied());
        }
        if let Connections::PerPixel(mask) = &self.strategy.connections {
            w.f32s(mask.iter().copied());
        }
        if let Some(image) = &self.relative_moment {
            w.f32s(image.data.iter().copied());
        }
        if let Some(start) = &self.start {
            w.f32s(start.image.iter().flatten().copied());
        }
        w.0
    }

    /// The decisions at the head of an [`EmisState::encode`], read from `r` without the
    /// buffers after them: what a job that ended without outputs still shows.
    pub fn read_decisions(r: &mut impl std::io::Read) -> Result<Decisions, String> {
        use std::io::Read;
        let mut head = [0u8; 12];
        r.read_exact(&mut head).map_err(|e| format!("EMIS checkpoint: {e}"))?;
        if &head[..4] != STATE_MAGIC {
            return Err("EMIS checkpoint has an unknown format".into());
        }
        let word = |at: usize| u32::from_le_bytes(head[at..at + 4].try_into().expect("invariant: 4 bytes"));
        check_version("EMIS checkpoint", word(4))?;
        let len = word(8) as u64;
        let mut json = Vec::new();
        // a header longer than a few reports is corrupt: read no more than that
        r.take(len.min(MAX_META_BYTES)).read_to_end(&mut json).map_err(|e| format!("EMIS checkpoint: {e}"))?;
        if json.len() as u64 != len {
            return Err(format!("EMIS checkpoint header has {} of its {len} bytes", json.len()));
        }
        let meta: StateMeta = serde_json::from_slice(&json).map_err(|e| format!("EMIS checkpoint: {e}"))?;
        Ok(Decisions { nu: meta.nu, connections: meta.connections, reports: meta.reports })
    }

    /// Restores a state written by [`EmisState::encode`] for an image of `width`×`height`.
    pub fn decode(config: EmisConfig, width: u32, height: u32, bytes: &[u8]) -> Result<EmisState, String> {
        let mut r = Reader(bytes);
        if r.take(4, "the header")? != STATE_MAGIC {
            return Err("EMIS checkpoint has an unknown format".into());
        }
        check_version("EMIS checkpoint", r.u32("the format version")?)?;
        let len = r.u32("the header")? as usize;
        let meta: StateMeta =
            serde_json::from_slice(r.take(len, "the header")?).map_err(|e| format!("EMIS checkpoint: {e}"))?;
        if meta.reduced && (config.pilot != PilotStart::PathTracing || meta.kept_from > 0) {
            return Err("EMIS checkpoint: a reduced candidate set without a path-tracing start in progress".into());
        }
        let mut state = EmisState::new(config, width, height);
        state.candidate_set = if meta.reduced { CandidateSet::Reduced } else { CandidateSet::Full };
        state.candidates = state.config.candidates_of(state.candidate_set);
        state.kept_from = meta.kept_from;
        let pilot = read_pilot(&mut r, width, height, state.candidates.len())?;
        let pixels = width as usize * height as usize;
        let merge = match meta.merge {
            MergeKind::None => None,
            MergeKind::Constant(c) => Some(MergeMask::Constant(c)),
            MergeKind::PerPixel => Some(MergeMask::PerPixel(Arc::new(r.f32s(pixels, "the merge mask")?))),
        };
        let connections = if meta.connection_mask {
            let mask = r.f32s(pixels, "the connection mask")?;
            Connections::check_mask(&mask, pixels).map_err(|e| format!("EMIS checkpoint: {e}"))?;
            Connections::PerPixel(Arc::new(mask))
        } else {
            Connections::Fixed(meta.connections)
        };
        if meta.relative_moment {
            let data = r.f32s(pixels, "the relative moment")?;
            state.relative_moment = Some(Image { width: width as usize, height: height as usize, data });
        }
        if let Some(start) = meta.start {
            if meta.reduced || start.iterations != meta.kept_from {
                return Err("EMIS checkpoint: a kept start that does not end where the image begins".into());
            }
            let weight = start.weight_bits.map(f64::from_bits);
            if weight.is_some_and(|k| !(k.is_finite() && k >= 0.0)) {
                return Err("EMIS checkpoint: the kept start's weight is not a finite number ≥ 0".into());
            }
            let flat = r.f32s(pixels * 3, "the kept start's image")?;
            let image = flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            state.start = Some(KeptStart { image, iterations: start.iterations, weight });
        }
        if !r.0.is_empty() {
            return Err(format!("EMIS checkpoint has {} bytes too many", r.0.len()));
        }
        state.strategy = Strategy { nu: meta.nu, connections, merge };
        state.moments = pilot.moments;
        state.statistics = pilot.statistics;
        state.guides = pilot.guides;
        state.updates_done = meta.updates_done;
        if !meta.collecting {
            state.stop_collecting();
        }
        state.reports = meta.reports;
        Ok(state)
    }
}

#[cfg(test)]
#[path = "wire_tests.rs"]
mod tests;
