//! Balance-heuristic MIS over sample counts, as pure functions of a path's gathered pdfs.
//!
//! A full path has vertices `0 ..= k` from the light end (0) to the camera (k). Technique `s`
//! samples vertices `0..s` from the light and `s..=k` from the camera:
//!
//! | technique | `s` | count `n` |
//! |---|---|---|
//! | emitter hit (unidirectional) | 0 | 1 |
//! | next-event estimation | 1 | 1 |
//! | connection (light-vertex cache) | 2 ..= k−1 | c·N/\|cache\| |
//! | light tracing | k | N |
//! | merge at vertex `i` (1 ≤ i ≤ k−2) | — | N·χ·c_i, with density p_i · p_light(i)·πr² |
//!
//! The weight of the technique that produced a sample is n_T p_T / Σ_j n_j p_j (Veach's balance
//! heuristic with sample counts; Georgiev et al. 2012 for merges; Grittmann et al. 2022 for the
//! counts as variables). Ratios p_j / p_T are products of per-vertex ratios
//! `from_light[i] / from_camera[i]`, so only two pdf arrays are needed (SeeSharp's
//! `BidirPathPdfs`). Densities through a delta lobe are stored as 0 and count as 1 in the ratio
//! products (pbrt's `remap0`); techniques whose connection touches a delta vertex cannot sample
//! the path and are left out.

/// Capacity of the stack arrays: the longest path (in vertices) the bidirectional
/// integrators build.
pub const MAX_VERTICES: usize = 64;

/// A path's densities, gathered from its two subpaths.
#[derive(Clone, Debug)]
pub struct PathPdfs {
    /// Number of vertices (k + 1).
    pub len: usize,
    /// `from_light[i]`: density of vertex i when sampled from vertex i−1 (the light side), in
    /// area measure. `from_light[0]` is the emission density of the light vertex (position pdf ×
    /// light selection; for an infinite light the direction pdf, solid angle).
    pub from_light: [f32; MAX_VERTICES],
    /// `from_camera[i]`: density of vertex i when sampled from vertex i+1 (the camera side).
    /// `from_camera[k]` is 1 (pinhole); `from_camera[0]` is 0 when the light cannot be hit.
    pub from_camera: [f32; MAX_VERTICES],
    /// Vertex i scatters through a delta lobe (specular surface).
    pub delta: [bool; MAX_VERTICES],
    /// Density of vertex 0 under next-event estimation from vertex 1 (× light selection); 0 when
    /// next-event estimation cannot produce the path.
    pub next_event0: f32,
    /// Whether a camera path can hit the light vertex (false for point lights). Kept apart from
    /// `from_camera[0]`, which is 0 both for unhittable lights and after a delta bounce.
    pub emitter_hittable: bool,
    /// Whether light tracing can connect the light vertex itself to the camera (false for
    /// infinite lights, whose vertex is at infinity).
    pub emitter_splattable: bool,
}

impl PathPdfs {
    /// Empty arrays for a path of `len` vertices.
    pub fn new(len: usize) -> Self {
        assert!(len >= 2 && len <= MAX_VERTICES, "invariant: path length {len} within 2..={MAX_VERTICES}");
        PathPdfs {
            len,
            from_light: [0.0; MAX_VERTICES],
            from_camera: [0.0; MAX_VERTICES],
            delta: [false; MAX_VERTICES],
            next_event0: 0.0,
            emitter_hittable: true,
            emitter_splattable: true,
        }
    }
}

/// Parameters of merging (vertex merging / photon mapping).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MergeCounts {
    /// Acceptance area π r².
    pub area: f32,
    /// N · χ: light paths times this pixel's merge probability.
    pub count: f32,
    /// Apply the correlation-aware factor c_i (Grittmann et al. 2021) to merge densities.
    pub correlation_aware: bool,
    /// Acceptance area used by the correlation-aware factor, π (d₁ tan 1°)².
    pub correlation_area: f32,
    /// N, the lower clamp of the correlation-aware factor is 1/N.
    pub light_paths: f32,
}

/// How many samples each technique takes per camera path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleCounts {
    /// Emitter hits by the camera path (0 or 1).
    pub hit: f32,
    /// Next-event estimation (0 or 1).
    pub next_event: f32,
    /// Effective count of every connection technique: c · N / |cache|.
    pub connect: f32,
    /// Light tracing: N light paths.
    pub light_trace: f32,
    /// Merging, if enabled.
    pub merge: Option<MergeCounts>,
}

impl SampleCounts {
    /// Unidirectional path tracing: emitter hits and next-event estimation.
    pub const PATH_TRACING: SampleCounts =
        SampleCounts { hit: 1.0, next_event: 1.0, connect: 0.0, light_trace: 0.0, merge: None };
}

/// A sampling technique of a full path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Technique {
    /// The camera path hit the emitter (s = 0).
    EmitterHit,
    /// Next-event estimation (s = 1).
    NextEvent,
    /// Connection of `s` light vertices to the camera subpath (2 ≤ s ≤ k − 1).
    Connect(usize),
    /// Light tracing: the light subpath connected to the camera (s = k).
    LightTrace,
    /// Merge at vertex `i` (1 ≤ i ≤ k − 2).
    Merge(usize),
}

#[inline]
fn remap0(x: f32) -> f32 {
    if x != 0.0 { x } else { 1.0 }
}

/// `ratio[s]` = p_s / p_0 for the unidirectional-from-camera technique 0, with the emission
/// density at vertex 0; the caller swaps in next-event estimation's density for s = 1.
#[inline]
fn prefix_ratios(p: &PathPdfs, out: &mut [f32; MAX_VERTICES + 1]) {
    out[0] = 1.0;
    for i in 0..p.len {
        out[i + 1] = out[i] * remap0(p.from_light[i]) / remap0(p.from_camera[i]);
    }
}

/// Whether technique `s` can produce the path: its connection may not touch a delta vertex.
#[inline]
fn can_connect(p: &PathPdfs, s: usize) -> bool {
    !(s < p.len && p.delta[s]) && !(s >= 1 && p.delta[s - 1])
}

/// The correlation-aware factor c_i of a merge at vertex i (Grittmann et al. 2021;
/// docs/emis.md §3.4): the probability that the camera side reaches vertex i, against both
/// sides, clamped below at 1/N. The probabilities are products of up to 63 factors, so they are
/// formed in f64: in f32 both underflow on long paths and their ratio is noise.
pub fn correlation_factor(p: &PathPdfs, i: usize, m: &MergeCounts) -> f32 {
    let k = p.len - 1;
    let a = m.correlation_area as f64;
    let mut p_cam = 1.0f64;
    for j in i..k {
        p_cam *= (p.from_camera[j] as f64 * a).min(1.0);
    }
    let mut p_light = (p.from_light[0] as f64 * p.from_light[1] as f64 * a * a).min(1.0);
    for j in 2..=i {
        p_light *= (p.from_light[j] as f64 * a).min(1.0);
    }
    if m.light_paths <= 0.0 || (p_cam == 0.0 && p_light == 0.0) {
        return 1.0;
    }
    ((p_cam / (p_cam + p_light - p_cam * p_light)) as f32).max(1.0 / m.light_paths)
}

/// What every technique's density of a path needs beyond the sample counts, computed once per
/// sample and shared by its MIS weight and any observer re-weighting it with other counts
/// (the EMIS proxy): the prefix ratios p_s / p_0 and the merges' correlation-aware factors
/// before their 1/N floor.
#[derive(Clone, Debug)]
pub struct PathRatios {
    /// `ratio[s]` = p_s / p_0 with the emission density at vertex 0.
    ratio: [f32; MAX_VERTICES + 1],
    /// Merge at vertex i: c_i before the floor (1 where merges are not correlation-aware).
    correlation: [f32; MAX_VERTICES],
}

impl PathRatios {
    /// The ratios of path `p`; `merge` gives the correlation-aware factor's area, if merges
    /// are in play (their counts do not matter here).
    #[inline]
    pub fn new(p: &PathPdfs, merge: Option<&MergeCounts>) -> Self {
        let mut r = PathRatios { ratio: [0.0; MAX_VERTICES + 1], correlation: [1.0; MAX_VERTICES] };
        prefix_ratios(p, &mut r.ratio);
        if let Some(m) = merge.filter(|m| m.correlation_aware) {
            raw_correlation_factors(p, m.correlation_area, &mut r.correlation);
        }
        r
    }

    /// The correlation-aware factor of a merge at vertex `i` under `m`: c_i clamped below at
    /// 1/N, or 1.
    #[inline]
    pub fn factor(&self, i: usize, m: &MergeCounts) -> f32 {
        if m.correlation_aware && m.light_paths > 0.0 { self.correlation[i].max(1.0 / m.light_paths) } else { 1.0 }
    }
}

/// c_i of every merge vertex before the 1/N floor, in O(k): suffix products of the camera
/// side, a running product of the light side. Vertices neither side reaches keep 1.
fn raw_correlation_factors(p: &PathPdfs, area: f32, out: &mut [f32; MAX_VERTICES]) {
    let k = p.len - 1;
    if k < 3 {
        return;
    }
    let a = area as f64;
    // camera[i] = Π_{j=i}^{k−1} min(from_camera[j]·a, 1)
    let mut camera = [1.0f64; MAX_VERTICES + 1];
    for j in (1..k).rev() {
        camera[j] = (p.from_camera[j] as f64 * a).min(1.0) * camera[j + 1];
    }
    let mut light = (p.from_light[0] as f64 * p.from_light[1] as f64 * a * a).min(1.0);
    for i in 1..k - 1 {
        if i >= 2 {
            light *= (p.from_light[i] as f64 * a).min(1.0);
        }
        let cam = camera[i];
        if !(cam == 0.0 && light == 0.0) {
            out[i] = (cam / (cam + light - cam * light)) as f32;
        }
    }
}

/// The correlation-aware factors c_i of every merge vertex of `p` under `m` (1 where undefined).
pub fn correlation_factors(p: &PathPdfs, m: &MergeCounts, out: &mut [f32; MAX_VERTICES]) {
    let m = MergeCounts { correlation_aware: true, ..*m };
    let r = PathRatios::new(p, Some(&m));
    for (i, o) in out.iter_mut().enumerate() {
        *o = r.factor(i, &m);
    }
}

/// n_T · p_T / p_0 of every technique, written to `out` in the order emitter hit, next event,
/// connections s = 2..k−1, light tracing (index max(k, 2)), merges i = 1..k−2 (zero where a
/// technique cannot sample the path or is not used). Returns the number of entries written.
pub fn technique_densities(p: &PathPdfs, counts: &SampleCounts, out: &mut [f32; 2 * MAX_VERTICES]) -> usize {
    technique_densities_with(p, &PathRatios::new(p, counts.merge.as_ref()), counts, out)
}

/// [`technique_densities`] from the path's ratios, computed once ([`PathRatios::new`] with a
/// merge of the same areas, if `counts` merge).
pub fn technique_densities_with(
    p: &PathPdfs,
    r: &PathRatios,
    counts: &SampleCounts,
    out: &mut [f32; 2 * MAX_VERTICES],
) -> usize {
    let k = p.len - 1;
    let ratio = &r.ratio;
    let mut n = 0;
    // s = 0: the camera path hits the light
    out[n] = if p.emitter_hittable && can_connect(p, 0) { counts.hit } else { 0.0 };
    n += 1;
    // s = 1: next-event estimation uses its own density for vertex 0
    out[n] = if p.next_event0 > 0.0 && can_connect(p, 1) && k >= 2 {
        counts.next_event * p.next_event0 / remap0(p.from_camera[0])
    } else {
        0.0
    };
    n += 1;
    for s in 2..k {
        out[n] = if can_connect(p, s) { counts.connect * ratio[s] } else { 0.0 };
        n += 1;
    }
    out[n] = if k >= 1 && can_connect(p, k) && (k >= 2 || p.emitter_splattable) {
        counts.light_trace * ratio[k]
    } else {
        0.0
    };
    n += 1;
    if let Some(m) = &counts.merge {
        for i in 1..k.saturating_sub(1) {
            out[n] =
                if p.delta[i] { 0.0 } else { m.count * r.factor(i, m) * ratio[i] * remap0(p.from_light[i]) * m.area };
            n += 1;
        }
    }
    n
}

/// Index of `t` in the layout of [`technique_densities`].
pub fn technique_index(p: &PathPdfs, t: Technique) -> usize {
    let k = p.len - 1;
    match t {
        Technique::EmitterHit => 0,
        Technique::NextEvent => 1,
        Technique::Connect(s) => {
            debug_assert!((2..k).contains(&s));
            s
        }
        Technique::LightTrace => k.max(2),
        Technique::Merge(i) => {
            debug_assert!((1..k.saturating_sub(1)).contains(&i));
            k.max(2) + i
        }
    }
}

/// The balance-heuristic weight of technique `t` for the path described by `p`.
pub fn weight(p: &PathPdfs, counts: &SampleCounts, t: Technique) -> f32 {
    weight_with(p, &PathRatios::new(p, counts.merge.as_ref()), counts, t)
}

/// [`weight`] from the path's ratios, computed once ([`PathRatios::new`]).
#[inline]
pub fn weight_with(p: &PathPdfs, r: &PathRatios, counts: &SampleCounts, t: Technique) -> f32 {
    let mut d = [0.0f32; 2 * MAX_VERTICES];
    let n = technique_densities_with(p, r, counts, &mut d);
    let own = d[technique_index(p, t)];
    let total: f32 = d[..n].iter().sum();
    if own > 0.0 && total.is_finite() && total > 0.0 { (own / total).min(1.0) } else { 0.0 }
}

/// Weight of an emitter hit by the camera path.
pub fn weight_emitter_hit(p: &PathPdfs, counts: &SampleCounts) -> f32 {
    weight(p, counts, Technique::EmitterHit)
}

/// Weight of next-event estimation.
pub fn weight_next_event(p: &PathPdfs, counts: &SampleCounts) -> f32 {
    weight(p, counts, Technique::NextEvent)
}

/// Weight of a connection of `s` light vertices.
pub fn weight_connect(p: &PathPdfs, counts: &SampleCounts, s: usize) -> f32 {
    weight(p, counts, Technique::Connect(s))
}

/// Weight of light tracing.
pub fn weight_light_trace(p: &PathPdfs, counts: &SampleCounts) -> f32 {
    weight(p, counts, Technique::LightTrace)
}

/// Weight of a merge at vertex `i`.
pub fn weight_merge(p: &PathPdfs, counts: &SampleCounts, i: usize) -> f32 {
    weight(p, counts, Technique::Merge(i))
}

#[cfg(test)]
pub(crate) mod tests;
