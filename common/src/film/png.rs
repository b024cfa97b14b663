//! 8-bit sRGB PNG previews: linear values clamped to [0, 1] and encoded with the sRGB transfer
//! curve, no other tone mapping (what Mitsuba's `write_bitmap` does for previews).

use std::path::Path;

/// The sRGB opto-electronic transfer function.
#[inline]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 };
    if x <= 0.003_130_8 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 }
}

/// Writes a preview PNG.
pub fn write_png(path: &Path, width: u32, height: u32, rgb: &[[f32; 3]]) -> Result<(), image::ImageError> {
    let bytes: Vec<u8> = rgb.iter().flat_map(|p| p.map(|c| (linear_to_srgb(c) * 255.0 + 0.5) as u8)).collect();
    image::save_buffer(path, &bytes, width, height, image::ColorType::Rgb8)
}
