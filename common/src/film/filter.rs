//! Reconstruction filters (Mitsuba's `rfilter` plugins) and how a sample lands on the film.
//!
//! A camera sample at continuous raster position `s` adds `value · f(i + ½ − s.x) · f(j + ½ −
//! s.y)` to every pixel (i, j) within the radius and the same weight to the pixel's weight sum;
//! the pixel is Σ w·L / Σ w (Mitsuba's `ImageBlock::put` and `develop`). The box filter is the
//! special case where the sample lands in its own pixel with weight 1, so a pixel is the plain
//! average of its samples. Light-tracing splats estimate the same pixel values and go through
//! the same weights, divided by the filter's integral over the image ([`Filter::splat_norm`]),
//! so that they do not depend on how many camera samples a pixel has.
//!
//! Weights are evaluated as Mitsuba's JIT variants on a CPU (`llvm_ad_rgb`, which renders the
//! references) evaluate them: exactly, except the Gaussian, which is Mitsuba's polynomial fit
//! of the exponential shifted to reach 0 at the radius; its scalar variants use a 32-step table
//! instead.

use serde::{Deserialize, Serialize};

/// The largest radius Tessera accepts, in pixels: a tile's sums carry a border of about this
/// many pixels on each side (Mitsuba has no limit; its filters' defaults reach 2 or 3).
pub const MAX_RADIUS: f32 = 16.0;

/// The most pixels a sample reaches along one axis.
pub const MAX_TAPS: usize = 2 * MAX_RADIUS as usize + 2;

/// The filter functions Mitsuba ships, with their parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
pub enum FilterKind {
    /// 1 on [−½, ½): each sample lands in its pixel.
    Box,
    /// max(0, 1 − |x|/r).
    Tent {
        /// r (Mitsuba's default 1).
        radius: f32,
    },
    /// A Gaussian shifted to reach 0 at its radius 4σ.
    Gaussian {
        /// σ (Mitsuba's default 0.5).
        stddev: f32,
    },
    /// The Mitchell–Netravali cubic, radius 2.
    Mitchell {
        /// B (default ⅓).
        b: f32,
        /// C (default ⅓).
        c: f32,
    },
    /// Catmull–Rom: the cubic with B = 0, C = ½.
    CatmullRom,
    /// Windowed sinc with `lobes` lobes, radius `lobes`.
    Lanczos {
        /// L (default 3).
        lobes: u32,
    },
}

impl FilterKind {
    /// Mitsuba's default when the film names no filter: a Gaussian with σ = 0.5.
    pub const DEFAULT: FilterKind = FilterKind::Gaussian { stddev: 0.5 };
}

/// A reconstruction filter ready to weigh samples.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filter {
    /// Which function.
    pub kind: FilterKind,
    radius: f32,
    /// The Gaussian's polynomial in x², shifted to reach 0 at the radius.
    gaussian: [f32; 10],
}

impl Filter {
    /// The box filter.
    pub const BOX: Filter = Filter { kind: FilterKind::Box, radius: 0.5, gaussian: [0.0; 10] };

    /// A filter of `kind`; a radius of exactly ½ counts as the box, as in Mitsuba. The radius
    /// must not exceed [`MAX_RADIUS`] (the scene loader checks it).
    pub fn new(kind: FilterKind) -> Filter {
        let radius = match kind {
            FilterKind::Box => 0.5,
            FilterKind::Tent { radius } => radius,
            FilterKind::Gaussian { stddev } => 4.0 * stddev,
            FilterKind::Mitchell { .. } | FilterKind::CatmullRom => 2.0,
            FilterKind::Lanczos { lobes } => lobes as f32,
        };
        assert!(radius <= MAX_RADIUS, "invariant: filter radius {radius} checked against MAX_RADIUS");
        if radius == 0.5 {
            return Filter::BOX;
        }
        let gaussian = match kind {
            FilterKind::Gaussian { stddev } => gaussian_polynomial(stddev, radius),
            _ => [0.0; 10],
        };
        Filter { kind, radius, gaussian }
    }

    /// Whether the filter can be negative, so that non-negative samples can still give
    /// negative pixels: Mitchell–Netravali (for most B, C), Catmull–Rom and Lanczos.
    pub fn has_negative_lobes(&self) -> bool {
        matches!(self.kind, FilterKind::Mitchell { .. } | FilterKind::CatmullRom | FilterKind::Lanczos { .. })
    }

    /// Whether this is the box filter (each sample lands in its own pixel with weight 1).
    #[inline]
    pub fn is_box(&self) -> bool {
        self.kind == FilterKind::Box
    }

    /// The radius in pixels.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// Pixels a sample can reach beyond its own pixel on each side (Mitsuba's block border).
    pub fn border(&self) -> u32 {
        if self.is_box() { 0 } else { (self.radius - 0.5 - 2.0 * 1500.0 * f32::EPSILON).ceil().max(0.0) as u32 }
    }

    /// The 1D filter value at offset `x` (pixels).
    pub fn eval(&self, x: f32) -> f32 {
        let ax = x.abs();
        match self.kind {
            FilterKind::Box => (-0.5..0.5).contains(&x) as u8 as f32,
            FilterKind::Tent { radius } => (1.0 - ax / radius).max(0.0),
            FilterKind::Gaussian { .. } => estrin(&self.gaussian, x * x).max(0.0) * (ax < self.radius) as u8 as f32,
            FilterKind::Mitchell { b, c } => mitchell(ax, b, c),
            FilterKind::CatmullRom => mitchell(ax, 0.0, 0.5),
            FilterKind::Lanczos { lobes } => {
                let l = lobes as f32;
                if ax >= l {
                    0.0
                } else if ax < 1e-5 {
                    1.0
                } else {
                    let px = std::f32::consts::PI * x;
                    l * px.sin() * (px / l).sin() / (px * px)
                }
            }
        }
    }

    /// The pixels (inclusive-exclusive ranges of columns and rows, clipped to `0..width` and
    /// `0..height`) a sample at raster position `(x, y)` reaches.
    #[inline]
    pub fn footprint(&self, x: f32, y: f32, width: u32, height: u32) -> (std::ops::Range<u32>, std::ops::Range<u32>) {
        let span = |s: f32, n: u32| {
            // pixel i is reached when |i + ½ − s| < r
            let lo = (s - 0.5 - self.radius).floor() + 1.0;
            let hi = (s - 0.5 + self.radius).ceil();
            (lo.max(0.0) as u32).min(n)..(hi.max(0.0) as u32).min(n)
        };
        (span(x, width), span(y, height))
    }

    /// The filter's integral over the image for each column (`n` = width) or row (`n` =
    /// height): ∫₀ⁿ f(t − i − ½) dt. A light-tracing splat into pixel (i, j) is divided by
    /// `norm_x[i] · norm_y[j]`: the weight a camera-sample density of one per pixel gives that
    /// pixel in expectation, so splats and camera samples estimate the same pixel value,
    /// at the image's border too.
    pub fn splat_norm(&self, n: u32) -> Vec<f32> {
        // the filters are smooth or piecewise linear: 64 midpoint steps per pixel integrate
        // them to well below the noise of any render
        const STEPS: u32 = 64;
        let r = self.radius.ceil() as i64 + 1;
        (0..n)
            .map(|i| {
                let mut sum = 0.0f64;
                for p in (i as i64 - r).max(0)..(i as i64 + r + 1).min(n as i64) {
                    for k in 0..STEPS {
                        let t = p as f64 + (k as f64 + 0.5) / STEPS as f64;
                        sum += self.eval((t - i as f64 - 0.5) as f32) as f64;
                    }
                }
                (sum / STEPS as f64) as f32
            })
            .collect()
    }
}

/// Mitsuba's CPU Gaussian (`src/rfilters/gaussian.cpp`): a minimax fit of exp(−t/2) on
/// [0, 16] in t = x²/σ², as a polynomial in x², with its constant lowered so it is 0 at r².
fn gaussian_polynomial(stddev: f32, radius: f32) -> [f32; 10] {
    const FIT: [f64; 10] = [
        9.992604880e-1,
        -4.977025247e-1,
        1.222248550e-1,
        -1.932406282e-2,
        2.136713061e-3,
        -1.679873860e-4,
        9.202145248e-6,
        -3.329417433e-7,
        7.128382794e-9,
        -6.821193280e-11,
    ];
    let mut c = [0.0f32; 10];
    let mut scale = 1.0f64;
    for (ci, fit) in c.iter_mut().zip(FIT) {
        *ci = (fit * scale) as f32;
        scale /= (stddev as f64) * (stddev as f64);
    }
    c[0] -= estrin(&c, radius * radius);
    c
}

/// Σ c_i t^i in Estrin's order with fused multiply-adds, as Mitsuba evaluates it: the terms
/// alternate in sign and nearly cancel in the tail, where each rounding shows.
#[inline]
fn estrin(c: &[f32; 10], t: f32) -> f32 {
    // a fused multiply-add rounds once on any CPU; without the instruction compiled in, each
    // is a library call (a sixth of a Gaussian-filtered render's time went to them)
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has the FMA instructions, checked just above
        return unsafe { estrin_fma(c, t) };
    }
    estrin_any(c, t)
}

/// [`estrin`] compiled with the FMA instructions.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "fma")]
fn estrin_fma(c: &[f32; 10], t: f32) -> f32 {
    estrin_any(c, t)
}

/// [`estrin`] on any CPU.
#[inline(always)]
fn estrin_any(c: &[f32; 10], t: f32) -> f32 {
    let t2 = t * t;
    let t4 = t2 * t2;
    let t8 = t4 * t4;
    let p = [
        t.mul_add(c[1], c[0]),
        t.mul_add(c[3], c[2]),
        t.mul_add(c[5], c[4]),
        t.mul_add(c[7], c[6]),
        t.mul_add(c[9], c[8]),
    ];
    let q = [t2.mul_add(p[1], p[0]), t2.mul_add(p[3], p[2]), p[4]];
    t8.mul_add(q[2], t4.mul_add(q[1], q[0]))
}

/// The Mitchell–Netravali cubic at |x| = `ax`.
fn mitchell(ax: f32, b: f32, c: f32) -> f32 {
    let (x2, x3) = (ax * ax, ax * ax * ax);
    let v = if ax < 1.0 {
        (12.0 - 9.0 * b - 6.0 * c) * x3 + (-18.0 + 12.0 * b + 6.0 * c) * x2 + (6.0 - 2.0 * b)
    } else if ax < 2.0 {
        (-b - 6.0 * c) * x3 + (6.0 * b + 30.0 * c) * x2 + (-12.0 * b - 48.0 * c) * ax + (8.0 * b + 24.0 * c)
    } else {
        0.0
    };
    v / 6.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filter_functions_match_mitsubas_definitions() {
        let g = Filter::new(FilterKind::DEFAULT);
        assert_eq!(g.radius(), 2.0);
        // the polynomial stays within 1e-3 of the shifted exponential and reaches 0 at r
        for x in [0.0f32, 0.3, 0.5, 1.0, 1.5, 1.9] {
            let exact = (-2.0 * x * x).exp() - (-8.0f32).exp();
            assert!((g.eval(x) - exact).abs() < 1e-3, "{x}: {} vs {exact}", g.eval(x));
        }
        assert_eq!(g.eval(2.0), 0.0);
        assert!(g.eval(1.999).abs() < 1e-4);
        let t = Filter::new(FilterKind::Tent { radius: 1.5 });
        assert!((t.eval(0.75) - 0.5).abs() < 1e-6);
        // Mitchell with B = C = 1/3: 8/9 at 0, continuous at 1, 0 at 2
        let m = Filter::new(FilterKind::Mitchell { b: 1.0 / 3.0, c: 1.0 / 3.0 });
        assert!((m.eval(0.0) - 8.0 / 9.0).abs() < 1e-6);
        assert!((m.eval(0.9999) - m.eval(1.0001)).abs() < 1e-3);
        assert!(m.eval(1.9999).abs() < 1e-4 && m.eval(2.0) == 0.0);
        let cr = Filter::new(FilterKind::CatmullRom);
        assert!((cr.eval(0.0) - 1.0).abs() < 1e-6 && cr.eval(1.0).abs() < 1e-6);
        let l = Filter::new(FilterKind::Lanczos { lobes: 3 });
        assert_eq!(l.eval(0.0), 1.0);
        assert!(l.eval(1.0).abs() < 1e-5 && l.eval(2.0).abs() < 1e-5 && l.eval(3.0) == 0.0);
        assert!(l.eval(1.5) < 0.0, "the second lobe is negative");
        // a radius of exactly 0.5 is the box
        assert!(Filter::new(FilterKind::Tent { radius: 0.5 }).is_box());
    }

    /// Weights Mitsuba 3.9.1 (`llvm_ad_rgb`) gives the pixels of an 8×8 block around one sample
    /// at raster (3.3, 4.6): `scripts/filter-goldens.py`.
    const MITSUBA: &[(&str, &[(u32, u32, f32)])] = &[
        (
            "gaussian",
            &[
                (1, 3, 1.053696906e-04),
                (2, 3, 2.459256910e-02),
                (3, 3, 8.173854649e-02),
                (4, 3, 4.944044631e-03),
                (1, 4, 1.165071269e-03),
                (2, 4, 2.719196975e-01),
                (3, 4, 9.037819505e-01),
                (4, 4, 5.466623604e-02),
                (1, 5, 2.348748822e-04),
                (2, 5, 5.481820181e-02),
                (3, 5, 1.821997464e-01),
                (4, 5, 1.102055050e-02),
                (1, 6, 4.627053727e-07),
                (2, 6, 1.079922877e-04),
                (3, 6, 3.589349508e-04),
                (4, 6, 2.171056985e-05),
            ],
        ),
        (
            "tent",
            &[
                (2, 3, 5.917162448e-02),
                (3, 3, 1.301775426e-01),
                (4, 3, 1.183431316e-02),
                (2, 4, 3.550296426e-01),
                (3, 4, 7.810651064e-01),
                (4, 4, 7.100586593e-02),
                (2, 5, 1.183431745e-01),
                (3, 5, 2.603549361e-01),
                (4, 5, 2.366861328e-02),
            ],
        ),
        (
            "mitchell",
            &[
                (1, 3, -1.380026224e-04),
                (2, 3, 2.784018638e-03),
                (3, 3, 1.104607154e-02),
                (4, 3, -1.920025970e-04),
                (1, 4, -8.894014172e-03),
                (2, 4, 1.794248670e-01),
                (3, 4, 7.118989229e-01),
                (4, 4, -1.237421297e-02),
                (1, 5, -1.220434322e-03),
                (2, 5, 2.462063357e-02),
                (3, 5, 9.768658131e-02),
                (4, 5, -1.697986270e-03),
                (1, 6, 3.010234286e-05),
                (2, 6, -6.072745891e-04),
                (3, 6, -2.409466077e-03),
                (4, 6, 4.188129242e-05),
            ],
        ),
        (
            "catmullrom",
            &[
                (1, 3, 6.479764124e-04),
                (2, 3, -6.803980097e-03),
                (3, 3, -3.693585843e-02),
                (4, 3, 2.591995522e-03),
                (1, 4, -1.562349033e-02),
                (2, 4, 1.640521437e-01),
                (3, 4, 8.905679584e-01),
                (4, 4, -6.249612942e-02),
                (1, 5, -1.095962361e-03),
                (2, 5, 1.150799077e-02),
                (3, 5, 6.247189268e-02),
                (4, 5, -4.384001717e-03),
                (1, 6, 7.199879474e-05),
                (2, 6, -7.560126833e-04),
                (3, 6, -4.104064777e-03),
                (4, 6, 2.880051616e-04),
            ],
        ),
        (
            "lanczos",
            &[
                (0, 2, 8.164429164e-05),
                (1, 2, -9.036999545e-04),
                (2, 2, 3.574839560e-03),
                (3, 2, 1.600227877e-02),
                (4, 2, -2.033325378e-03),
                (5, 2, 4.727059568e-04),
                (0, 3, -3.360093979e-04),
                (1, 3, 3.719202941e-03),
                (2, 3, -1.471235417e-02),
                (3, 3, -6.585783511e-02),
                (4, 3, 8.368209004e-03),
                (5, 3, -1.945434837e-03),
                (0, 4, 4.652020056e-03),
                (1, 4, -5.149203166e-02),
                (2, 4, 2.036912292e-01),
                (3, 4, 9.117958546e-01),
                (4, 4, -1.158571020e-01),
                (5, 4, 2.693437040e-02),
                (0, 5, 4.445072846e-04),
                (1, 5, -4.920138512e-03),
                (2, 5, 1.946299337e-02),
                (3, 5, 8.712342381e-02),
                (4, 5, -1.107031479e-02),
                (5, 5, 2.573618433e-03),
                (0, 6, -1.126235293e-04),
                (1, 6, 1.246601343e-03),
                (2, 6, -4.931282252e-03),
                (3, 6, -2.207420953e-02),
                (4, 6, 2.804853721e-03),
                (5, 6, -6.520702736e-04),
                (0, 7, 5.531493571e-06),
                (1, 7, -6.122670311e-05),
                (2, 7, 2.421994723e-04),
                (3, 7, 1.084172749e-03),
                (4, 7, -1.377601147e-04),
                (5, 7, 3.202636799e-05),
            ],
        ),
    ];

    #[test]
    fn one_sample_splats_with_mitsubas_weights() {
        use crate::film::{FilmSpec, TileAccum};
        let kinds = [
            ("gaussian", FilterKind::DEFAULT),
            ("tent", FilterKind::Tent { radius: 1.3 }),
            ("mitchell", FilterKind::Mitchell { b: 1.0 / 3.0, c: 1.0 / 3.0 }),
            ("catmullrom", FilterKind::CatmullRom),
            ("lanczos", FilterKind::Lanczos { lobes: 3 }),
        ];
        for (name, kind) in kinds {
            let spec = FilmSpec::new(8, 8, Filter::new(kind));
            let mut t = TileAccum::new(spec.full(), &spec);
            t.add_sample(3, 4, glam::Vec2::new(3.3, 4.6), crate::math::Rgb::ONE);
            let weights = t.weight.unwrap();
            let golden = MITSUBA.iter().find(|(n, _)| *n == name).unwrap().1;
            for (i, &w) in weights.iter().enumerate() {
                let (x, y) = (i as u32 % 8, i as u32 / 8);
                let expected = golden.iter().find(|g| (g.0, g.1) == (x, y)).map_or(0.0, |g| g.2);
                let tolerance = 2e-6 + 1e-5 * expected.abs();
                assert!(
                    (w as f32 - expected).abs() <= tolerance,
                    "{name} pixel ({x}, {y}): {w} vs Mitsuba's {expected}"
                );
            }
        }
    }

    #[test]
    fn borders_and_footprints_cover_the_radius() {
        assert_eq!(Filter::BOX.border(), 0);
        assert_eq!(Filter::new(FilterKind::DEFAULT).border(), 2);
        assert_eq!(Filter::new(FilterKind::Tent { radius: 1.0 }).border(), 1);
        let g = Filter::new(FilterKind::DEFAULT);
        // a sample at 10.3 reaches pixel centres 8.5 .. 11.5 (|c − s| < 2)
        assert_eq!(g.footprint(10.3, 10.3, 100, 100), (8..12, 8..12));
        assert_eq!(g.footprint(0.2, 99.9, 100, 100), (0..2, 98..100));
        for x in [0.0f32, 0.3, 0.5, 0.99, 7.5] {
            let (cols, _) = g.footprint(x, x, 100, 100);
            for i in 0..100u32 {
                let reached = cols.contains(&i);
                assert_eq!(reached, (i as f32 + 0.5 - x).abs() < 2.0, "x {x} pixel {i}");
            }
        }
    }

    #[test]
    fn splat_norms_are_the_filter_integral_and_fall_off_at_the_border() {
        for kind in [FilterKind::Tent { radius: 1.0 }, FilterKind::DEFAULT, FilterKind::Lanczos { lobes: 3 }] {
            let f = Filter::new(kind);
            let norm = f.splat_norm(20);
            // the interior value is the full integral, the same for every interior pixel
            let interior = norm[10];
            assert!((norm[9] - interior).abs() < 1e-6);
            let full: f64 = (0..200_000).map(|k| f.eval(-5.0 + k as f32 * 5e-5) as f64 * 5e-5).sum();
            assert!((interior as f64 - full).abs() < 1e-3 * full, "{kind:?}: {interior} vs {full}");
            if !matches!(kind, FilterKind::Lanczos { .. }) {
                assert!(norm[0] < interior, "{kind:?}: the image border cuts the filter");
            }
        }
        assert!((Filter::new(FilterKind::Tent { radius: 1.0 }).splat_norm(5)[2] - 1.0).abs() < 1e-6);
    }
}
