//! Gathering a full path's pdf arrays from a light subpath and a camera subpath, for the MIS
//! weights of [`super::mis`]. The stored densities of both subpaths are copied; the densities
//! around the join (which depend on the technique) are set by the caller through [`Join`].

use super::mis::PathPdfs;
use super::vertex::PathVertex;

/// Densities that exist only once the two subpaths are joined.
#[derive(Clone, Copy, Debug, Default)]
pub struct Join {
    /// Density of the last camera vertex when sampled from the last light vertex.
    pub camera_end_from_light: f32,
    /// Density of the camera vertex before it, when sampled from the last camera vertex coming
    /// from the light side (0 if that vertex is the pinhole).
    pub camera_next_from_light: f32,
    /// Density of the last light vertex when sampled from the last camera vertex.
    pub light_end_from_camera: f32,
    /// Density of the light vertex before it, when sampled from the last light vertex coming
    /// from the camera side.
    pub light_next_from_camera: f32,
    /// Next-event density of the light vertex (vertex 0).
    pub next_event0: f32,
    /// The light subpath's last vertex arrived at by sampling (a merge) rather than evaluated
    /// (a connection): its delta flag then stays as traced.
    pub light_end_sampled: bool,
}

/// The pdf arrays of the path `light[0..s]` + `camera[t-1..=0]` (camera subpath in camera
/// order, `camera[0]` the pinhole). Either subpath may be empty but not both.
/// `infinite_light` says whether the path's light vertex lies on an infinite light.
pub fn gather(light: &[PathVertex], camera: &[PathVertex], join: &Join, infinite_light: bool) -> PathPdfs {
    let (s, t) = (light.len(), camera.len());
    let mut p = PathPdfs::new(s + t);
    for (i, v) in light.iter().enumerate() {
        p.from_light[i] = v.pdf_fwd;
        p.from_camera[i] = v.pdf_rev;
        p.delta[i] = v.delta;
    }
    for (j, v) in camera.iter().enumerate() {
        let i = s + t - 1 - j;
        p.from_camera[i] = v.pdf_fwd;
        p.from_light[i] = v.pdf_rev;
        p.delta[i] = v.delta;
    }
    // the join: the connection itself is evaluated, never sampled through a delta lobe
    if t >= 1 {
        p.from_light[s] = join.camera_end_from_light;
        p.delta[s] = false;
        if t >= 2 {
            p.from_light[s + 1] = join.camera_next_from_light;
        }
    }
    if s >= 1 {
        p.from_camera[s - 1] = join.light_end_from_camera;
        if !join.light_end_sampled {
            p.delta[s - 1] = false;
        }
        if s >= 2 {
            p.from_camera[s - 2] = join.light_next_from_camera;
        }
    }
    p.next_event0 = join.next_event0;
    // a light vertex's delta flag marks a delta light (a point, a spot, one direction): no
    // camera path can hit it, while next-event estimation and light tracing reach it as usual
    if let Some(v) = light.first().filter(|v| matches!(v.kind, super::vertex::VertexKind::Light { .. })) {
        p.emitter_hittable = !v.delta;
        p.delta[0] = false;
    }
    p.emitter_splattable = !infinite_light;
    p
}
