//! The files a finished render produces, written alike by `tessera render` and by the
//! coordinator: the EXR (beauty, per-pixel sample counts and, for EMIS, the merge-mask and
//! relative-moment layers with the decisions as attributes), an sRGB PNG preview, and for EMIS
//! a strategy PNG and a JSON report of every update.

use image::ImageEncoder;
use image::codecs::png::{CompressionType, FilterType, PngEncoder};
use std::path::{Path, PathBuf};
use tessera_common::emis::{EmisState, UpdateReport};
use tessera_common::film::Film;
use tessera_common::film::exr::{Attribute, ExrExtras, write_exr};
use tessera_common::film::png::linear_to_srgb;
use tessera_common::integrator::path::connections::Connections;

/// Writing an output file failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutputError {
    /// The file could not be written.
    #[error("cannot write {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

/// Where a render's files go, from the path a user gave (`-o`): the EXR, with the PNG preview
/// and, for EMIS, the strategy PNG and JSON report beside it. A `.png` path names the preview
/// and the EXR goes beside it with `.exr`, so that no file overwrites another.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutputPaths {
    /// The EXR.
    pub exr: PathBuf,
    /// The sRGB preview.
    pub png: PathBuf,
    /// EMIS: the strategy PNG.
    pub strategy_png: PathBuf,
    /// EMIS: the report.
    pub emis_json: PathBuf,
}

impl OutputPaths {
    /// The files for `-o path`.
    pub fn new(path: &Path) -> OutputPaths {
        let is_png = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
        let (exr, png) = match is_png {
            true => (path.with_extension("exr"), path.to_path_buf()),
            false => (path.to_path_buf(), path.with_extension("png")),
        };
        OutputPaths {
            strategy_png: exr.with_extension("strategy.png"),
            emis_json: exr.with_extension("emis.json"),
            exr,
            png,
        }
    }
}

fn write_error(path: &Path, e: impl std::fmt::Display) -> OutputError {
    OutputError::Write { path: path.to_path_buf(), message: e.to_string() }
}

/// How a render was made, for the EXR's `tessera/*` attributes.
#[derive(Clone, Debug, Default)]
pub struct Provenance {
    /// Integrator name.
    pub integrator: String,
    /// Samples per pixel (iterations) in the image.
    pub spp: u32,
    /// Seed of all random numbers.
    pub seed: u64,
    /// The scene: its path (local) or its job's name (farm).
    pub scene: String,
    /// Further text attributes, e.g. `render_seconds` or `job`.
    pub extra: Vec<(String, String)>,
}

/// PNG encoder effort.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PngEffort {
    /// The encoder's default compression.
    Default,
    /// Fast deflate: the coordinator encodes while uploads wait, and the default level costs
    /// about 0.2 s per megapixel.
    Fast,
}

/// A finished render ready to be written: the averaged image and what goes beside it.
pub struct Outputs<'a> {
    film: &'a Film,
    rgb: Vec<[f32; 3]>,
    /// EMIS: the state and its per-pixel merge mask.
    emis: Option<(&'a EmisState, Vec<f32>)>,
    attributes: Vec<(String, Attribute)>,
}

impl<'a> Outputs<'a> {
    /// The outputs of `film`, made as `provenance` says, with EMIS's decisions if given.
    pub fn new(film: &'a Film, provenance: &Provenance, emis: Option<&'a EmisState>) -> Self {
        let text = |k: &str, v: String| (format!("tessera/{k}"), Attribute::Text(v));
        let mut attributes = vec![
            text("integrator", provenance.integrator.clone()),
            text("spp", provenance.spp.to_string()),
            text("seed", provenance.seed.to_string()),
            text("scene", provenance.scene.clone()),
        ];
        attributes.extend(provenance.extra.iter().map(|(k, v)| text(k, v.clone())));
        if let Some(e) = emis {
            attributes.push(("tessera/emis_nu".into(), Attribute::Float(e.strategy.nu)));
            match &e.strategy.connections {
                Connections::Fixed(c) => {
                    attributes.push(("tessera/emis_connections".into(), Attribute::Int(*c as i32)))
                }
                Connections::PerPixel(mask) => {
                    let mean = e.strategy.connections.mean(mask.len()) as f32;
                    attributes.push(("tessera/emis_mean_connections".into(), Attribute::Float(mean)));
                }
            }
            attributes.push(("tessera/emis_updates".into(), Attribute::Int(e.updates_done as i32)));
            // a path-tracing start's iterations: the counts layer holds kept_from.. only, and
            // the start enters the image by its weight (absent or 0: left out)
            attributes.push(("tessera/emis_kept_from".into(), Attribute::Int(e.kept_from as i32)));
            if let Some(k) = e.start.as_ref().and_then(|s| s.weight) {
                attributes.push(("tessera/emis_start_weight".into(), Attribute::Float(k as f32)));
            }
        }
        // no Inf or NaN reaches a file or a preview (film::exr::finite)
        let mut rgb = emis.map_or_else(|| film.average(), |e| e.image(film));
        for c in rgb.iter_mut().flatten() {
            *c = tessera_common::film::exr::finite(*c);
        }
        Outputs { film, rgb, emis: emis.map(|e| (e, e.merge_mask())), attributes }
    }

    /// The averaged linear RGB image.
    pub fn rgb(&self) -> &[[f32; 3]] {
        &self.rgb
    }

    /// Writes the EXR: beauty, sample counts, EMIS layers and every attribute.
    pub fn write_exr(&self, path: &Path) -> Result<(), OutputError> {
        let mut extras =
            ExrExtras { counts: Some(&self.film.count), layers: Vec::new(), attributes: self.attributes.clone() };
        if let Some((e, mask)) = &self.emis {
            extras.layers.push(("merge_mask", mask));
            if let Connections::PerPixel(connections) = &e.strategy.connections {
                extras.layers.push(("connections", connections));
            }
            if let Some(relative) = &e.relative_moment {
                extras.layers.push(("relative_moment", &relative.data));
            }
        }
        write_exr(path, self.film.width, self.film.height, &self.rgb, &extras).map_err(|e| write_error(path, e))
    }

    /// Writes the sRGB preview (clamped, no tone mapping).
    pub fn write_png(&self, path: &Path, effort: PngEffort) -> Result<(), OutputError> {
        write_srgb_png(path, self.film.width, self.film.height, &self.rgb, effort)
    }

    /// EMIS: writes the strategy picture (the image in grey, tinted orange by the merge
    /// probability χ); false, writing nothing, for other integrators.
    pub fn write_strategy_png(&self, path: &Path, effort: PngEffort) -> Result<bool, OutputError> {
        let Some((_, mask)) = &self.emis else { return Ok(false) };
        write_srgb_png(path, self.film.width, self.film.height, &strategy_map(&self.rgb, mask), effort)?;
        Ok(true)
    }

    /// EMIS: the JSON report of every update (`None` for other integrators).
    pub fn emis_report(&self, integrator: &str, iterations: u32) -> Option<serde_json::Value> {
        let (e, _) = self.emis.as_ref()?;
        Some(serde_json::json!({
            "integrator": integrator,
            "iterations": iterations,
            "kept_from": e.kept_from,
            "final": match &e.strategy.connections {
                Connections::Fixed(c) => serde_json::json!({ "nu": e.strategy.nu, "connections": c }),
                Connections::PerPixel(mask) => serde_json::json!({
                    "nu": e.strategy.nu,
                    "connections": 0,
                    "mean_connections": e.strategy.connections.mean(mask.len()),
                }),
            },
            "candidates": e.candidates,
            "updates": e.reports,
        }))
    }

    /// EMIS: the JSON report as `tessera render` writes it, pretty-printed (`None` for other
    /// integrators). The farm stores the same text, so the two files differ only in the
    /// updates' timings (`denoise_ms`, `optimize_ms`).
    pub fn emis_report_text(&self, integrator: &str, iterations: u32) -> Option<String> {
        let report = self.emis_report(integrator, iterations)?;
        Some(serde_json::to_string_pretty(&report).expect("invariant: a JSON value serialises"))
    }

    /// Writes everything to `paths`: the EXR, the PNG and, for EMIS, the strategy PNG and the
    /// report.
    pub fn write_all(&self, paths: &OutputPaths, integrator: &str, iterations: u32) -> Result<(), OutputError> {
        if let Some(dir) = paths.exr.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| write_error(dir, e))?;
        }
        self.write_exr(&paths.exr)?;
        self.write_png(&paths.png, PngEffort::Default)?;
        self.write_strategy_png(&paths.strategy_png, PngEffort::Default)?;
        if let Some(text) = self.emis_report_text(integrator, iterations) {
            std::fs::write(&paths.emis_json, text).map_err(|e| write_error(&paths.emis_json, e))?;
        }
        Ok(())
    }
}

/// The decisions in an EMIS report ([`Outputs::emis_report`]), read back by the coordinator
/// to show a finished job's strategy after a restart (its EMIS state is gone by then).
#[derive(Clone, Debug, serde::Deserialize)]
pub struct ReportDecisions {
    /// The strategy the last iterations rendered with.
    #[serde(rename = "final")]
    pub last: FinalStrategy,
    /// Every update.
    pub updates: Vec<UpdateReport>,
}

/// The report's `final` strategy.
#[derive(Clone, Debug, serde::Deserialize)]
pub struct FinalStrategy {
    /// Light paths per pixel per iteration (0: path tracing).
    pub nu: f32,
    /// Connections per camera vertex (0 with per-pixel connections).
    pub connections: u32,
}

/// Encodes linear RGB as an 8-bit sRGB PNG.
fn write_srgb_png(
    path: &Path,
    width: u32,
    height: u32,
    rgb: &[[f32; 3]],
    effort: PngEffort,
) -> Result<(), OutputError> {
    let bytes: Vec<u8> = rgb.iter().flat_map(|p| p.map(|c| (linear_to_srgb(c) * 255.0 + 0.5) as u8)).collect();
    let file = std::fs::File::create(path).map_err(|e| write_error(path, e))?;
    let compression = match effort {
        PngEffort::Default => CompressionType::Default,
        PngEffort::Fast => CompressionType::Fast,
    };
    PngEncoder::new_with_quality(std::io::BufWriter::new(file), compression, FilterType::Adaptive)
        .write_image(&bytes, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| write_error(path, e))
}

/// The strategy as a picture: the image's luminance in grey, tinted orange by the merge
/// probability χ (ν and c are image-wide and in the EXR attributes and the report).
fn strategy_map(rgb: &[[f32; 3]], mask: &[f32]) -> Vec<[f32; 3]> {
    const ORANGE: [f32; 3] = [1.0, 0.35, 0.0];
    rgb.iter()
        .zip(mask)
        .map(|(c, &chi)| {
            let grey = (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]).clamp(0.0, 1.0) * 0.6 + 0.05;
            let t = 0.7 * chi.clamp(0.0, 1.0);
            [0, 1, 2].map(|k| grey * (1.0 - t) + ORANGE[k] * t)
        })
        .collect()
}

#[cfg(test)]
mod path_tests {
    use super::OutputPaths;
    use std::path::{Path, PathBuf};

    /// `-o x.png` must not write the EXR under the PNG's name (it was overwritten by the PNG).
    #[test]
    fn a_png_output_keeps_the_exr_beside_it() {
        let paths = |p: &str| {
            let o = OutputPaths::new(Path::new(p));
            [o.exr, o.png, o.strategy_png, o.emis_json].map(|p: PathBuf| p.display().to_string())
        };
        assert_eq!(paths("out/a.exr"), ["out/a.exr", "out/a.png", "out/a.strategy.png", "out/a.emis.json"]);
        assert_eq!(paths("a.PNG"), ["a.exr", "a.PNG", "a.strategy.png", "a.emis.json"]);
        assert_eq!(paths("a"), ["a", "a.png", "a.strategy.png", "a.emis.json"]);
    }
}
