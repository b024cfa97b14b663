//! `tessera bench photon-map N`: build and query rates of the photon map for N photons spread
//! through a unit cube, queried at N points with a radius that finds about 10 photons each, on
//! one thread.

use tessera_common::integrator::path::photon_map::PhotonMap;
use tessera_common::integrator::path::vertex::PathVertex;
use tessera_common::sampler::Sampler;

/// Arguments of `tessera bench photon-map`.
#[derive(clap::Args, Debug, Clone)]
pub struct PhotonMapArgs {
    /// Photons (and queries).
    pub photons: u32,
}

/// Runs `tessera bench photon-map`.
pub fn run(args: &PhotonMapArgs) -> anyhow::Result<()> {
    let n = args.photons;
    let point = |seed: u64, i: u32| {
        let mut s = Sampler::for_pixel(seed, i, 0);
        let u = s.next_2d();
        glam::Vec3::new(u.x, u.y, s.next_1d())
    };
    let vertices: Vec<PathVertex> = (0..n).map(|i| PathVertex::surface_at(point(1, i))).collect();
    let all: Vec<u32> = (0..n).collect();
    let radius = (10.0 / (n as f32 * 4.0 / 3.0 * std::f32::consts::PI)).cbrt();
    let t = std::time::Instant::now();
    let map = PhotonMap::build(&vertices, &all, radius);
    let build = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let mut found = 0u64;
    for i in 0..n {
        map.query(point(2, i), radius, |_, _| found += 1);
    }
    let query = t.elapsed().as_secs_f64();
    println!(
        "photon map, {n} photons: build {:.3} s ({:.1} M photons/s); {n} queries of radius {radius:.4} in {:.3} s ({:.2} M queries/s, {:.1} photons found per query, single thread)",
        build,
        n as f64 / build / 1e6,
        query,
        n as f64 / query / 1e6,
        found as f64 / n as f64
    );
    Ok(())
}
