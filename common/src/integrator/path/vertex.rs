//! Path vertices as the bidirectional integrators store them: position, normals, throughput
//! and the densities the MIS weights need, in both directions.

use crate::geometry::SurfaceRef;
use crate::math::{Frame, Rgb};
use glam::Vec3;

/// What a vertex is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexKind {
    /// The first vertex of a light path, on light `light`.
    Light {
        /// Index into `Scene::lights`.
        light: u32,
        /// Where on its shape, for an area light (textured radiance).
        at: SurfaceRef,
    },
    /// The camera (pinhole) at the start of a camera path.
    Camera,
    /// A surface scattering vertex.
    Surface {
        /// Index into `Scene::materials`.
        material: u32,
        /// Where on which shape, to resolve a textured material (see `Scene::material_at`).
        at: SurfaceRef,
    },
}

/// One vertex of a camera or light subpath.
#[derive(Clone, Copy, Debug)]
pub struct PathVertex {
    /// Position (for an infinite light: a point on the disk the path starts from).
    pub p: Vec3,
    /// Geometric normal (for point lights zero; for infinite lights the direction of travel).
    pub n_geo: Vec3,
    /// Shading normal.
    pub n_shading: Vec3,
    /// First tangent of the shading frame where an anisotropic material needs Mitsuba's (see
    /// `Scene::intersect`); zero where the frame follows from the normal alone.
    pub tangent: Vec3,
    /// Unit direction towards the previous vertex (zero on the first vertex).
    pub wo: Vec3,
    /// Throughput of the subpath up to this vertex (importance for light paths, weighted by the
    /// inverse sampling densities). On a light vertex: 1 / (light selection · position pdf).
    pub beta: Rgb,
    /// Area density of this vertex when sampled from its predecessor along the subpath (0
    /// when sampled through a delta lobe).
    pub pdf_fwd: f32,
    /// Area density of the predecessor when sampled from this vertex in the reverse direction.
    pub pdf_rev: f32,
    /// On depth-1 light vertices: density of the light vertex under next-event estimation from
    /// here, in the light vertex's measure.
    pub pdf_next_event: f32,
    /// Kind and material or light.
    pub kind: VertexKind,
    /// The direction leaving this vertex was sampled from a delta lobe.
    pub delta: bool,
    /// Edges from the start of the subpath.
    pub depth: u32,
}

impl PathVertex {
    /// A surface vertex at `p` facing +z with unit throughput (photon-map tests and benchmarks).
    pub fn surface_at(p: Vec3) -> Self {
        PathVertex {
            p,
            n_geo: Vec3::Z,
            n_shading: Vec3::Z,
            tangent: Vec3::ZERO,
            wo: Vec3::Z,
            beta: Rgb::ONE,
            pdf_fwd: 1.0,
            pdf_rev: 0.0,
            pdf_next_event: 0.0,
            kind: VertexKind::Surface { material: 0, at: SurfaceRef::default() },
            delta: false,
            depth: 1,
        }
    }

    /// The shading frame.
    #[inline]
    pub fn frame(&self) -> Frame {
        if self.tangent == Vec3::ZERO {
            Frame::from_normal(self.n_shading)
        } else {
            Frame { s: self.tangent, t: self.n_shading.cross(self.tangent), n: self.n_shading }
        }
    }

    /// Shading-normal correction of importance transport (Veach 1997, §5.3): the factor that
    /// makes a light path's throughput estimate the same integrand a camera path does, for the
    /// directions `w_prev` (towards the light side) and `w_next`.
    #[inline]
    pub fn importance_correction(&self, w_prev: Vec3, w_next: Vec3) -> f32 {
        let num = self.n_shading.dot(w_prev).abs() * self.n_geo.dot(w_next).abs();
        let den = self.n_geo.dot(w_prev).abs() * self.n_shading.dot(w_next).abs();
        if den > 0.0 { num / den } else { 0.0 }
    }
}

/// Converts a solid-angle density of sampling, from point `from`, the direction towards vertex
/// `to` into the density of `to` in its own measure: area for surfaces and area lights, solid
/// angle for infinite lights, and 0 for point lights and the pinhole, which no ray can hit.
#[inline]
pub fn density_at_vertex(pdf: f32, from: Vec3, to: &PathVertex, infinite_light: bool) -> f32 {
    match to.kind {
        VertexKind::Camera => 0.0,
        VertexKind::Light { .. } if infinite_light => pdf,
        VertexKind::Light { .. } if to.n_geo == Vec3::ZERO => 0.0,
        _ => solid_angle_to_area(pdf, from, to.p, to.n_geo),
    }
}

/// Converts a solid-angle density at `from` towards `to` into an area density at `to`, whose
/// geometric normal is `n_to` (no cosine for points without a surface, i.e. zero normals).
#[inline]
pub fn solid_angle_to_area(pdf: f32, from: Vec3, to: Vec3, n_to: Vec3) -> f32 {
    let d = to - from;
    let dist2 = d.length_squared();
    if dist2 == 0.0 {
        return 0.0;
    }
    let cos = if n_to == Vec3::ZERO { 1.0 } else { n_to.dot(d).abs() / dist2.sqrt() };
    pdf * cos / dist2
}
