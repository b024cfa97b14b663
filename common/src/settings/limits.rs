//! What a job may ask of the machine that renders it: every setting is bounded by the work and
//! memory it implies, checked where a job is accepted (the coordinator, `tessera render`) and
//! again by a worker before it allocates anything for a tile.
//!
//! The memory of one tile is estimated from the settings and the film alone (the scene's own
//! memory is bounded where it is loaded): the film's sums, the light subpaths of an iteration
//! with their photon map, and an EMIS job's per-pixel moments. The estimate is of the order of
//! what a tile really takes, not a bound on it: it refuses settings that cannot fit (a million
//! light paths per pixel asked a worker for terabytes), not ones that might.

use super::{IntegratorName, RenderSettings, SettingsError, invalid};
use crate::emis::EmisMethod;
use crate::emis::candidate::CandidateConfig;
use crate::integrator::path::vertex::PathVertex;

/// How much work and memory one job may ask for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkLimits {
    /// Light subpaths one iteration may trace (ν × pixels).
    pub max_light_paths: u64,
    /// Connections per camera vertex.
    pub max_connections: u32,
    /// Samples (iterations) per pixel.
    pub max_spp: u32,
    /// Estimated memory of one tile while it renders, in bytes.
    pub max_tile_bytes: u64,
}

/// The most iterations a job renders, whatever its budget: a time budget ends here however
/// much time is left, so that no iteration count can overflow.
pub const MAX_SPP: u32 = 1 << 24;

/// [`WorkLimits::max_tile_bytes`] unless configured.
pub const DEFAULT_MAX_TILE_BYTES: u64 = 16 << 30;

impl WorkLimits {
    /// The defaults.
    pub const DEFAULT: WorkLimits = WorkLimits {
        // eight light paths per pixel of a 2048² film
        max_light_paths: 1 << 25,
        max_connections: 64,
        max_spp: MAX_SPP,
        max_tile_bytes: DEFAULT_MAX_TILE_BYTES,
    };
}

impl Default for WorkLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Light subpath vertices an iteration is expected to store per path: Russian roulette ends
/// most paths within a few bounces, whatever `max_depth` allows.
const VERTICES_PER_LIGHT_PATH: u64 = 6;
/// Bytes a photon-map entry takes besides its vertex.
const PHOTON_BYTES: u64 = 16;
/// Bytes per pixel of a tile's sums (RGB and weight in f64, the count, the light tracer's
/// splats) and of what the renderer keeps beside them.
const FILM_BYTES_PER_PIXEL: u64 = 96;
/// Bytes per pixel of an EMIS job's guides and image estimates besides its moments.
const EMIS_BYTES_PER_PIXEL: u64 = 64;

/// Light subpaths an iteration traces for `nu` per pixel, as the integrators count them.
fn light_paths(nu: f64, pixels: u64) -> u64 {
    if nu <= 0.0 { 0 } else { ((nu * pixels as f64).floor() as u64).max(1) }
}

impl RenderSettings {
    /// The light subpaths per iteration the settings may trace on a film of `pixels` (for
    /// EMIS, those of its largest candidate).
    pub fn light_paths_per_iteration(&self, pixels: u64) -> u64 {
        let nu = match self.integrator.emis_method() {
            Some(EmisMethod::Vcm) => CandidateConfig::vcm().max_nu(),
            Some(EmisMethod::Bdpt) => CandidateConfig::bdpt().max_nu(),
            None if self.integrator == IntegratorName::Pt => 0.0,
            None => self.light_paths_per_pixel as f64,
        };
        light_paths(nu, pixels)
    }

    /// About the memory one tile of these settings takes on a `width`×`height` film (a
    /// full-frame tile; a path-tracing tile is at most a 64² part of it).
    pub fn tile_bytes(&self, width: u32, height: u32) -> u64 {
        let pixels = width as u64 * height as u64;
        let film = pixels.saturating_mul(FILM_BYTES_PER_PIXEL);
        let vertices = self.light_paths_per_iteration(pixels).saturating_mul(VERTICES_PER_LIGHT_PATH);
        let light = vertices.saturating_mul(std::mem::size_of::<PathVertex>() as u64 + PHOTON_BYTES);
        let emis = match self.integrator.emis_method() {
            Some(m) => {
                let candidates = match m {
                    EmisMethod::Vcm => CandidateConfig::vcm().candidates().len(),
                    EmisMethod::Bdpt => CandidateConfig::bdpt().candidates().len(),
                } as u64;
                pixels.saturating_mul(candidates * 4 + EMIS_BYTES_PER_PIXEL)
            }
            None => 0,
        };
        film.saturating_add(light).saturating_add(emis)
    }

    /// Checks the settings against `limits` for a `width`×`height` film; the error names the
    /// field and what it would cost.
    pub fn check_work(&self, width: u32, height: u32, limits: &WorkLimits) -> Result<(), SettingsError> {
        if let Some(spp) = self.spp.filter(|&s| s > limits.max_spp) {
            return Err(invalid("spp", format!("{spp} is over the limit of {}", limits.max_spp)));
        }
        if self.connections > limits.max_connections {
            let c = self.connections;
            return Err(invalid(
                "connections",
                format!("{c} per camera vertex is over the limit of {}", limits.max_connections),
            ));
        }
        let paths = self.light_paths_per_iteration(width as u64 * height as u64);
        if paths > limits.max_light_paths {
            return Err(invalid(
                "light_paths_per_pixel",
                format!(
                    "{} per pixel of a {width}×{height} film traces {paths} light paths an iteration, over the limit of {}",
                    self.light_paths_per_pixel, limits.max_light_paths
                ),
            ));
        }
        let bytes = self.tile_bytes(width, height);
        if bytes > limits.max_tile_bytes {
            return Err(invalid(
                "integrator",
                format!(
                    "{} on a {width}×{height} film needs about {} MiB per tile, over the limit of {} MiB",
                    self.integrator.as_str(),
                    bytes >> 20,
                    limits.max_tile_bytes >> 20
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings(integrator: IntegratorName, nu: f32) -> RenderSettings {
        RenderSettings { integrator, light_paths_per_pixel: nu, spp: Some(4), ..Default::default() }
    }

    #[test]
    fn a_million_light_paths_per_pixel_are_refused_naming_the_field() {
        let limits = WorkLimits::default();
        assert!(settings(IntegratorName::Vcm, 1.0).check_work(1920, 1080, &limits).is_ok());
        let e = settings(IntegratorName::Lt, 1e6).check_work(256, 256, &limits).unwrap_err().to_string();
        assert!(e.contains("light_paths_per_pixel") && e.contains("65536000000"), "{e}");
        let many = RenderSettings { connections: 1000, ..settings(IntegratorName::Bdpt, 1.0) };
        assert!(many.check_work(64, 64, &limits).unwrap_err().to_string().contains("connections"));
        let spp = RenderSettings { spp: Some(u32::MAX), ..settings(IntegratorName::Pt, 0.0) };
        assert!(spp.check_work(64, 64, &limits).unwrap_err().to_string().contains("spp"));
    }

    #[test]
    fn tile_memory_grows_with_the_film_and_emis_moments() {
        let pt = settings(IntegratorName::Pt, 0.0).tile_bytes(1920, 1080);
        let vcm = settings(IntegratorName::Vcm, 1.0).tile_bytes(1920, 1080);
        let emis = settings(IntegratorName::EmisVcm, 1.0).tile_bytes(1920, 1080);
        assert!(pt < vcm && vcm < emis, "{pt} {vcm} {emis}");
        // an EMIS-VCM tile at 1080p takes a few GB (issue 69 saw 2-3 GB)
        assert!((1 << 30..8 << 30).contains(&emis), "{emis}");
        let huge = settings(IntegratorName::EmisVcm, 1.0);
        let e = huge.check_work(4096, 4096, &WorkLimits::default()).unwrap_err().to_string();
        assert!(e.contains("MiB per tile"), "{e}");
    }
}
