//! Byte encodings of what crosses a process boundary in an EMIS render on the farm: the
//! [`PilotData`] a worker uploads with a tile, and the [`EmisState`] the coordinator
//! checkpoints. Little-endian and versioned; decoding checks every size against the job and
//! every value's range, so a corrupt or hostile payload is refused with a reason instead of
//! reaching the optimiser (or panicking).

use super::cost::StatisticsSums;
use super::filter::Image;
use super::guides::GuideBuffer;
use super::moments::MomentBuffer;
use super::{CandidateSet, EmisConfig, EmisState, PilotData, PilotStart, Strategy, UpdateReport};
use crate::integrator::path::connections::Connections;
use crate::integrator::path::merge::MergeMask;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Pilot data with f32 moment sums: the coordinator's checkpoints (and uploads of earlier
/// versions).
const PILOT_MAGIC_F32: &[u8; 4] = b"TPD1";
/// Pilot data with bfloat16 moment sums: uploads, whose sums [`MomentBuffer::round_for_wire`]
/// rounded, so that the encoding loses nothing.
const PILOT_MAGIC_BF16: &[u8; 4] = b"TPD2";
const STATE_MAGIC: &[u8; 4] = b"TES1";

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

/// The bfloat16 nearest to `x` (ties to even), as bits. A finite `x` too large for it stays
/// finite (the largest bfloat16): +∞ flags a candidate that cannot sample a path, which
/// rounding must not invent.
pub(super) fn bf16_bits(x: f32) -> u16 {
    let b = half::bf16::from_f32(x);
    if x.is_finite() && b.is_infinite() { half::bf16::MAX.copysign(b).to_bits() } else { b.to_bits() }
}

/// The f32 of bfloat16 `bits` (exact).
pub(super) fn from_bf16_bits(bits: u16) -> f32 {
    half::bf16::from_bits(bits).to_f32()
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
    w.0.extend_from_slice(if precision == SumPrecision::F32 { PILOT_MAGIC_F32 } else { PILOT_MAGIC_BF16 });
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

fn read_pilot(r: &mut Reader, width: u32, height: u32, candidates: usize) -> Result<PilotData, String> {
    let precision = match r.take(4, "the header")? {
        m if m == PILOT_MAGIC_F32 => SumPrecision::F32,
        m if m == PILOT_MAGIC_BF16 => SumPrecision::Bf16,
        _ => return Err("pilot data has an unknown format".into()),
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
    let statistics = StatisticsSums {
        iterations: r.u64("the statistics")?,
        camera_vertices: r.u64("the statistics")?,
        light_paths: r.u64("the statistics")?,
        light_vertices: r.u64("the statistics")?,
        merge_queries: r.u64("the statistics")?,
        photons_per_path: r.f64("the statistics")?,
    };
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
        20 + self.moments.sums.len() * 2 + 48 + 8 + if self.guides.is_zero() { 0 } else { pixels * 7 * 4 }
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
    #[serde(default)]
    reduced: bool,
    /// The first iteration the image keeps.
    #[serde(default)]
    kept_from: u32,
    /// Connections per pixel follow the merge mask (`connections` is then 0).
    #[serde(default)]
    connection_mask: bool,
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
        };
        let json = serde_json::to_vec(&meta).expect("invariant: plain data serialises");
        let mut w = Writer(Vec::new());
        w.0.extend_from_slice(STATE_MAGIC);
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
        w.0
    }

    /// The decisions at the head of an [`EmisState::encode`], read from `r` without the
    /// buffers after them: what a job that ended without outputs still shows.
    pub fn read_decisions(r: &mut impl std::io::Read) -> Result<Decisions, String> {
        use std::io::Read;
        let mut head = [0u8; 8];
        r.read_exact(&mut head).map_err(|e| format!("EMIS checkpoint: {e}"))?;
        if &head[..4] != STATE_MAGIC {
            return Err("EMIS checkpoint has an unknown format".into());
        }
        let len = u32::from_le_bytes(head[4..].try_into().expect("invariant: 4 bytes")) as u64;
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
mod tests {
    use super::*;
    use crate::emis::EmisMethod;

    fn pilot(width: u32, height: u32, candidates: usize) -> PilotData {
        let pixels = (width * height) as usize;
        let mut moments = MomentBuffer::new(width, height, candidates);
        for (i, s) in moments.sums.iter_mut().enumerate() {
            *s = if i % 7 == 3 { f32::INFINITY } else { i as f32 * 0.25 };
        }
        moments.iterations = 2;
        let mut guides = GuideBuffer::new(width, height);
        guides.samples = 2;
        guides.albedo = (0..pixels).map(|i| [i as f32, 0.5, 0.25]).collect();
        guides.depth = (0..pixels).map(|i| i as f32 * 3.0).collect();
        let statistics = StatisticsSums {
            iterations: 2,
            camera_vertices: 10,
            light_paths: 12,
            light_vertices: 30,
            merge_queries: 8,
            photons_per_path: 0.75,
        };
        PilotData { moments, statistics, guides }
    }

    #[test]
    fn uploads_carry_moments_in_half_the_bytes_and_lose_nothing_once_rounded() {
        let mut p = pilot(3, 2, 5);
        p.moments.sums[1] = 0.1;
        let exact = p.clone();
        p.moments.round_for_wire();
        let bytes = p.encode();
        assert_eq!(bytes.len(), p.encoded_len());
        assert_eq!(&bytes[..4], PILOT_MAGIC_BF16);
        assert_eq!(PilotData::decode(&bytes, 3, 2, 5).unwrap(), p);
        // unrounded sums are rounded by the encoding: the decoded data is not the original
        assert_ne!(PilotData::decode(&exact.encode(), 3, 2, 5).unwrap(), exact);
        // a checkpoint keeps sums exactly (they are sums of rounded calls, not rounded)
        let mut w = Writer(Vec::new());
        write_pilot(&mut w, SumPrecision::F32, &exact.moments, &exact.statistics, &exact.guides);
        assert_eq!(PilotData::decode(&w.0, 3, 2, 5).unwrap(), exact);
        assert_eq!(w.0.len(), bytes.len() + 2 * exact.moments.sums.len() - 4);
        // without guides (calls past the guide iterations) an upload leaves them out
        p.guides = GuideBuffer::new(3, 2);
        let bytes = p.encode();
        assert_eq!(bytes.len(), p.encoded_len());
        assert_eq!(bytes.len(), pilot(3, 2, 5).encode().len() - 6 * 7 * 4);
        assert_eq!(PilotData::decode(&bytes, 3, 2, 5).unwrap(), p);
        // a negative zero is not left out (it would come back positive)
        p.guides.normal[1][2] = -0.0;
        let back = PilotData::decode(&p.encode(), 3, 2, 5).unwrap();
        assert_eq!(back.guides.normal[1][2].to_bits(), (-0.0f32).to_bits());
    }

    #[test]
    fn pilot_data_round_trips_and_refuses_bad_sizes_and_values() {
        let p = pilot(3, 2, 5);
        let bytes = p.encode();
        assert_eq!(bytes.len(), p.encoded_len());
        assert_eq!(PilotData::decode(&bytes, 3, 2, 5).unwrap(), p);
        assert!(PilotData::decode(&bytes, 2, 3, 5).unwrap_err().contains("expected 2×3"));
        assert!(PilotData::decode(&bytes[..bytes.len() - 1], 3, 2, 5).unwrap_err().contains("depth guide"));
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(PilotData::decode(&longer, 3, 2, 5).unwrap_err().contains("too many"));
        let mut nan = p.clone();
        nan.moments.sums[7] = f32::NAN;
        assert!(PilotData::decode(&nan.encode(), 3, 2, 5).unwrap_err().contains("moment sum 7 (pixel 1)"));
        let mut guide = p;
        guide.guides.normal[0][1] = f32::INFINITY;
        assert!(PilotData::decode(&guide.encode(), 3, 2, 5).unwrap_err().contains("guide"));
    }

    #[test]
    fn decisions_read_from_a_checkpoint_head_alone() {
        let config = EmisConfig::new(EmisMethod::Vcm);
        let mut state = EmisState::new(config, 4, 3);
        state.update(&[[0.5; 3]; 12], 1);
        let bytes = state.encode();
        let d = EmisState::read_decisions(&mut &bytes[..]).unwrap();
        assert_eq!(
            (d.nu, Connections::Fixed(d.connections), d.reports.len()),
            (state.strategy.nu, state.strategy.connections, 1)
        );
        assert_eq!(d.reports[0].iteration, 1);
        // the head is enough: the buffers after it are not read
        let meta_len = 8 + u32::from_le_bytes(bytes[4..8].try_into().unwrap()) as usize;
        assert!(EmisState::read_decisions(&mut &bytes[..meta_len]).is_ok());
        assert!(EmisState::read_decisions(&mut &bytes[..meta_len - 1]).unwrap_err().contains("bytes"));
        assert!(EmisState::read_decisions(&mut &b"TPD1...."[..]).unwrap_err().contains("unknown format"));
    }

    #[test]
    fn emis_state_checkpoint_round_trips() {
        let config = EmisConfig::new(EmisMethod::Vcm);
        let mut state = EmisState::new(config.clone(), 3, 2);
        state.absorb(&pilot(3, 2, state.candidates.len())).unwrap();
        state.strategy = Strategy {
            nu: 0.5,
            connections: Connections::Fixed(2),
            merge: Some(MergeMask::PerPixel(Arc::new(vec![0.0, 1.0, 0.5, 0.25, 1.0, 0.0]))),
        };
        state.relative_moment = Some(Image { width: 3, height: 2, data: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0] });
        state.updates_done = 2;
        state.stop_collecting();
        let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
        assert_eq!(back.strategy, state.strategy);
        // per-pixel connections travel after the merge mask, and are checked
        let mut per_pixel = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
        per_pixel.strategy.connections = Connections::PerPixel(Arc::new(vec![0.0, 1.5, 8.0, 0.25, 4.0, 2.0]));
        let back = EmisState::decode(config.clone(), 3, 2, &per_pixel.encode()).unwrap();
        assert_eq!(back.strategy, per_pixel.strategy);
        assert_eq!(back.relative_moment.as_ref().map(|i| &i.data), state.relative_moment.as_ref().map(|i| &i.data));
        per_pixel.strategy.connections = Connections::PerPixel(Arc::new(vec![0.0, 1.5, f32::NAN, 0.25, 4.0, 2.0]));
        let err = EmisState::decode(config.clone(), 3, 2, &per_pixel.encode()).map(|_| ()).unwrap_err();
        assert!(err.contains("connection mask value NaN at pixel 2"), "{err}");
        assert_eq!(back.moments, state.moments);
        assert_eq!(back.statistics, state.statistics);
        assert_eq!(back.guides, state.guides);
        assert_eq!(back.updates_done, 2);
        assert!(!back.collecting());
        assert_eq!(back.relative_moment.as_ref().map(|i| &i.data), state.relative_moment.as_ref().map(|i| &i.data));
        assert!(EmisState::decode(config, 2, 3, &state.encode()).is_err());
    }

    /// A path-tracing start keeps its reduced candidate set across a checkpoint, and after the
    /// restart the full set and the first kept iteration.
    #[test]
    fn emis_state_checkpoint_keeps_the_candidate_set_and_the_first_kept_iteration() {
        let config = EmisConfig { pilot: PilotStart::PathTracing, ..EmisConfig::new(EmisMethod::Vcm) };
        let mut state = EmisState::new(config.clone(), 3, 2);
        assert_eq!((state.candidate_set, state.candidates.len()), (CandidateSet::Reduced, 9));
        state.absorb(&pilot(3, 2, 9)).unwrap();
        let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
        assert_eq!((back.candidate_set, back.candidates.len(), back.kept_from), (CandidateSet::Reduced, 9, 0));
        assert_eq!(back.moments, state.moments);
        assert_eq!(back.strategy, state.strategy);
        state.candidate_set = CandidateSet::Full;
        state.candidates = config.candidates_of(CandidateSet::Full);
        state.moments = MomentBuffer::new(3, 2, 51);
        state.kept_from = 4;
        let back = EmisState::decode(config.clone(), 3, 2, &state.encode()).unwrap();
        assert_eq!((back.candidate_set, back.candidates.len(), back.kept_from), (CandidateSet::Full, 51, 4));
        // a reduced set after a restart, or with the default pilot, is corrupt
        state.candidate_set = CandidateSet::Reduced;
        assert!(EmisState::decode(config, 3, 2, &state.encode()).err().unwrap().contains("reduced"));
        state.kept_from = 0;
        let bidirectional = EmisConfig::new(EmisMethod::Vcm);
        assert!(EmisState::decode(bidirectional, 3, 2, &state.encode()).err().unwrap().contains("reduced"));
    }
}
