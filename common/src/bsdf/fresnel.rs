//! Fresnel equations for dielectrics and conductors (unpolarised light).

use crate::math::Rgb;
use glam::Vec3;

/// Dielectric Fresnel reflectance for a wave arriving with `cos_theta_i` (signed: negative means
/// from the interior side) at an interface with relative index `eta` = interior / exterior.
/// Returns `(F, cos_theta_t, eta_ti)`: the reflectance, the signed cosine of the transmitted
/// direction (opposite sign to `cos_theta_i`), and the relative index seen by the transmitted
/// wave (n_t / n_i).
#[inline]
pub fn fresnel_dielectric(cos_theta_i: f32, eta: f32) -> (f32, f32, f32) {
    let (cos_i, eta_ti) = if cos_theta_i >= 0.0 { (cos_theta_i, eta) } else { (-cos_theta_i, 1.0 / eta) };
    if eta == 1.0 {
        return (0.0, -cos_theta_i, 1.0);
    }
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta_ti * eta_ti);
    if sin2_t >= 1.0 {
        return (1.0, 0.0, eta_ti); // total internal reflection
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_s = (cos_i - eta_ti * cos_t) / (cos_i + eta_ti * cos_t);
    let r_p = (eta_ti * cos_i - cos_t) / (eta_ti * cos_i + cos_t);
    let f = 0.5 * (r_s * r_s + r_p * r_p);
    (f, if cos_theta_i >= 0.0 { -cos_t } else { cos_t }, eta_ti)
}

/// Exact unpolarised conductor reflectance for one channel with complex index `eta + i k`
/// (relative to the exterior) at `cos_theta_i` ≥ 0.
#[inline]
pub fn fresnel_conductor_channel(cos_theta_i: f32, eta: f32, k: f32) -> f32 {
    let c2 = cos_theta_i * cos_theta_i;
    let s2 = (1.0 - c2).max(0.0);
    let (eta2, k2) = (eta * eta, k * k);
    let t0 = eta2 - k2 - s2;
    let a2b2 = (t0 * t0 + 4.0 * eta2 * k2).max(0.0).sqrt();
    let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
    let t1 = a2b2 + c2;
    let t2 = 2.0 * cos_theta_i * a;
    let r_s = (t1 - t2) / (t1 + t2);
    let t3 = c2 * a2b2 + s2 * s2;
    let t4 = t2 * s2;
    let r_p = r_s * (t3 - t4) / (t3 + t4);
    let f = 0.5 * (r_s + r_p);
    if f.is_finite() { f.clamp(0.0, 1.0) } else { 1.0 }
}

/// [`fresnel_conductor_channel`] for each RGB channel.
#[inline]
pub fn fresnel_conductor(cos_theta_i: f32, eta: Rgb, k: Rgb) -> Rgb {
    Vec3::new(
        fresnel_conductor_channel(cos_theta_i, eta.x, k.x),
        fresnel_conductor_channel(cos_theta_i, eta.y, k.y),
        fresnel_conductor_channel(cos_theta_i, eta.z, k.z),
    )
}

/// Hemispherically averaged dielectric reflectance `2 ∫ F(μ) μ dμ`, by Mitsuba's fits (Egan and
/// Hilgeman for eta < 1, d'Eon and Irving otherwise) so that `plastic` matches it.
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let inv = 1.0 / eta;
    if eta < 1.0 {
        0.0636 * inv + eta * (eta * -1.4399 + 0.7099) + 0.6681
    } else {
        let coeffs = [0.919317f32, -3.4793, 6.75335, -7.80989, 4.98554, -1.36881];
        coeffs.iter().rev().fold(0.0, |acc, c| acc * inv + c)
    }
}

/// Mirror reflection of `w` about +z in the local frame.
#[inline]
pub fn reflect_z(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

/// Mirror reflection of `w` about the unit normal `m`.
#[inline]
pub fn reflect(w: Vec3, m: Vec3) -> Vec3 {
    2.0 * w.dot(m) * m - w
}

/// Refraction of `w` (pointing away from the surface) through the unit normal `m`, for
/// `eta` = interior / exterior where `m` points to the exterior. Returns the refracted direction
/// and the relative index n_t / n_i, or `None` on total internal reflection.
#[inline]
pub fn refract(w: Vec3, m: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let mut cos_i = w.dot(m);
    let (mut eta, mut m) = (eta, m);
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
        m = -m;
    }
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-w / eta + (cos_i / eta - cos_t) * m, eta))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_fresnel_known_values() {
        // normal incidence: ((eta-1)/(eta+1))^2 = 0.04 for eta 1.5, from either side
        assert!((fresnel_dielectric(1.0, 1.5).0 - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric(-1.0, 1.5).0 - 0.04).abs() < 1e-6);
        // total internal reflection from inside beyond the critical angle
        assert_eq!(fresnel_dielectric(-0.5, 1.5).0, 1.0);
        // Snell: sin_t = sin_i / eta
        let (_, cos_t, eta_ti) = fresnel_dielectric(0.6, 1.5);
        assert!(((1.0 - cos_t * cos_t).sqrt() - 0.8 / 1.5).abs() < 1e-5 && cos_t < 0.0 && eta_ti == 1.5);
    }

    #[test]
    fn conductor_fresnel_limits() {
        // k = 0 reduces to the dielectric formula
        for c in [0.1f32, 0.5, 0.9, 1.0] {
            assert!((fresnel_conductor_channel(c, 1.5, 0.0) - fresnel_dielectric(c, 1.5).0).abs() < 1e-4);
        }
        // Mitsuba's default conductor (eta 0, k 1) is a perfect mirror
        assert!((fresnel_conductor_channel(0.3, 0.0, 1.0) - 1.0).abs() < 1e-5);
        // grazing incidence reflects everything
        assert!(fresnel_conductor_channel(0.0, 0.2, 3.9) > 0.999);
    }

    #[test]
    fn diffuse_fresnel_fit_matches_integral() {
        for eta in [1.0 / 1.5f32, 1.33, 1.5] {
            let n = 20_000;
            let integral: f32 = (0..n)
                .map(|i| {
                    let mu = (i as f32 + 0.5) / n as f32;
                    2.0 * fresnel_dielectric(mu, eta).0 * mu / n as f32
                })
                .sum();
            assert!(
                (fresnel_diffuse_reflectance(eta) - integral).abs() < 0.01,
                "eta {eta}: fit {} integral {integral}",
                fresnel_diffuse_reflectance(eta)
            );
        }
    }

    #[test]
    fn refraction_obeys_snell() {
        let w = Vec3::new(0.6, 0.0, 0.8);
        let (t, eta) = refract(w, Vec3::Z, 1.5).unwrap();
        assert!((eta - 1.5).abs() < 1e-6 && t.z < 0.0 && (t.length() - 1.0).abs() < 1e-5);
        assert!((t.x.abs() - 0.6 / 1.5).abs() < 1e-5);
        // reversing the path: from inside along t, light leaves along w
        let (back, eta2) = refract(t, Vec3::Z, 1.5).unwrap();
        assert!((back - w).length() < 1e-5, "{back}");
        assert!((eta2 - 1.0 / 1.5).abs() < 1e-6);
    }
}
