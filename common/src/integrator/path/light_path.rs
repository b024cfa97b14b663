//! Tracing light subpaths: a light is chosen, a ray is emitted, and each surface the path
//! reaches becomes a vertex, until `max_edges` edges or absorption. The densities needed by the
//! MIS weights are recorded on the way (forward on each vertex, reverse on its predecessor).

use super::vertex::{PathVertex, VertexKind, density_at_vertex, solid_angle_to_area};
use crate::bsdf::TransportMode;
use crate::light::Light;
use crate::math::Rgb;
use crate::sampler::Sampler;
use crate::scene::Scene;
use glam::Vec3;

/// Light paths traced per task; splats are merged in task order, so results do not depend on
/// the thread count.
pub const LIGHT_PATH_CHUNK: u32 = 256;

/// Longest subpath, in edges, the bidirectional integrators trace.
pub const MAX_BIDIR_EDGES: u32 = (super::mis::MAX_VERTICES - 2) as u32;

/// Number of light paths per iteration for ν and P pixels: ⌊ν·P⌋, at least 1 unless ν = 0
/// (no light paths: the bidirectional engine then path traces with hits and NEE only).
pub fn light_path_count(nu: f32, pixels: u32) -> u32 {
    if nu <= 0.0 { 0 } else { ((nu as f64 * pixels as f64).floor() as u32).max(1) }
}

/// Traces one light subpath into `out` (appending), with Russian roulette from `rr_depth` on
/// (survival min(max throughput relative to emission · η², 0.95), as camera paths use).
/// Returns the number of vertices appended (0 when the scene has no light or the emission
/// sample failed).
pub fn trace_light_path(
    scene: &Scene,
    sampler: &mut Sampler,
    max_edges: u32,
    rr_depth: u32,
    out: &mut Vec<PathVertex>,
) -> usize {
    let start = out.len();
    let Some((li, pmf, _)) = scene.light_sampler.sample(sampler.next_1d()) else { return 0 };
    let light = &scene.lights[li];
    let ctx = scene.light_context();
    let (u_pos, u_dir) = (sampler.next_2d(), sampler.next_2d());
    let Some(e) = light.sample_emission(&ctx, u_pos, u_dir) else { return 0 };
    if e.pdf_pos <= 0.0 || e.pdf_dir <= 0.0 || e.radiance == Rgb::ZERO {
        return 0;
    }
    let infinite = light.is_infinite();
    // the light vertex's own density: position (area) for finite lights, direction for infinite
    let pdf_origin = pmf * if infinite { e.pdf_dir } else { e.pdf_pos };
    out.push(PathVertex {
        p: e.p,
        n_geo: e.n,
        n_shading: e.n,
        tangent: Vec3::ZERO,
        wo: Vec3::ZERO,
        beta: Rgb::splat(1.0 / (pmf * e.pdf_pos)),
        pdf_fwd: pdf_origin,
        pdf_rev: 0.0,
        pdf_next_event: 0.0,
        kind: VertexKind::Light { light: li as u32, at: e.at },
        // on a light vertex: a delta light, which no camera path can hit
        delta: light.is_delta(),
        depth: 0,
    });
    if max_edges == 0 {
        return 1;
    }
    // importance leaving the light: Le |cos| / (pmf pdf_pos pdf_dir)
    let cos0 = if e.n == Vec3::ZERO || infinite { 1.0 } else { e.n.dot(e.d).abs() };
    let mut beta = e.radiance * (cos0 / (pmf * e.pdf_pos * e.pdf_dir));
    let beta_start = beta.max_element().max(1e-30);
    let mut eta = 1.0f32;
    let mut ray = crate::geometry::Ray::new(e.p, e.d);
    if !infinite && e.n != Vec3::ZERO {
        ray.o = crate::geometry::offset_ray_origin(e.p, e.n, e.d);
    }
    // density of the next vertex: direction pdf (finite lights) or disk position pdf (infinite)
    let mut pdf_dir = if infinite { e.pdf_pos } else { e.pdf_dir };
    let mut prev_p = e.p;
    let mut prev_infinite = infinite;
    loop {
        let Some(hit) = scene.intersect(&ray) else { break };
        let shape = &scene.shapes[hit.shape as usize];
        let depth = (out.len() - start) as u32;
        let pdf_fwd = if prev_infinite {
            pdf_dir * hit.n_geo.dot(ray.d).abs()
        } else {
            solid_angle_to_area(pdf_dir, prev_p, hit.p, hit.n_geo)
        };
        let mut v = PathVertex {
            p: hit.p,
            n_geo: hit.n_geo,
            n_shading: hit.frame.n,
            tangent: scene.vertex_tangent(&hit),
            wo: hit.wo,
            beta,
            pdf_fwd,
            pdf_rev: 0.0,
            pdf_next_event: 0.0,
            kind: VertexKind::Surface { material: shape.material, at: hit.surface() },
            delta: false,
            depth,
        };
        if depth == 1 {
            v.pdf_next_event = next_event_density(scene, &out[start], &v);
        }
        out.push(v);
        if depth >= max_edges {
            break;
        }
        // ---- continue: sample the BSDF in importance mode ----
        let material = scene.material_at(shape.material, hit.surface(), hit.p);
        let frame = hit.frame;
        let wo_local = frame.to_local(hit.wo);
        let (uc, u) = (sampler.next_1d(), sampler.next_2d());
        let Some(bs) = material.sample(wo_local, uc, u, TransportMode::Importance) else { break };
        let wi = frame.to_world(bs.wi);
        let current = out.len() - 1;
        let correction = out[current].importance_correction(hit.wo, wi);
        beta *= bs.weight * correction;
        eta *= bs.eta;
        if beta == Rgb::ZERO || !beta.is_finite() {
            break;
        }
        if depth >= rr_depth {
            let q = (beta.max_element() / beta_start * eta * eta).min(0.95);
            if sampler.next_1d() >= q {
                break;
            }
            beta /= q;
        }
        // reverse density of the predecessor, sampled from here towards it
        let prev = out[current - 1];
        let pdf_rev_sa = if bs.delta { 0.0 } else { material.pdf(bs.wi, wo_local) };
        out[current - 1].pdf_rev = density_at_vertex(pdf_rev_sa, hit.p, &prev, infinite && current - 1 == start);
        out[current].delta = bs.delta;
        pdf_dir = if bs.delta { 0.0 } else { bs.pdf };
        prev_p = hit.p;
        prev_infinite = false;
        ray = hit.spawn_ray(wi);
    }
    out.len() - start
}

/// Density with which next-event estimation from surface vertex `v` would produce the light
/// vertex `light_vertex`, in the light vertex's measure (area, or solid angle for infinite
/// lights), including the light selection probability.
pub fn next_event_density(scene: &Scene, light_vertex: &PathVertex, v: &PathVertex) -> f32 {
    let VertexKind::Light { light, .. } = light_vertex.kind else { return 0.0 };
    let l = &scene.lights[light as usize];
    let pmf = scene.light_sampler.pmf(light as usize);
    let ctx = scene.light_context();
    match l {
        // a delta light is chosen by its selection probability alone
        Light::Point { .. } | Light::Spot(_) | Light::Directional { .. } => pmf,
        Light::Constant { .. } | Light::Envmap(_) => {
            pmf * l.pdf_direct(&ctx, v.p, v.p - light_vertex.n_geo, light_vertex.n_geo)
        }
        Light::Area { .. } => {
            let sa = l.pdf_direct(&ctx, v.p, light_vertex.p, light_vertex.n_geo);
            pmf * solid_angle_to_area(sa, v.p, light_vertex.p, light_vertex.n_geo)
        }
    }
}
