//! Plastics: a diffuse base under a dielectric coating, as Mitsuba's `plastic` (smooth coating,
//! a delta specular lobe) and `roughplastic` (microfacet coating). The diffuse part accounts
//! for the coating's transmittance on the way in and out and for internal reflection
//! (`nonlinear` = false: the internal-reflection sum uses the average internal reflectance).

use super::fresnel::{fresnel_dielectric, fresnel_diffuse_reflectance, reflect, reflect_z, refract};
use super::microfacet::Microfacet;
use super::{BsdfSample, TransportMode};
use crate::math::{INV_PI, Rgb, mean, warp};
use glam::{Vec2, Vec3};

/// Smooth plastic.
#[derive(Clone, Debug, PartialEq)]
pub struct Plastic {
    /// Coating index relative to the exterior.
    pub eta: f32,
    /// Albedo of the base.
    pub diffuse_reflectance: Rgb,
    /// Multiplier on the coating reflection.
    pub specular_reflectance: Rgb,
    /// Use Mitsuba's nonlinear internal scattering (colour-dependent saturation).
    pub nonlinear: bool,
    fdr_int: f32,
    specular_sampling_weight: f32,
}

impl Plastic {
    /// A smooth plastic; `specular_reflectance` of `None` means 1 (as in Mitsuba, it then does
    /// not steer the lobe choice).
    pub fn new(eta: f32, diffuse_reflectance: Rgb, specular_reflectance: Option<Rgb>, nonlinear: bool) -> Self {
        let s_mean = specular_reflectance.map_or(1.0, mean);
        Plastic {
            eta,
            diffuse_reflectance,
            specular_reflectance: specular_reflectance.unwrap_or(Rgb::ONE),
            nonlinear,
            fdr_int: fresnel_diffuse_reflectance(1.0 / eta),
            specular_sampling_weight: s_mean / (mean(diffuse_reflectance) + s_mean),
        }
    }

    fn prob_specular(&self, f_i: f32) -> f32 {
        let ps = f_i * self.specular_sampling_weight;
        let pd = (1.0 - f_i) * (1.0 - self.specular_sampling_weight);
        ps / (ps + pd)
    }

    fn diffuse_value(&self, f_i: f32, f_o: f32) -> Rgb {
        let r = self.diffuse_reflectance;
        let denom = if self.nonlinear { Rgb::ONE - r * self.fdr_int } else { Rgb::splat(1.0 - self.fdr_int) };
        r / denom * ((1.0 - f_i) * (1.0 - f_o) * INV_PI / (self.eta * self.eta))
    }

    pub(super) fn sample(&self, wo: Vec3, uc: f32, u: Vec2, _mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let f_i = fresnel_dielectric(wo.z, self.eta).0;
        let p_spec = self.prob_specular(f_i);
        if uc < p_spec {
            return Some(BsdfSample::delta(
                reflect_z(wo),
                self.specular_reflectance * (f_i / p_spec),
                p_spec,
                1.0,
                false,
            ));
        }
        let wi = warp::square_to_cosine_hemisphere(u);
        if wi.z <= 0.0 {
            return None;
        }
        let f_o = fresnel_dielectric(wi.z, self.eta).0;
        BsdfSample::smooth(wo, wi, self.diffuse_value(f_i, f_o), (1.0 - p_spec) * warp::cosine_hemisphere_pdf(wi), 1.0)
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.diffuse_value(fresnel_dielectric(wo.z, self.eta).0, fresnel_dielectric(wi.z, self.eta).0)
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        (1.0 - self.prob_specular(fresnel_dielectric(wo.z, self.eta).0)) * warp::cosine_hemisphere_pdf(wi)
    }
}

/// Resolution of the coating-transmittance table over cos θ (Mitsuba uses 64 too).
const TRANSMITTANCE_RES: usize = 64;

/// Rough plastic.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughPlastic {
    /// Coating microfacet distribution.
    pub distribution: Microfacet,
    /// Coating index relative to the exterior.
    pub eta: f32,
    /// Albedo of the base.
    pub diffuse_reflectance: Rgb,
    /// Multiplier on the coating reflection.
    pub specular_reflectance: Rgb,
    /// Use nonlinear internal scattering.
    pub nonlinear: bool,
    specular_sampling_weight: f32,
    /// Shared by every rough plastic with this coating: a reference keeps the model (and every
    /// `Material`) small, and resolving a textured material copies it without a reference count.
    coating: &'static CoatingTables,
}

/// What identifies a coating's tables: the distribution's kind, α, η and visible sampling.
pub type CoatingKey = (bool, u32, u32, bool);

/// The key of the coating of `distribution` over index `eta`.
pub fn coating_key(distribution: &Microfacet, eta: f32) -> CoatingKey {
    (
        distribution.kind == super::MicrofacetKind::Ggx,
        distribution.alpha_u.to_bits(),
        eta.to_bits(),
        distribution.sample_visible,
    )
}

/// The most coatings a process keeps tables of (17 MB).
pub const MAX_COATINGS: usize = 1 << 16;

/// What a rough dielectric coating does to light, tabulated once per (distribution, η).
#[derive(Debug, PartialEq)]
struct CoatingTables {
    /// Transmittance into the coating by cos θ, on Mitsuba's μ grid.
    external_transmittance: [f32; TRANSMITTANCE_RES],
    /// Hemispherical reflectance of the coating seen from inside.
    internal_reflectance: f32,
}

impl CoatingTables {
    /// The tables of a coating, computed on first use and kept for the life of the process (a
    /// process sees few distinct coatings; each costs 260 bytes and about a million quadrature
    /// evaluations, which repeated scene loads then skip). At most [`MAX_COATINGS`] are kept:
    /// `None` past them (scenes are limited to a few each, so only a process that loaded
    /// thousands of hostile scenes gets there).
    fn of(distribution: &Microfacet, eta: f32) -> Option<&'static CoatingTables> {
        static CACHE: std::sync::LazyLock<
            std::sync::Mutex<std::collections::HashMap<CoatingKey, &'static CoatingTables>>,
        > = std::sync::LazyLock::new(Default::default);
        let key = coating_key(distribution, eta);
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(tables) = cache.get(&key) {
            return Some(*tables);
        }
        if cache.len() >= MAX_COATINGS {
            return None;
        }
        Some(*cache.entry(key).or_insert_with(|| Box::leak(Box::new(CoatingTables::compute(distribution, eta)))))
    }

    /// Mitsuba's tables: μ on a uniform grid over [0, 1] (the first at 1e-6), the internal
    /// reflectance as 2 × the grid mean of R(μ) μ seen from inside.
    fn compute(distribution: &Microfacet, eta: f32) -> CoatingTables {
        let mu = |i: usize| (i as f32 / (TRANSMITTANCE_RES - 1) as f32).max(1e-6);
        let external_transmittance = std::array::from_fn(|i| coating_albedo(distribution, mu(i), eta, true));
        let internal_reflectance = 2.0
            * (0..TRANSMITTANCE_RES)
                .map(|i| coating_albedo(distribution, mu(i), 1.0 / eta, false) * mu(i))
                .sum::<f32>()
            / TRANSMITTANCE_RES as f32;
        CoatingTables { external_transmittance, internal_reflectance }
    }
}

impl RoughPlastic {
    /// A rough plastic; precomputes the coating's transmittance table by quadrature. `None`
    /// when the process keeps [`MAX_COATINGS`] tables already.
    pub fn new(
        distribution: Microfacet,
        eta: f32,
        diffuse_reflectance: Rgb,
        specular_reflectance: Option<Rgb>,
        nonlinear: bool,
    ) -> Option<Self> {
        let s_mean = specular_reflectance.map_or(1.0, mean);
        Some(RoughPlastic {
            distribution,
            eta,
            diffuse_reflectance,
            specular_reflectance: specular_reflectance.unwrap_or(Rgb::ONE),
            nonlinear,
            specular_sampling_weight: s_mean / (mean(diffuse_reflectance) + s_mean),
            coating: CoatingTables::of(&distribution, eta)?,
        })
    }

    fn transmittance(&self, cos_theta: f32) -> f32 {
        let x = cos_theta.clamp(0.0, 1.0) * (TRANSMITTANCE_RES - 1) as f32;
        let i = (x as usize).min(TRANSMITTANCE_RES - 2);
        let t = x - i as f32;
        let table = &self.coating.external_transmittance;
        table[i] * (1.0 - t) + table[i + 1] * t
    }

    fn prob_specular(&self, cos_o: f32) -> f32 {
        let t_i = self.transmittance(cos_o);
        let ps = (1.0 - t_i) * self.specular_sampling_weight;
        let pd = t_i * (1.0 - self.specular_sampling_weight);
        ps / (ps + pd)
    }

    pub(super) fn sample(&self, wo: Vec3, uc: f32, u: Vec2, mode: TransportMode) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = if uc < self.prob_specular(wo.z) {
            reflect(wo, self.distribution.sample(wo, u))
        } else {
            warp::square_to_cosine_hemisphere(u)
        };
        if wi.z <= 0.0 {
            return None;
        }
        BsdfSample::smooth(wo, wi, self.eval(wo, wi, mode), self.pdf(wo, wi), 1.0)
    }

    pub(super) fn eval(&self, wo: Vec3, wi: Vec3, _mode: TransportMode) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let mut value = Rgb::ZERO;
        if let Some(h) = (wo + wi).try_normalize() {
            let d = self.distribution.d(h);
            let f = fresnel_dielectric(wo.dot(h), self.eta).0;
            let g = self.distribution.g(wo, wi, h);
            value += self.specular_reflectance * (f * d * g / (4.0 * wo.z * wi.z));
        }
        let r = self.diffuse_reflectance;
        let denom = if self.nonlinear {
            Rgb::ONE - r * self.coating.internal_reflectance
        } else {
            Rgb::splat(1.0 - self.coating.internal_reflectance)
        };
        value + r / denom * (INV_PI / (self.eta * self.eta) * self.transmittance(wo.z) * self.transmittance(wi.z))
    }

    pub(super) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let p_spec = self.prob_specular(wo.z);
        let spec = match (wo + wi).try_normalize() {
            Some(h) => self.distribution.pdf(wo, h) / (4.0 * wo.dot(h)),
            None => 0.0,
        };
        p_spec * spec + (1.0 - p_spec) * warp::cosine_hemisphere_pdf(wi)
    }
}

/// What a rough interface with relative index `eta` does to light arriving at `cos_theta`:
/// the fraction it transmits (`transmitted`) or reflects, counting single scattering off the
/// microfacets as Mitsuba's `eval_transmittance`/`eval_reflectance` do (`microfacet.h`):
/// ∫ D_wi(m) G1(wo, m) F dm over visible normals, by Gauss–Legendre quadrature of the
/// sampler's unit square with Mitsuba's resolutions (32² outside, 128² inside).
fn coating_albedo(distribution: &Microfacet, cos_theta: f32, eta: f32, transmitted: bool) -> f32 {
    let wi = Vec3::new((1.0 - cos_theta * cos_theta).max(0.0).sqrt(), 0.0, cos_theta);
    let (nodes, weights) = gauss_legendre(if eta > 1.0 { 32 } else { 128 });
    let mut sum = 0.0f64;
    for (x, wx) in nodes.iter().zip(&weights) {
        for (y, wy) in nodes.iter().zip(&weights) {
            let u = Vec2::new((x * 0.5 + 0.5) as f32, (y * 0.5 + 0.5) as f32);
            let m = distribution.sample(wi, u);
            // visible-normal density over the sampler's: 1 for GGX, whose visible normals
            // are sampled; the full-distribution ratio otherwise (Beckmann)
            let d_vis = distribution.g1(wi, m) * wi.dot(m).max(0.0) * distribution.d(m) / wi.z;
            let pdf = distribution.pdf(wi, m);
            if !(pdf > 0.0) || !(d_vis > 0.0) {
                continue;
            }
            let (f, _, _) = fresnel_dielectric(wi.dot(m), eta);
            let value = if transmitted {
                match refract(wi, m, eta) {
                    Some((wo, _)) if wo.z * wi.z < 0.0 => distribution.g1(wo, m) * (1.0 - f),
                    _ => 0.0,
                }
            } else {
                let wo = reflect(wi, m);
                if wo.z > 0.0 { distribution.g1(wo, m) * f } else { 0.0 }
            };
            sum += (value * d_vis / pdf) as f64 * wx * wy * 0.25;
        }
    }
    sum as f32
}

/// Nodes and weights of the `n`-point Gauss–Legendre rule on [−1, 1] (Newton on P_n).
fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let (mut nodes, mut weights) = (vec![0.0; n], vec![0.0; n]);
    for i in 0..n {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
        let mut dp = 0.0;
        for _ in 0..100 {
            // P_n(x) and its derivative by the three-term recurrence
            let (mut p0, mut p1) = (1.0, x);
            for k in 2..=n {
                let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                p0 = p1;
                p1 = p2;
            }
            dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
            let dx = p1 / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        nodes[i] = x;
        weights[i] = 2.0 / ((1.0 - x * x) * dp * dp);
    }
    (nodes, weights)
}
