//! Mitsuba's `envmap`: radiance arriving from infinity, looked up in a latitude-longitude
//! image (linear RGB × `scale`), rotated by `to_world`.
//!
//! The lookup is Mitsuba's exactly (`src/emitters/envmap.cpp`): for a direction d in the map's
//! frame, u = atan2(d.x, −d.z)/2π wrapped to [0, 1) and v = acos(d.y)/π, so +y is up and u = 0
//! looks along −z; bilinear between texels whose columns are centred ((i + ½)/W, periodic)
//! and whose rows are corner-aligned (row j at v = j/(H − 1), row 0 at the zenith).
//!
//! Importance sampling is Tessera's own (any density covering the radiance gives the same
//! expectation): the sphere is cut into cells between neighbouring texel centres; a cell is
//! chosen with probability ∝ its solid angle × the largest luminance of its four texels (so
//! every direction with radiance has density), and a direction uniformly in its solid angle.

use crate::math::{PI, Rgb, luminance};
use glam::{Mat3, Vec2, Vec3};

/// An environment map ready for lookups and sampling.
#[derive(Clone, Debug)]
pub struct Envmap {
    width: usize,
    height: usize,
    /// Linear RGB × scale, row-major, row 0 at the top (v = 0, +y).
    texels: Vec<Rgb>,
    /// Map frame to world (a rotation), and back.
    to_world: Mat3,
    to_local: Mat3,
    /// Per cell (row-major, W × (H − 1)): the cumulative sampling weight, for binary search.
    cdf: Vec<f64>,
    /// Per cell: its probability over its solid angle (the solid-angle density inside it).
    density: Vec<f32>,
}

/// The map's (u, v) of a direction in its own frame.
#[inline]
fn direction_to_uv(d: Vec3) -> Vec2 {
    let u = d.x.atan2(-d.z) * (0.5 / PI);
    Vec2::new(u - u.floor(), d.y.clamp(-1.0, 1.0).acos() / PI)
}

/// A direction in the map's frame from (u, v).
#[inline]
fn uv_to_direction(uv: Vec2) -> Vec3 {
    let (sin_t, cos_t) = (uv.y * PI).sin_cos();
    let (sin_p, cos_p) = (uv.x * 2.0 * PI).sin_cos();
    Vec3::new(sin_p * sin_t, cos_t, -cos_p * sin_t)
}

impl Envmap {
    /// A map from `width × height` linear RGB texels (row 0 at the top), multiplied by `scale`
    /// and rotated by `to_world` (which must be a rotation). Images smaller than 2×3 are
    /// padded as Mitsuba pads them (edge texels repeated).
    pub fn new(width: usize, height: usize, texels: &[Rgb], scale: f32, to_world: Mat3) -> Envmap {
        assert_eq!(texels.len(), width * height, "invariant: texel count matches the size");
        let (w, h) = (width.max(2), height.max(3));
        let texels: Vec<Rgb> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w).min(width - 1), (i / w).min(height - 1));
                texels[y * width + x] * scale
            })
            .collect();
        let mut map = Envmap {
            width: w,
            height: h,
            texels,
            to_world,
            to_local: to_world.transpose(),
            cdf: Vec::new(),
            density: Vec::new(),
        };
        map.build_distribution();
        map
    }

    /// The cells' sampling weights and densities.
    fn build_distribution(&mut self) {
        let (w, h) = (self.width, self.height);
        let (mut cdf, mut weights) = (Vec::with_capacity(w * (h - 1)), Vec::with_capacity(w * (h - 1)));
        let mut total = 0.0f64;
        for j in 0..h - 1 {
            let solid_angle = self.cell_solid_angle(j);
            for i in 0..w {
                let lum = [(i, j), ((i + 1) % w, j), (i, j + 1), ((i + 1) % w, j + 1)]
                    .iter()
                    .map(|&(x, y)| luminance(self.texels[y * w + x]).max(0.0))
                    .fold(0.0f32, f32::max);
                let weight = lum as f64 * solid_angle;
                total += weight;
                cdf.push(total);
                weights.push(lum);
            }
        }
        // the densities: P(cell) / Ω(cell) = lum / Σ lum·Ω; an all-black map is sampled uniformly
        let (cdf, density) = if total > 0.0 {
            (cdf, weights.iter().map(|&l| (l as f64 / total) as f32).collect())
        } else {
            let cells = (w * (h - 1)) as f64;
            let uniform: Vec<f64> = (0..w * (h - 1)).map(|k| (k + 1) as f64 / cells).collect();
            (uniform, vec![(1.0 / (4.0 * std::f64::consts::PI)) as f32; w * (h - 1)])
        };
        self.cdf = cdf;
        self.density = density;
    }

    /// Solid angle of a cell of row band `j` (between rows j and j + 1).
    fn cell_solid_angle(&self, j: usize) -> f64 {
        let band = |j: usize| (std::f64::consts::PI * j as f64 / (self.height - 1) as f64).cos();
        2.0 * std::f64::consts::PI / self.width as f64 * (band(j) - band(j + 1))
    }

    /// Radiance arriving from world direction `d` (pointing away from the scene).
    pub fn eval(&self, d: Vec3) -> Rgb {
        let uv = direction_to_uv(self.to_local * d);
        let (w, h) = (self.width, self.height);
        let x = uv.x * w as f32 - 0.5;
        let y = uv.y.clamp(0.0, 1.0) * (h - 1) as f32;
        let (x0, y0) = (x.floor(), y.floor().min((h - 2) as f32));
        let (fx, fy) = (x - x0, y - y0);
        let col = |c: f32| (c as i64).rem_euclid(w as i64) as usize;
        let (c0, c1, r0) = (col(x0), col(x0 + 1.0), y0 as usize);
        let t = |c: usize, r: usize| self.texels[r * w + c];
        let top = t(c0, r0) * (1.0 - fx) + t(c1, r0) * fx;
        let bottom = t(c0, r0 + 1) * (1.0 - fx) + t(c1, r0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// Samples a world direction towards the map (away from the scene) with two uniform
    /// numbers; returns it with its solid-angle density.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        let total = *self.cdf.last()?;
        let target = u.x as f64 * total;
        let cell = self.cdf.partition_point(|&c| c <= target).min(self.cdf.len() - 1);
        let lo = if cell == 0 { 0.0 } else { self.cdf[cell - 1] };
        let span = self.cdf[cell] - lo;
        let reuse = if span > 0.0 { ((target - lo) / span) as f32 } else { 0.5 };
        let (i, j) = (cell % self.width, cell / self.width);
        // uniform in the cell's solid angle: φ uniform, cos θ uniform
        let (w, h) = (self.width as f32, (self.height - 1) as f32);
        let u_coord = (i as f32 + 0.5 + reuse.clamp(0.0, 1.0)) / w;
        let (c0, c1) = ((PI * j as f32 / h).cos(), (PI * (j + 1) as f32 / h).cos());
        let cos_t = c0 + (c1 - c0) * u.y;
        let v_coord = cos_t.clamp(-1.0, 1.0).acos() / PI;
        let d = self.to_world * uv_to_direction(Vec2::new(u_coord - u_coord.floor(), v_coord));
        let pdf = self.density[cell];
        (pdf > 0.0).then_some((d, pdf))
    }

    /// The solid-angle density of [`Envmap::sample`] producing world direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        let uv = direction_to_uv(self.to_local * d);
        // cells start at texel centres
        let x = uv.x * self.width as f32 - 0.5;
        let i = (x.floor() as i64).rem_euclid(self.width as i64) as usize;
        let j = ((uv.y * (self.height - 1) as f32) as usize).min(self.height - 2);
        self.density[j * self.width + i]
    }

    /// Mean luminance of the radiance over the sphere (for light selection and EMIS).
    pub fn power(&self) -> f32 {
        let mut sum = 0.0f64;
        for j in 0..self.height - 1 {
            let omega = self.cell_solid_angle(j);
            for i in 0..self.width {
                let corners = [(i, j), ((i + 1) % self.width, j), (i, j + 1), ((i + 1) % self.width, j + 1)];
                let mean = corners.iter().map(|&(x, y)| luminance(self.texels[y * self.width + x]) as f64).sum::<f64>();
                sum += mean / 4.0 * omega;
            }
        }
        (sum / (4.0 * std::f64::consts::PI)) as f32
    }

    /// Bytes a map built from a `width × height` image will use (before padding small ones).
    pub fn bytes_for(width: usize, height: usize) -> usize {
        width.max(2) * height.max(3) * (std::mem::size_of::<Rgb>() + 8 + 4)
    }

    /// Bytes the map's texels and tables use.
    pub fn bytes(&self) -> usize {
        self.texels.len() * std::mem::size_of::<Rgb>() + self.cdf.len() * 8 + self.density.len() * 4
    }
}

#[cfg(test)]
mod tests;
