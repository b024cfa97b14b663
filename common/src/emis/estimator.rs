//! The moment estimator (docs/emis.md §3.3, checklist 4 to 7): a sample observer that
//! re-weights every pilot sample by δ for every candidate and adds δ·w2 into per-pixel ×
//! per-candidate sums, and that sums the path statistics of the cost model.
//!
//! Per sample: the proxy strategy's grouped balance weights w̄ (counts a = 1 for hits and NEE,
//! P light paths, 4 connections per camera vertex, χ = 1 merges of P light paths, the pixel's
//! radius); the pilot's count ratios m against a, read from the sample's own counts (so a pilot
//! whose strategy changes between updates stays correct); each candidate's ratios n; then
//! δ_{n,m} = S(m)²·T(n) / (S(n)²·T(m)) and w2 = (channel-mean contribution)².
//!
//! The proxy's connection density is 4·N/|cache| of the current iteration (≈ 4/(L̄l − 1)),
//! the density a candidate with c = 4 has whatever its N; so a candidate's connection ratio is
//! exactly c/4. (The reference uses 4/L̄l, off by the emitter vertex, which cannot be chosen.)
//!
//! A merge candidate's count ratio is χ·ν (merges use N = ν·P light paths, as in their MIS
//! weights), and merge moments are (contribution × kernel)², the square of what the image
//! receives. Both agreed with the measured variances better than the reference code's χ and
//! contribution² × kernel (docs/decisions/0001-estimator-switches.md), which are retired.
//!
//! Determinism: camera-path samples of a pixel come from one thread, in order, so they are
//! added to the pixel's sums directly. Light-tracing samples land in arbitrary pixels from any
//! thread; they are queued and added at the end of the iteration in (pixel, cache index)
//! order. The sums are therefore identical for any thread count.

use super::candidate::Candidate;
use super::cost::StatisticsSums;
use super::moments::MomentBuffer;
use super::proxy::ProxyWeights;
use super::proxy::proxy_weights;
use crate::integrator::observer::{IterationStart, PathCounters, SampleObserver, SampleRecord};
use crate::integrator::path::mis::{MergeCounts, SampleCounts, Technique};
use rayon::prelude::*;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, Ordering};

/// Most candidates one estimator handles (the VCM set has 51).
pub const MAX_CANDIDATES: usize = 64;

/// Connections of the proxy strategy per camera vertex.
const PROXY_CONNECTIONS: f32 = 4.0;

/// The candidates' count ratios against the proxy, per technique group (path tracing is 1),
/// as one array per group so that the per-sample loop over candidates vectorises.
#[derive(Clone, Debug, PartialEq)]
struct Ratios {
    lt: [f32; MAX_CANDIDATES],
    con: [f32; MAX_CANDIDATES],
    vm: [f32; MAX_CANDIDATES],
    len: usize,
}

/// A light-tracing sample waiting for the end of its iteration.
#[derive(Clone, Copy, Debug)]
struct Queued {
    pixel: u32,
    sequence: u32,
    weights: [f32; 5],
    pilot: [f32; 4],
    w2: f32,
}

/// One thread's queue of light-tracing samples, alone on its cache lines: neighbouring locks
/// would bounce one line between the threads on every splat.
#[repr(align(128))]
struct Shard(Mutex<Vec<Queued>>);

/// Collects moments and statistics of pilot iterations; see the module documentation.
pub struct MomentEstimator {
    candidates: Ratios,
    width: u32,
    height: u32,
    merging: bool,
    /// The proxy's connection density of the current iteration (f32 bits).
    proxy_connect: AtomicU32,
    /// f32 bits, indexed `pixel * candidates + candidate`.
    sums: Vec<AtomicU32>,
    /// Light-tracing samples of the iteration, one queue per pool thread: a single queue's
    /// lock, taken once per splat, would serialise the threads.
    queued: Vec<Shard>,
    statistics: Mutex<StatisticsSums>,
    /// Time the work (costs measured per job).
    timed: bool,
}

impl MomentEstimator {
    /// An estimator for `candidates` on a `width × height` image.
    pub fn new(width: u32, height: u32, candidates: &[Candidate]) -> Self {
        assert!(candidates.len() <= MAX_CANDIDATES, "invariant: at most {MAX_CANDIDATES} candidates");
        let mut ratios =
            Ratios { lt: [0.0; MAX_CANDIDATES], con: [0.0; MAX_CANDIDATES], vm: [0.0; MAX_CANDIDATES], len: 0 };
        for (i, c) in candidates.iter().enumerate() {
            ratios.lt[i] = c.nu;
            ratios.con[i] = c.connections as f32 / PROXY_CONNECTIONS;
            ratios.vm[i] = if c.merge { c.nu } else { 0.0 };
        }
        ratios.len = candidates.len();
        let n = width as usize * height as usize * candidates.len();
        MomentEstimator {
            candidates: ratios,
            width,
            height,
            merging: candidates.iter().any(|c| c.merge),
            proxy_connect: AtomicU32::new((PROXY_CONNECTIONS / 5.0).to_bits()),
            // megabytes: zeroed (and their pages faulted in) by all threads
            sums: (0..n).into_par_iter().map(|_| AtomicU32::new(0)).collect(),
            queued: (0..rayon::current_num_threads().max(1)).map(|_| Shard(Mutex::new(Vec::new()))).collect(),
            statistics: Mutex::new(StatisticsSums::default()),
            timed: false,
        }
    }

    /// The same estimator asking the integrator to time its work when `timed` (costs measured
    /// per job need the times; calibrated costs do not).
    pub fn timed(self, timed: bool) -> Self {
        MomentEstimator { timed, ..self }
    }

    fn pixels(&self) -> f32 {
        (self.width * self.height) as f32
    }

    /// The proxy's counts for a sample drawn with `counts`.
    fn proxy_counts(&self, counts: &SampleCounts) -> SampleCounts {
        let p = self.pixels();
        let merge =
            if self.merging { counts.merge.map(|m| MergeCounts { count: p, light_paths: p, ..m }) } else { None };
        SampleCounts {
            hit: 1.0,
            next_event: 1.0,
            connect: f32::from_bits(self.proxy_connect.load(Ordering::Relaxed)),
            light_trace: p,
            merge,
        }
    }

    /// The pilot's ratios (pt, lt, con, vm) against the proxy.
    fn pilot_ratios(&self, counts: &SampleCounts, proxy: &SampleCounts) -> [f32; 4] {
        let vm = counts.merge.as_ref().map_or(0.0, |m| m.count / self.pixels());
        let con = if proxy.connect > 0.0 { counts.connect / proxy.connect } else { 0.0 };
        [
            counts.hit.max(counts.next_event),
            counts.light_trace / self.pixels(),
            con,
            if self.merging { vm } else { 0.0 },
        ]
    }

    /// δ·w2 of every candidate for a sample with proxy weights `w` and pilot ratios `m`.
    #[inline]
    fn contributions(&self, w: &[f32; 5], m: &[f32; 4], w2: f32, out: &mut [f32; MAX_CANDIDATES]) {
        let [pt, lt, con, vm, vm_c] = *w;
        let s_m = m[0] * pt + m[1] * lt + m[2] * con + m[3] * vm;
        let t_m = m[0] * pt + m[1] * lt + m[2] * con + m[3] * vm_c;
        if !(s_m > 0.0 && t_m > 0.0) {
            // the pilot cannot have drawn this sample: nothing to add
            out[..self.candidates.len].fill(0.0);
            return;
        }
        let scale = s_m * s_m * w2 / t_m;
        // eight lanes where the CPU has them; the same operations, so the same sums, on any CPU
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has the AVX2 instructions, checked just above
            unsafe { candidates_avx2(&self.candidates, [pt, lt, con, vm, vm_c], scale, out) };
            return;
        }
        candidates_any(&self.candidates, [pt, lt, con, vm, vm_c], scale, out);
    }

    #[inline]
    fn add_to_pixel(&self, pixel: u32, values: &[f32]) {
        let base = pixel as usize * self.candidates.len;
        for (slot, &v) in self.sums[base..base + values.len()].iter().zip(values) {
            // one writer per pixel at a time (see the module documentation): load and store
            let old = f32::from_bits(slot.load(Ordering::Relaxed));
            slot.store((old + v).to_bits(), Ordering::Relaxed);
        }
    }

    /// The moments and statistics, as a mergeable buffer, reusing the sums' memory (a pilot
    /// iteration's buffer is megabytes; copying it per iteration would cost a visible share of
    /// the collecting iterations).
    pub fn into_snapshot(self) -> (MomentBuffer, StatisticsSums) {
        let statistics = self.statistics.into_inner().expect("invariant: statistics lock is never poisoned");
        let buffer = MomentBuffer {
            width: self.width,
            height: self.height,
            candidates: self.candidates.len,
            // AtomicU32 → f32 has the same size and alignment: the collect reuses the allocation
            sums: self.sums.into_iter().map(|a| f32::from_bits(a.into_inner())).collect(),
            iterations: statistics.iterations as u32,
        };
        (buffer, statistics)
    }

    /// The moments and statistics so far, as a mergeable buffer.
    pub fn snapshot(&self) -> (MomentBuffer, StatisticsSums) {
        let statistics = *self.statistics.lock().expect("invariant: statistics lock is never poisoned");
        let mut buffer = MomentBuffer::new(self.width, self.height, self.candidates.len);
        for (d, s) in buffer.sums.iter_mut().zip(&self.sums) {
            *d = f32::from_bits(s.load(Ordering::Relaxed));
        }
        buffer.iterations = statistics.iterations as u32;
        (buffer, statistics)
    }
}

/// δ·w2 of every candidate slot (those past the candidates' count are never read), for proxy
/// weights `w` and `scale` = S(m)²·w2/T(m): all [`MAX_CANDIDATES`] slots, so that the loop has
/// a fixed trip count and vectorises whole.
#[inline(always)]
fn candidates_any(r: &Ratios, w: [f32; 5], scale: f32, out: &mut [f32; MAX_CANDIDATES]) {
    let [pt, lt, con, vm, vm_c] = w;
    for (((o, &n_lt), &n_con), &n_vm) in out.iter_mut().zip(&r.lt).zip(&r.con).zip(&r.vm) {
        let common = pt + n_lt * lt + n_con * con;
        let s_n = common + n_vm * vm;
        let t_n = common + n_vm * vm_c;
        // S(n) = 0: the candidate cannot sample the path, its moment is infinite
        *o = if s_n > 0.0 { scale * t_n / (s_n * s_n) } else { f32::INFINITY };
    }
}

/// [`candidates_any`] compiled with the AVX2 instructions.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn candidates_avx2(r: &Ratios, w: [f32; 5], scale: f32, out: &mut [f32; MAX_CANDIDATES]) {
    candidates_any(r, w, scale, out)
}

/// The channel mean of a contribution, squared.
#[inline]
fn squared_value(record: &SampleRecord) -> f32 {
    let y = (record.value.x + record.value.y + record.value.z) / 3.0;
    y * y
}

impl SampleObserver for MomentEstimator {
    const MEASURES: bool = true;

    fn on_sample(&self, record: &SampleRecord) {
        let proxy = self.proxy_counts(record.counts);
        let w: ProxyWeights = proxy_weights(record.pdfs, record.ratios, &proxy);
        let weights = [w.pt as f32, w.lt as f32, w.con as f32, w.vm as f32, w.vm_correlated as f32];
        let pilot = self.pilot_ratios(record.counts, &proxy);
        let w2 = squared_value(record);
        if !w2.is_finite() {
            return;
        }
        if record.technique == Technique::LightTrace {
            let q = Queued { pixel: record.pixel, sequence: record.sequence, weights, pilot, w2 };
            let shard = rayon::current_thread_index().unwrap_or(0) % self.queued.len();
            self.queued[shard].0.lock().expect("invariant: queue lock is never poisoned").push(q);
            return;
        }
        let mut out = [0.0f32; MAX_CANDIDATES];
        self.contributions(&weights, &pilot, w2, &mut out);
        self.add_to_pixel(record.pixel, &out[..self.candidates.len]);
    }

    fn wants_times(&self) -> bool {
        self.timed
    }

    fn on_iteration_start(&self, start: &IterationStart) {
        if start.selectable_vertices > 0 {
            let density = PROXY_CONNECTIONS * start.light_paths as f32 / start.selectable_vertices as f32;
            self.proxy_connect.store(density.to_bits(), Ordering::Relaxed);
        } else {
            // no light vertices this iteration: the statistics' 4/L̄c, or 4/5 without any
            let statistics = self.statistics.lock().expect("invariant: statistics lock is never poisoned");
            let lc = statistics.statistics(self.width * self.height).camera_vertices.max(1.0);
            self.proxy_connect.store((PROXY_CONNECTIONS / lc as f32).to_bits(), Ordering::Relaxed);
        }
    }

    fn on_iteration_end(&self, start: &IterationStart, counters: &PathCounters) {
        let mut queued: Vec<Queued> = self
            .queued
            .iter()
            .flat_map(|shard| std::mem::take(&mut *shard.0.lock().expect("invariant: queue lock is never poisoned")))
            .collect();
        // (pixel, sequence) is unique per sample: the order, and so the sums, do not depend on
        // which thread queued what
        queued.par_sort_unstable_by_key(|q| (q.pixel, q.sequence));
        queued.par_chunk_by(|a, b| a.pixel == b.pixel).for_each(|samples| {
            let mut total = [0.0f32; MAX_CANDIDATES];
            let mut out = [0.0f32; MAX_CANDIDATES];
            for q in samples {
                self.contributions(&q.weights, &q.pilot, q.w2, &mut out);
                for (t, o) in total.iter_mut().zip(&out) {
                    *t += o;
                }
            }
            self.add_to_pixel(samples[0].pixel, &total[..self.candidates.len]);
        });
        self.statistics.lock().expect("invariant: statistics lock is never poisoned").add_iteration(
            start.light_paths,
            start.light_vertices,
            counters,
        );
    }
}
