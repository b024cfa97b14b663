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
//! The choice is two-level, a row band by an f64 marginal and a cell within it by an f32
//! conditional table, so the tables add 4 bytes per texel to the texels' 12; densities are
//! read back from the same tables, so sampling and density agree exactly.

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
    /// Per row band (H − 1): the cumulative probability of choosing it, ending at 1.
    marginal: Vec<f64>,
    /// Per cell (row-major, W × (H − 1)): the cumulative probability of the cell within its
    /// band, ending at 1 in every band with weight.
    conditional: Vec<f32>,
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
        Self::from_texels(width, height, texels.to_vec(), scale, to_world)
    }

    /// [`Envmap::new`] taking the texels over, so that a big map is not copied.
    pub fn from_texels(width: usize, height: usize, texels: Vec<Rgb>, scale: f32, to_world: Mat3) -> Envmap {
        assert_eq!(texels.len(), width * height, "invariant: texel count matches the size");
        let (w, h) = (width.max(2), height.max(3));
        let texels: Vec<Rgb> = if (w, h) == (width, height) {
            let mut texels = texels;
            texels.iter_mut().for_each(|t| *t = *t * scale);
            texels
        } else {
            (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w).min(width - 1), (i / w).min(height - 1));
                    texels[y * width + x] * scale
                })
                .collect()
        };
        let mut map = Envmap {
            width: w,
            height: h,
            texels,
            to_world,
            to_local: to_world.transpose(),
            marginal: Vec::new(),
            conditional: Vec::new(),
        };
        map.build_distribution();
        map
    }

    /// The cells' sampling tables. An all-black map is sampled uniformly.
    fn build_distribution(&mut self) {
        let (w, h) = (self.width, self.height);
        let mut conditional = Vec::with_capacity(w * (h - 1));
        let mut bands = Vec::with_capacity(h - 1);
        let lum = |x: usize, y: usize| luminance(self.texels[y * w + x]).max(0.0);
        for j in 0..h - 1 {
            let start = conditional.len();
            let mut sum = 0.0f64;
            for i in 0..w {
                let i1 = (i + 1) % w;
                sum += lum(i, j).max(lum(i1, j)).max(lum(i, j + 1)).max(lum(i1, j + 1)) as f64;
                conditional.push(sum as f32);
            }
            let row = &mut conditional[start..];
            if sum > 0.0 {
                row.iter_mut().for_each(|c| *c = (*c as f64 / sum) as f32);
            } else {
                row.iter_mut().enumerate().for_each(|(i, c)| *c = (i + 1) as f32 / w as f32);
            }
            row[w - 1] = 1.0;
            bands.push(sum * self.cell_solid_angle(j));
        }
        let total: f64 = bands.iter().sum();
        let mut acc = 0.0;
        let marginal: Vec<f64> = bands
            .iter()
            .enumerate()
            .map(|(j, b)| {
                acc += if total > 0.0 {
                    b / total
                } else {
                    self.cell_solid_angle(j) * w as f64 / (4.0 * std::f64::consts::PI)
                };
                acc
            })
            .collect();
        self.marginal = marginal;
        if let Some(last) = self.marginal.last_mut() {
            *last = 1.0;
        }
        self.conditional = conditional;
    }

    /// Probability of choosing band `j`, and cell `i` within it.
    #[inline]
    fn cell_probability(&self, i: usize, j: usize) -> f64 {
        let band = self.marginal[j] - if j == 0 { 0.0 } else { self.marginal[j - 1] };
        let row = &self.conditional[j * self.width..(j + 1) * self.width];
        let cell = row[i] as f64 - if i == 0 { 0.0 } else { row[i - 1] as f64 };
        band * cell
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
        let w = self.width;
        let ux = u.x as f64;
        let j = self.marginal.partition_point(|&c| c <= ux).min(self.marginal.len() - 1);
        let lo = if j == 0 { 0.0 } else { self.marginal[j - 1] };
        let span = self.marginal[j] - lo;
        // the first number, reused within the band to choose the cell
        let v = if span > 0.0 { ((ux - lo) / span) as f32 } else { 0.5 };
        let row = &self.conditional[j * w..(j + 1) * w];
        let i = row.partition_point(|&c| c <= v).min(w - 1);
        let lo = if i == 0 { 0.0 } else { row[i - 1] };
        let span = row[i] - lo;
        let reuse = if span > 0.0 { (v - lo) / span } else { 0.5 };
        // uniform in the cell's solid angle: φ uniform, cos θ uniform
        let (wf, hf) = (w as f32, (self.height - 1) as f32);
        let u_coord = (i as f32 + 0.5 + reuse.clamp(0.0, 1.0)) / wf;
        let (c0, c1) = ((PI * j as f32 / hf).cos(), (PI * (j + 1) as f32 / hf).cos());
        let cos_t = c0 + (c1 - c0) * u.y;
        let v_coord = cos_t.clamp(-1.0, 1.0).acos() / PI;
        let d = self.to_world * uv_to_direction(Vec2::new(u_coord - u_coord.floor(), v_coord));
        let pdf = self.cell_density(i, j);
        (pdf > 0.0).then_some((d, pdf))
    }

    /// Solid-angle density inside cell (i, j).
    #[inline]
    fn cell_density(&self, i: usize, j: usize) -> f32 {
        (self.cell_probability(i, j) / self.cell_solid_angle(j)) as f32
    }

    /// The solid-angle density of [`Envmap::sample`] producing world direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        let uv = direction_to_uv(self.to_local * d);
        // cells start at texel centres
        let x = uv.x * self.width as f32 - 0.5;
        let i = (x.floor() as i64).rem_euclid(self.width as i64) as usize;
        let j = ((uv.y * (self.height - 1) as f32) as usize).min(self.height - 2);
        self.cell_density(i, j)
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
        width.max(2) * height.max(3) * (std::mem::size_of::<Rgb>() + 4) + height.max(3) * 8
    }

    /// Bytes the map's texels and tables use.
    pub fn bytes(&self) -> usize {
        self.texels.len() * std::mem::size_of::<Rgb>() + self.conditional.len() * 4 + self.marginal.len() * 8
    }
}

#[cfg(test)]
mod tests;
