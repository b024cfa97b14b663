//! Colours of Mitsuba 3 `<spectrum>` values in Tessera's RGB rendering, as Mitsuba's `*_rgb`
//! variants compute them (`Properties::get_texture_impl` and `spectrum_list_to_srgb`).
//!
//! A spectrum is either one value for all wavelengths or a piecewise-linear list of
//! `wavelength:value` pairs (inline or from a file). Which RGB triple it becomes depends on how
//! the plugin reads it ([`ColorUsage`]): reflectances are weighted by the D65 illuminant and
//! clipped to [0, 1], other unbounded quantities (conductor IORs, roughness) are weighted and
//! clamped at 0, emitted quantities are integrated unweighted. The CIE 1931 2° observer and D65
//! tables below are Mitsuba's (`src/core/spectrum.cpp`, `include/mitsuba/core/spectrum.h`).
//!
//! ```
//! use tessera_common::spectrum::{ColorUsage, Spectrum};
//! let flat = Spectrum::parse("400:0.5, 700:0.5").unwrap();
//! let rgb = flat.to_rgb(ColorUsage::Bounded).rgb;
//! assert!((rgb.y - 0.499878).abs() < 1e-4);
//! ```

use crate::math::Rgb;
use tables::{CIE_1931, D65};

mod tables;

/// How a plugin reads a colour, which decides how a spectrum becomes RGB (Mitsuba's
/// `get_texture`, `get_unbounded_texture` and `get_emissive_texture`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorUsage {
    /// Reflectances and transmittances: D65-weighted, clipped to [0, 1]; an `<rgb>` outside
    /// [0, 1] is an error.
    Bounded,
    /// Unbounded material quantities (conductor `eta`/`k`, roughness `alpha`): D65-weighted,
    /// negative channels clamped to 0.
    Unbounded,
    /// Emitted radiance, intensity or irradiance: integrated without a white-point weight,
    /// negative channels clamped to 0.
    Emissive,
}

/// A `<spectrum>` property as written, before conversion.
#[derive(Clone, Debug, PartialEq)]
pub enum Spectrum {
    /// `value="v"`: the same value at every wavelength.
    Uniform(f64),
    /// Piecewise-linear samples, wavelengths in nm strictly increasing, at least two.
    Sampled {
        /// Wavelengths in nm.
        wavelengths: Vec<f64>,
        /// Values at those wavelengths.
        values: Vec<f64>,
    },
}

/// A malformed spectrum.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
#[non_exhaustive]
pub enum SpectrumError {
    /// A token that is neither a number nor a `wavelength:value` pair.
    #[error("\"{0}\" is not a wavelength:value pair")]
    BadPair(String),
    /// A value that does not parse as a finite number.
    #[error("\"{0}\" is not a finite number")]
    BadNumber(String),
    /// Fewer than two samples.
    #[error("a spectrum needs at least two wavelength:value pairs")]
    TooFew,
    /// Wavelengths out of order.
    #[error("wavelengths must increase strictly ({next} nm follows {previous} nm)")]
    NotIncreasing {
        /// The earlier wavelength.
        previous: f64,
        /// The wavelength that does not exceed it.
        next: f64,
    },
    /// A line of a spectrum file that is not `wavelength value`.
    #[error("line {line}: expected \"wavelength value\", found \"{text}\"")]
    BadLine {
        /// 1-based line number.
        line: usize,
        /// The line.
        text: String,
    },
}

/// The RGB value of a spectrum for one usage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Converted {
    /// Linear sRGB.
    pub rgb: Rgb,
    /// Whether channels were clipped into range (Mitsuba warns then).
    pub clipped: bool,
}

const CIE_MIN: f64 = 360.0;
const CIE_MAX: f64 = 830.0;
const CIE_SAMPLES: usize = 95;
/// Makes a unit spectrum integrate to luminance 1 (`MI_CIE_Y_NORMALIZATION`).
#[allow(clippy::excessive_precision)]
const CIE_Y_NORMALIZATION: f64 = 1.0 / 106.7502593994140625;
/// Makes the D65 table integrate to luminance 1 (`MI_CIE_D65_NORMALIZATION`).
const CIE_D65_NORMALIZATION: f64 = 1.0 / 98.99741751876255;
/// Wavelengths of the Riemann sum in `spectrum_list_to_srgb`.
const INTEGRATION_STEPS: usize = 1000;

/// XYZ → linear sRGB (Rec. 709 primaries, D65 white), single precision as in Mitsuba.
#[allow(clippy::excessive_precision)]
const XYZ_TO_SRGB: [[f32; 3]; 3] =
    [[3.240479, -1.537150, -0.498535], [-0.969256, 1.875991, 0.041556], [0.055648, -0.204043, 1.057311]];

impl Spectrum {
    /// Parses a `value` attribute: one number (no colon), or `wavelength:value` pairs
    /// separated by commas or spaces.
    pub fn parse(text: &str) -> Result<Spectrum, SpectrumError> {
        let tokens: Vec<&str> = text.split(|c: char| c == ',' || c.is_whitespace()).filter(|t| !t.is_empty()).collect();
        if let [single] = tokens.as_slice()
            && !single.contains(':')
        {
            return Ok(Spectrum::Uniform(number(single)?));
        }
        let mut wavelengths = Vec::with_capacity(tokens.len());
        let mut values = Vec::with_capacity(tokens.len());
        for token in tokens {
            let (w, v) = token
                .split_once(':')
                .filter(|(w, v)| !w.is_empty() && !v.is_empty() && !v.contains(':'))
                .ok_or_else(|| SpectrumError::BadPair(token.to_string()))?;
            wavelengths.push(number(w)?);
            values.push(number(v)?);
        }
        Spectrum::sampled(wavelengths, values)
    }

    /// Parses a spectrum file: one `wavelength value` pair per line; blank lines and lines
    /// starting with `#` are skipped, text after the two numbers is ignored (as Mitsuba does).
    pub fn parse_file(text: &str) -> Result<Spectrum, SpectrumError> {
        let mut wavelengths = Vec::new();
        let mut values = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let trimmed = line.trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let bad = || SpectrumError::BadLine { line: i + 1, text: trimmed.to_string() };
            let mut fields = trimmed.split_whitespace();
            let (Some(w), Some(v)) = (fields.next(), fields.next()) else { return Err(bad()) };
            wavelengths.push(number(w).map_err(|_| bad())?);
            values.push(number(v).map_err(|_| bad())?);
        }
        Spectrum::sampled(wavelengths, values)
    }

    fn sampled(wavelengths: Vec<f64>, values: Vec<f64>) -> Result<Spectrum, SpectrumError> {
        if wavelengths.len() < 2 {
            return Err(SpectrumError::TooFew);
        }
        if let Some(w) = wavelengths.windows(2).find(|w| w[1] <= w[0]) {
            return Err(SpectrumError::NotIncreasing { previous: w[0], next: w[1] });
        }
        Ok(Spectrum::Sampled { wavelengths, values })
    }

    /// The RGB value Mitsuba's RGB variants use for this spectrum when a plugin reads it as
    /// `usage`.
    pub fn to_rgb(&self, usage: ColorUsage) -> Converted {
        match self {
            // A flat spectrum is not white under a D65 white point; emitters get that tint so
            // that RGB renders match spectral ones.
            Spectrum::Uniform(v) if usage == ColorUsage::Emissive => {
                Converted { rgb: *v as f32 * emissive_white(), clipped: false }
            }
            Spectrum::Uniform(v) => Converted { rgb: Rgb::splat(*v as f32), clipped: false },
            Spectrum::Sampled { wavelengths, values } => {
                spectrum_list_to_srgb(wavelengths, values, usage == ColorUsage::Bounded, usage != ColorUsage::Emissive)
            }
        }
    }
}

fn number(token: &str) -> Result<f64, SpectrumError> {
    token
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| SpectrumError::BadNumber(token.to_string()))
}

/// The RGB colour of an equal-energy spectrum of value 1 seen as emission: XYZ (1, 1, 1) in
/// linear sRGB, about (1.204794, 0.948291, 0.908916).
pub fn emissive_white() -> Rgb {
    let row = |r: [f32; 3]| r[0] + r[1] + r[2];
    Rgb::new(row(XYZ_TO_SRGB[0]), row(XYZ_TO_SRGB[1]), row(XYZ_TO_SRGB[2]))
}

/// Mitsuba's `spectrum_list_to_srgb`: integrates the piecewise-linear spectrum against the CIE
/// 1931 curves (optionally weighted by D65) over 1000 wavelengths spread across 360-830 nm,
/// skipping those outside the spectrum's own range, then converts XYZ to linear sRGB and clips
/// (to [0, 1] when `bounded`, else at 0).
pub fn spectrum_list_to_srgb(wavelengths: &[f64], values: &[f64], bounded: bool, d65: bool) -> Converted {
    let n = wavelengths.len().min(values.len());
    if n < 2 {
        return Converted { rgb: Rgb::ZERO, clipped: false };
    }
    let (first, last) = (wavelengths[0], wavelengths[n - 1]);
    let mut xyz = [0.0f64; 3];
    for i in 0..INTEGRATION_STEPS {
        let w = CIE_MIN + (i as f64 / (INTEGRATION_STEPS - 1) as f64) * (CIE_MAX - CIE_MIN);
        if w < first || w > last {
            continue;
        }
        let index = wavelengths[..n].partition_point(|&x| x <= w).saturating_sub(1).min(n - 2);
        let (w0, w1) = (wavelengths[index], wavelengths[index + 1]);
        let (v0, v1) = (values[index], values[index + 1]);
        let v = ((w - w1) * v0 + (w0 - w) * v1) / (w0 - w1);
        let weight = if d65 { cie_d65(w) } else { 1.0 };
        let cmf = cie1931_xyz(w);
        for k in 0..3 {
            xyz[k] += cmf[k] * v * weight;
        }
    }
    let scale = (CIE_MAX - CIE_MIN) * CIE_Y_NORMALIZATION / INTEGRATION_STEPS as f64;
    let xyz = xyz.map(|c| c * scale);
    let mut rgb = XYZ_TO_SRGB.map(|row| row.iter().zip(&xyz).map(|(m, c)| *m as f64 * c).sum::<f64>());
    let clipped = if bounded { rgb.iter().any(|c| !(0.0..=1.0).contains(c)) } else { rgb.iter().any(|c| *c < 0.0) };
    if clipped {
        rgb = rgb.map(|c| if bounded { c.clamp(0.0, 1.0) } else { c.max(0.0) });
    }
    Converted { rgb: Rgb::new(rgb[0] as f32, rgb[1] as f32, rgb[2] as f32), clipped }
}

/// Linear interpolation in a 95-entry table over 360-830 nm; `w` must lie in that range.
fn lookup(table: &[f32; CIE_SAMPLES], w: f64) -> f64 {
    let t = (w - CIE_MIN) * ((CIE_SAMPLES - 1) as f64 / (CIE_MAX - CIE_MIN));
    let i0 = (t as usize).min(CIE_SAMPLES - 2);
    let w1 = t - i0 as f64;
    (1.0 - w1).mul_add(table[i0] as f64, w1 * table[i0 + 1] as f64)
}

/// The CIE 1931 2° colour matching functions x̄, ȳ, z̄ at `w` nm (0 outside 360-830 nm).
pub fn cie1931_xyz(w: f64) -> [f64; 3] {
    if !(CIE_MIN..=CIE_MAX).contains(&w) {
        return [0.0; 3];
    }
    [lookup(&CIE_1931[0], w), lookup(&CIE_1931[1], w), lookup(&CIE_1931[2], w)]
}

/// The D65 illuminant at `w` nm, normalised to luminance 1 (0 outside 360-830 nm).
pub fn cie_d65(w: f64) -> f64 {
    if !(CIE_MIN..=CIE_MAX).contains(&w) {
        return 0.0;
    }
    lookup(&D65, w) * CIE_D65_NORMALIZATION
}

#[cfg(test)]
mod tests {
    use super::*;

    const CORNELL_WHITE: &str = "400:0.343, 404:0.445, 408:0.551, 412:0.624, 416:0.665, 420:0.687, 424:0.708, \
        428:0.723, 432:0.715, 436:0.71, 440:0.745, 444:0.758, 448:0.739, 452:0.767, 456:0.777, 460:0.765, \
        464:0.751, 468:0.745, 472:0.748, 476:0.729, 480:0.745, 484:0.757, 488:0.753, 492:0.75, 496:0.746, \
        500:0.747, 504:0.735, 508:0.732, 512:0.739, 516:0.734, 520:0.725, 524:0.721, 528:0.733, 532:0.725, \
        536:0.732, 540:0.743, 544:0.744, 548:0.748, 552:0.728, 556:0.716, 560:0.733, 564:0.726, 568:0.713, \
        572:0.74, 576:0.754, 580:0.764, 584:0.752, 588:0.736, 592:0.734, 596:0.741, 600:0.74, 604:0.732, \
        608:0.745, 612:0.755, 616:0.751, 620:0.744, 624:0.731, 628:0.733, 632:0.744, 636:0.731, 640:0.712, \
        644:0.708, 648:0.729, 652:0.73, 656:0.727, 660:0.707, 664:0.703, 668:0.729, 672:0.75, 676:0.76, \
        680:0.751, 684:0.739, 688:0.724, 692:0.73, 696:0.74, 700:0.737";

    fn assert_rgb(text: &str, usage: ColorUsage, expected: [f32; 3]) -> Converted {
        let c = Spectrum::parse(text).unwrap().to_rgb(usage);
        for k in 0..3 {
            let rel = (c.rgb[k] - expected[k]).abs() / expected[k].abs().max(1e-6);
            assert!(rel < 1e-4, "{text:.40} as {usage:?}: {} vs {expected:?}", c.rgb);
        }
        c
    }

    #[test]
    fn spectrum_cornell_white_matches_mitsuba() {
        let Spectrum::Sampled { wavelengths, .. } = Spectrum::parse(CORNELL_WHITE).unwrap() else { panic!("sampled") };
        assert_eq!(wavelengths.len(), 76);
        assert_rgb(CORNELL_WHITE, ColorUsage::Bounded, [0.735013, 0.735625, 0.736264]);
        assert_rgb(CORNELL_WHITE, ColorUsage::Emissive, [0.88531, 0.69901, 0.66603]);
    }

    #[test]
    fn spectrum_cornell_light_matches_mitsuba() {
        assert_rgb("400:0, 500:8, 600:15.6, 700:18.4", ColorUsage::Emissive, [20.7108, 10.8546, 2.77115]);
    }

    #[test]
    fn spectrum_uniform_value_is_tinted_only_for_emitters() {
        assert_rgb("0.5", ColorUsage::Bounded, [0.5, 0.5, 0.5]);
        assert_rgb("0.5", ColorUsage::Unbounded, [0.5, 0.5, 0.5]);
        assert_rgb("0.5", ColorUsage::Emissive, [0.602397, 0.474146, 0.454458]);
        // a single value is never range-checked
        assert_eq!(Spectrum::parse("2").unwrap().to_rgb(ColorUsage::Bounded).rgb, Rgb::splat(2.0));
    }

    #[test]
    fn spectrum_flat_lists_match_mitsuba() {
        assert_rgb("400:0.5, 700:0.5", ColorUsage::Bounded, [0.497671, 0.499878, 0.497455]);
        assert_rgb("400:0.5, 700:0.5", ColorUsage::Emissive, [0.59985, 0.47476, 0.45172]);
        assert_rgb("360:1, 830:1", ColorUsage::Emissive, [1.20488, 0.948228, 0.909267]);
    }

    #[test]
    fn spectrum_bounded_list_is_clipped() {
        let c = assert_rgb("400:2, 700:2", ColorUsage::Bounded, [1.0, 1.0, 1.0]);
        assert!(c.clipped);
        let c = Spectrum::parse("400:2, 700:2").unwrap().to_rgb(ColorUsage::Unbounded);
        assert!(c.rgb.min_element() > 1.9, "unbounded keeps the value: {}", c.rgb);
        // a narrow spike outside the sRGB gamut has a negative channel, clamped at zero
        let c = Spectrum::parse("500:0, 520:10, 540:0").unwrap().to_rgb(ColorUsage::Emissive);
        assert!(c.clipped && c.rgb.min_element() == 0.0, "{}", c.rgb);
    }

    #[test]
    fn spectrum_parse_rejects_malformed_lists() {
        assert_eq!(Spectrum::parse("400:0.5"), Err(SpectrumError::TooFew));
        assert_eq!(Spectrum::parse("500:1, 400:1"), Err(SpectrumError::NotIncreasing { previous: 500.0, next: 400.0 }));
        assert_eq!(Spectrum::parse("400:0.5, 700"), Err(SpectrumError::BadPair("700".into())));
        assert_eq!(Spectrum::parse("400:x, 700:1"), Err(SpectrumError::BadNumber("x".into())));
        assert_eq!(Spectrum::parse("400:1:2, 700:1"), Err(SpectrumError::BadPair("400:1:2".into())));
    }

    #[test]
    fn spectrum_file_skips_comments_and_names_bad_lines() {
        let s = Spectrum::parse_file("# measured\n400 0.5\n\n700 0.5 extra\n").unwrap();
        assert_eq!(s, Spectrum::Sampled { wavelengths: vec![400.0, 700.0], values: vec![0.5, 0.5] });
        let e = Spectrum::parse_file("400 0.5\n500\n").unwrap_err();
        assert_eq!(e, SpectrumError::BadLine { line: 2, text: "500".into() });
    }

    #[test]
    fn spectrum_tables_are_normalised() {
        // D65 is 100 at 560 nm and ȳ peaks at 1 at 555 nm
        assert!((cie_d65(560.0) / CIE_D65_NORMALIZATION - 100.0).abs() < 1e-9);
        assert!((cie1931_xyz(555.0)[1] - 1.0).abs() < 1e-9);
        assert_eq!(cie1931_xyz(359.9), [0.0; 3]);
        assert_eq!(cie_d65(830.1), 0.0);
    }
}
