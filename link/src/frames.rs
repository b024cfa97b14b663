//! Frame numbers and frame-numbered names, as `tessera submit --frames` and the coordinator read
//! them: ranges such as `1-240`, `1-240:2` or `1,5,10-20`, and names in which each run of `#` is
//! the zero-padded frame number (the Blender and Flamenco convention: `shot.####.exr` is
//! `shot.0007.exr` for frame 7).

use tessera_common::settings::RenderSettings;

/// The most frames one job may have.
pub const MAX_FRAMES: usize = 100_000;

/// The frames `spec` names, in the order given, each once: comma-separated items, each a
/// number `N`, a range `A-B` or a stepped range `A-B:S` (B ≥ A, S ≥ 1). At most
/// [`MAX_FRAMES`] may be named in all, repeats counted.
pub fn parse(spec: &str) -> Result<Vec<u32>, String> {
    let bad = |item: &str, why: &str| format!("frames \"{spec}\": \"{item}\" {why}");
    let mut frames = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut named = 0usize;
    for item in spec.split(',').map(str::trim) {
        let (range, step) = match item.split_once(':') {
            Some((r, s)) => (r, s.parse::<u32>().ok().filter(|&s| s > 0).ok_or_else(|| bad(item, "has a bad step"))?),
            None => (item, 1),
        };
        let (a, b) = match range.split_once('-') {
            Some((a, b)) => (a, b),
            None => (range, range),
        };
        let number = |s: &str| s.trim().parse::<u32>().map_err(|_| bad(item, "is not a frame number or range"));
        let (a, b) = (number(a)?, number(b)?);
        if b < a {
            return Err(bad(item, "ends before it starts"));
        }
        // counted with repeats, so that a hostile list of one long range over and over costs no
        // more than MAX_FRAMES steps
        named += ((b - a) / step) as usize + 1;
        if named > MAX_FRAMES {
            return Err(format!("frames \"{spec}\": more than {MAX_FRAMES} frames"));
        }
        for n in (a..=b).step_by(step as usize) {
            if seen.insert(n) {
                frames.push(n);
            }
        }
    }
    Ok(frames)
}

/// Whether `name` holds a run of `#` (a frame-numbered name).
pub fn is_pattern(name: &str) -> bool {
    name.contains('#')
}

/// `pattern` with each run of `#` replaced by `frame`, zero-padded to the run's length (never
/// cut: frame 12345 in `####` is `12345`).
pub fn expand(pattern: &str, frame: u32) -> String {
    let mut out = String::with_capacity(pattern.len() + 4);
    let mut chars = pattern.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '#' {
            out.push(c);
            continue;
        }
        let mut width = 1;
        while chars.next_if_eq(&'#').is_some() {
            width += 1;
        }
        out.push_str(&format!("{frame:0width$}"));
    }
    out
}

/// How a job of frames makes frame N from its scene and settings.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameRule<'a> {
    /// The scene's path; runs of `#` are the frame number (one file per frame).
    pub scene: &'a str,
    /// The scene parameter that carries the frame number (a scene of one file).
    pub param: &'a str,
    /// Frame N renders with the seed plus N.
    pub seed_per_frame: bool,
}

impl FrameRule<'_> {
    /// Frame `number`'s scene path and settings: its own file where the path has runs of `#`,
    /// else the frame parameter set (a scene must use a parameter it is given); the seed moved
    /// on by the frame number if asked. `tessera render --frames` and the farm both make their
    /// frames so, which is why they render the same bits.
    pub fn frame(&self, settings: &RenderSettings, number: u32) -> (String, RenderSettings) {
        let mut settings = settings.clone();
        if !is_pattern(self.scene) {
            settings.defines.insert(self.param.to_string(), number.to_string());
        }
        if self.seed_per_frame {
            settings.seed = Some(settings.seed.unwrap_or(0).wrapping_add(u64::from(number)));
        }
        (expand(self.scene, number), settings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_steps_and_lists_expand_in_order_once() {
        assert_eq!(parse("1-5").unwrap(), [1, 2, 3, 4, 5]);
        assert_eq!(parse("1-9:4").unwrap(), [1, 5, 9]);
        assert_eq!(parse("1,5,10-12, 5").unwrap(), [1, 5, 10, 11, 12]);
        for bad in ["", "a", "5-1", "1-3:0", "1-", "-2", "0-4294967295"] {
            assert!(parse(bad).is_err(), "{bad}");
        }
        // one long range named over and over is refused, not expanded again each time
        let repeated = ["1-60000"; 2].join(",");
        assert!(parse(&repeated).unwrap_err().contains("more than"));
    }

    #[test]
    fn runs_of_hashes_are_the_padded_frame_number() {
        assert_eq!(expand("shot.####.exr", 7), "shot.0007.exr");
        assert_eq!(expand("a#b##", 3), "a3b03");
        assert_eq!(expand("f.##.png", 12345), "f.12345.png");
        assert_eq!(expand("plain.exr", 3), "plain.exr");
        assert!(is_pattern("x.#.exr") && !is_pattern("x.exr"));
    }
}
