//! Microfacet distributions (GGX / Trowbridge-Reitz and Beckmann) with Smith shadowing, as
//! Mitsuba's `microfacet.h` defines them: `alpha` is used as given, shadowing is the separable
//! Smith form, and GGX samples the distribution of visible normals.

use crate::math::{PI, safe_sqrt};
use glam::{Vec2, Vec3};

/// Which normal distribution.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MicrofacetKind {
    /// Beckmann-Spizzichino.
    Beckmann,
    /// GGX / Trowbridge-Reitz.
    Ggx,
}

/// An anisotropic microfacet distribution in the local frame (z = macro normal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Microfacet {
    /// The distribution.
    pub kind: MicrofacetKind,
    /// Roughness along the first tangent.
    pub alpha_u: f32,
    /// Roughness along the second tangent.
    pub alpha_v: f32,
    /// Sample visible normals (GGX). Beckmann always samples `D(m) cos θm`: unbiased, with
    /// slightly more variance at grazing angles than Mitsuba's visible-normal routine.
    pub sample_visible: bool,
}

impl Microfacet {
    /// Smallest alpha accepted: below it the lobe is numerically a mirror.
    pub const MIN_ALPHA: f32 = 1e-4;

    /// A distribution with alphas clamped to [`Self::MIN_ALPHA`].
    pub fn new(kind: MicrofacetKind, alpha_u: f32, alpha_v: f32, sample_visible: bool) -> Self {
        Microfacet {
            kind,
            alpha_u: alpha_u.max(Self::MIN_ALPHA),
            alpha_v: alpha_v.max(Self::MIN_ALPHA),
            sample_visible,
        }
    }

    /// Normal distribution `D(m)` (area density of microfacet normals, projected: ∫D cos = 1).
    pub fn d(&self, m: Vec3) -> f32 {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let cos2 = m.z * m.z;
        if m.z <= 0.0 {
            return 0.0;
        }
        let r = match self.kind {
            MicrofacetKind::Beckmann => {
                let e = ((m.x / au) * (m.x / au) + (m.y / av) * (m.y / av)) / cos2;
                (-e).exp() / (PI * au * av * cos2 * cos2)
            }
            MicrofacetKind::Ggx => {
                let t = (m.x / au) * (m.x / au) + (m.y / av) * (m.y / av) + cos2;
                1.0 / (PI * au * av * t * t)
            }
        };
        if r * cos2 > 1e-20 { r } else { 0.0 }
    }

    /// Smith's one-direction shadowing `G1(v, m)`; zero when `m` faces away from `v`.
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        if v.dot(m) * v.z <= 0.0 {
            return 0.0;
        }
        let xy2 = (self.alpha_u * v.x) * (self.alpha_u * v.x) + (self.alpha_v * v.y) * (self.alpha_v * v.y);
        let tan_alpha2 = xy2 / (v.z * v.z); // alpha² tan² θ
        if tan_alpha2 == 0.0 {
            return 1.0;
        }
        match self.kind {
            MicrofacetKind::Beckmann => {
                let a = 1.0 / tan_alpha2.sqrt();
                if a >= 1.6 { 1.0 } else { (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a) }
            }
            MicrofacetKind::Ggx => 2.0 / (1.0 + (1.0 + tan_alpha2).sqrt()),
        }
    }

    /// Separable Smith shadowing-masking `G1(wi) G1(wo)`.
    #[inline]
    pub fn g(&self, wi: Vec3, wo: Vec3, m: Vec3) -> f32 {
        self.g1(wi, m) * self.g1(wo, m)
    }

    /// Density of the normals this distribution samples given the direction `wo` (on either side:
    /// the upper-hemisphere copy is used), in the solid-angle measure of `m`.
    pub fn pdf(&self, wo: Vec3, m: Vec3) -> f32 {
        let w = if wo.z < 0.0 { -wo } else { wo };
        let visible = self.sample_visible && self.kind == MicrofacetKind::Ggx;
        self.pdf_given(wo, m, self.d(m), if visible { self.g1(w, m) } else { 0.0 })
    }

    /// [`Microfacet::pdf`] from `D(m)` and, when visible normals are sampled, `G1(|wo|, m)`
    /// already computed by the caller.
    #[inline]
    pub fn pdf_given(&self, wo: Vec3, m: Vec3, d: f32, g1_wo: f32) -> f32 {
        if self.sample_visible && self.kind == MicrofacetKind::Ggx {
            let w = if wo.z < 0.0 { -wo } else { wo };
            if w.z == 0.0 {
                return 0.0;
            }
            d * g1_wo * w.dot(m).abs() / w.z
        } else {
            d * m.z.max(0.0)
        }
    }

    /// Samples a microfacet normal (upper hemisphere) for the direction `wo`.
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Vec3 {
        if self.sample_visible && self.kind == MicrofacetKind::Ggx {
            let w = if wo.z < 0.0 { -wo } else { wo };
            self.sample_ggx_visible(w, u)
        } else {
            self.sample_full(u)
        }
    }

    /// Heitz 2018, "Sampling the GGX distribution of visible normals": stretch to the unit
    /// hemisphere, sample the projected disk, unstretch.
    fn sample_ggx_visible(&self, w: Vec3, u: Vec2) -> Vec3 {
        let vh = Vec3::new(self.alpha_u * w.x, self.alpha_v * w.y, w.z).normalize();
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 { Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt() } else { Vec3::X };
        let t2 = vh.cross(t1);
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let p1 = r * phi.cos();
        let mut p2 = r * phi.sin();
        let s = 0.5 * (1.0 + vh.z);
        p2 = (1.0 - s) * safe_sqrt(1.0 - p1 * p1) + s * p2;
        let nh = p1 * t1 + p2 * t2 + safe_sqrt(1.0 - p1 * p1 - p2 * p2) * vh;
        Vec3::new(self.alpha_u * nh.x, self.alpha_v * nh.y, nh.z.max(1e-6)).normalize()
    }

    /// Samples `D(m) cos θm` (the full distribution).
    fn sample_full(&self, u: Vec2) -> Vec3 {
        let (au, av) = (self.alpha_u, self.alpha_v);
        let (phi, alpha2) = if au == av {
            (2.0 * PI * u.y, au * au)
        } else {
            let mut phi = ((av / au) * (2.0 * PI * u.y + 0.5 * PI).tan()).atan();
            if u.y > 0.5 {
                phi += PI;
            }
            let (s, c) = phi.sin_cos();
            (phi, 1.0 / ((c * c) / (au * au) + (s * s) / (av * av)))
        };
        let tan2 = match self.kind {
            MicrofacetKind::Beckmann => -alpha2 * (1.0 - u.x).ln(),
            MicrofacetKind::Ggx => alpha2 * u.x / (1.0 - u.x).max(1e-12),
        };
        let cos_theta = 1.0 / (1.0 + tan2).sqrt();
        let sin_theta = safe_sqrt(1.0 - cos_theta * cos_theta);
        let (s, c) = phi.sin_cos();
        Vec3::new(sin_theta * c, sin_theta * s, cos_theta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn integrate_hemisphere(f: impl Fn(Vec3) -> f32) -> f32 {
        let (nt, np) = (800, 400);
        let mut sum = 0.0f64;
        for i in 0..nt {
            let theta = (i as f32 + 0.5) / nt as f32 * 0.5 * PI;
            for j in 0..np {
                let phi = (j as f32 + 0.5) / np as f32 * 2.0 * PI;
                let m = Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
                sum += (f(m) * theta.sin()) as f64;
            }
        }
        (sum * (0.5 * PI as f64 / nt as f64) * (2.0 * PI as f64 / np as f64)) as f32
    }

    #[test]
    fn projected_area_integrates_to_one() {
        for kind in [MicrofacetKind::Beckmann, MicrofacetKind::Ggx] {
            for (au, av) in [(0.1, 0.1), (0.3, 0.3), (0.2, 0.5)] {
                let d = Microfacet::new(kind, au, av, true);
                let integral = integrate_hemisphere(|m| d.d(m) * m.z);
                assert!((integral - 1.0).abs() < 0.01, "{kind:?} {au} {av}: {integral}");
            }
        }
    }

    #[test]
    fn visible_normal_pdf_integrates_to_one() {
        let d = Microfacet::new(MicrofacetKind::Ggx, 0.3, 0.2, true);
        for wo in [Vec3::Z, Vec3::new(0.6, 0.0, 0.8), Vec3::new(-0.5, 0.5, 0.3).normalize()] {
            let integral = integrate_hemisphere(|m| d.pdf(wo, m));
            assert!((integral - 1.0).abs() < 0.01, "{wo}: {integral}");
        }
    }
}
