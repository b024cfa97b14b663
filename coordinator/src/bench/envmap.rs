//! `tessera bench envmap [WxH] [--file F]`: how long an environment map takes to become
//! render-ready (texels in linear RGB, sampling tables) and how much memory it holds. The
//! synthetic map is a sky with a small, bright sun, so the tables see a peaked distribution;
//! `--file` times a real image through the scene loader's path (decode, convert, tables).

use anyhow::{Context, bail};
use glam::{Mat3, Vec3};
use std::time::Instant;
use tessera_common::light::Envmap;
use tessera_common::math::Rgb;
use tessera_common::texture::{Bitmap, BitmapOptions, TextureLimits};

/// Arguments of `tessera bench envmap`.
#[derive(clap::Args, Debug, Clone)]
pub struct EnvmapArgs {
    /// Size of the synthetic map.
    #[arg(default_value = "8192x4096")]
    pub size: String,
    /// Also time this image file (any format `envmap` reads).
    #[arg(long)]
    pub file: Option<std::path::PathBuf>,
    /// Builds timed (the median is reported).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
}

/// Runs `tessera bench envmap`.
pub fn run(args: &EnvmapArgs) -> anyhow::Result<()> {
    let (w, h) = args
        .size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<usize>().ok()?, h.parse::<usize>().ok()?)))
        .with_context(|| format!("size \"{}\" must look like 8192x4096", args.size))?;
    if w < 2 || h < 2 || args.repeats == 0 {
        bail!("the map needs at least 2x2 texels and one repeat");
    }
    let texels = sky(w, h);
    let mut times = Vec::new();
    let mut bytes = 0;
    for _ in 0..args.repeats {
        let t = Instant::now();
        let map = Envmap::new(w, h, &texels, 1.0, Mat3::IDENTITY);
        times.push(t.elapsed().as_secs_f64());
        bytes = map.bytes();
    }
    times.sort_by(f64::total_cmp);
    println!(
        "envmap {w}x{h} (synthetic sky): tables built in {:.3} s (median of {}, min {:.3} s), {:.1} MB held ({:.1} bytes per texel), single thread",
        times[times.len() / 2],
        times.len(),
        times[0],
        bytes as f64 / 1e6,
        bytes as f64 / (w * h) as f64
    );
    if let Some(file) = &args.file {
        let t = Instant::now();
        let bitmap = Bitmap::load(file, BitmapOptions::default(), &TextureLimits::default())?;
        let decode = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (w, h) = (bitmap.width() as usize, bitmap.height() as usize);
        let texels = bitmap.linear_rgb();
        let convert = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let map = Envmap::from_texels(w, h, texels, 1.0, Mat3::IDENTITY);
        let tables = t.elapsed().as_secs_f64();
        println!(
            "envmap {} ({w}x{h}): decode {decode:.3} s, to linear RGB {convert:.3} s, tables {tables:.3} s; {:.1} MB held",
            file.display(),
            map.bytes() as f64 / 1e6
        );
    }
    Ok(())
}

/// A lat-long sky: a horizon-to-zenith gradient, a darker ground and a 2° sun of radiance 5000.
fn sky(w: usize, h: usize) -> Vec<Rgb> {
    let sun = Vec3::new(0.3, 0.6, -0.74).normalize();
    let cos_sun = 1.0f32.to_radians().cos();
    let mut texels = Vec::with_capacity(w * h);
    for j in 0..h {
        let theta = std::f32::consts::PI * j as f32 / (h - 1) as f32;
        for i in 0..w {
            let phi = 2.0 * std::f32::consts::PI * (i as f32 + 0.5) / w as f32;
            let d = Vec3::new(phi.sin() * theta.sin(), theta.cos(), -phi.cos() * theta.sin());
            let base = if d.y > 0.0 { Rgb::new(0.4, 0.6, 1.0) * (0.3 + 0.7 * d.y) } else { Rgb::splat(0.15) };
            texels.push(if d.dot(sun) > cos_sun { Rgb::splat(5000.0) } else { base });
        }
    }
    texels
}
