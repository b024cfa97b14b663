//! A small PNG bar chart for `tessera bench --equal-time --chart`: one group of bars per
//! scene, one bar per integrator, the speed-up over the first integrator on a log₂ axis, with
//! a legend and labels in a built-in 3×5 pixel font (no font files needed).

use anyhow::Context;
use std::path::Path;

/// One scene's speed-ups, in the order of the legend.
pub struct Group {
    /// The scene's name.
    pub label: String,
    /// Speed-up of each integrator (finite and positive, or skipped).
    pub values: Vec<f64>,
}

const PALETTE: [[u8; 3]; 8] = [
    [120, 120, 120],
    [31, 119, 180],
    [44, 160, 44],
    [255, 127, 14],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [23, 190, 207],
];

/// Glyphs of the 3×5 font: five rows of three pixels each, top to bottom.
fn glyph(c: char) -> [&'static str; 5] {
    match c.to_ascii_lowercase() {
        '0' => ["###", "#.#", "#.#", "#.#", "###"],
        '1' => [".#.", "##.", ".#.", ".#.", "###"],
        '2' => ["###", "..#", "###", "#..", "###"],
        '3' => ["###", "..#", "###", "..#", "###"],
        '4' => ["#.#", "#.#", "###", "..#", "..#"],
        '5' => ["###", "#..", "###", "..#", "###"],
        '6' => ["###", "#..", "###", "#.#", "###"],
        '7' => ["###", "..#", "..#", "..#", "..#"],
        '8' => ["###", "#.#", "###", "#.#", "###"],
        '9' => ["###", "#.#", "###", "..#", "###"],
        '.' => ["...", "...", "...", "...", ".#."],
        '-' => ["...", "...", "###", "...", "..."],
        '=' => ["...", "###", "...", "###", "..."],
        ':' => ["...", ".#.", "...", ".#.", "..."],
        '/' => ["..#", "..#", ".#.", "#..", "#.."],
        'a' => ["###", "#.#", "###", "#.#", "#.#"],
        'b' => ["##.", "#.#", "##.", "#.#", "##."],
        'c' => ["###", "#..", "#..", "#..", "###"],
        'd' => ["##.", "#.#", "#.#", "#.#", "##."],
        'e' => ["###", "#..", "###", "#..", "###"],
        'f' => ["###", "#..", "###", "#..", "#.."],
        'g' => ["###", "#..", "#.#", "#.#", "###"],
        'h' => ["#.#", "#.#", "###", "#.#", "#.#"],
        'i' => ["###", ".#.", ".#.", ".#.", "###"],
        'j' => ["..#", "..#", "..#", "#.#", "###"],
        'k' => ["#.#", "#.#", "##.", "#.#", "#.#"],
        'l' => ["#..", "#..", "#..", "#..", "###"],
        'm' => ["#.#", "###", "###", "#.#", "#.#"],
        'n' => ["##.", "#.#", "#.#", "#.#", "#.#"],
        'o' => ["###", "#.#", "#.#", "#.#", "###"],
        'p' => ["###", "#.#", "###", "#..", "#.."],
        'q' => ["###", "#.#", "#.#", "###", "..#"],
        'r' => ["##.", "#.#", "##.", "#.#", "#.#"],
        's' => ["###", "#..", "###", "..#", "###"],
        't' => ["###", ".#.", ".#.", ".#.", ".#."],
        'u' => ["#.#", "#.#", "#.#", "#.#", "###"],
        'v' => ["#.#", "#.#", "#.#", "#.#", ".#."],
        'w' => ["#.#", "#.#", "###", "###", "#.#"],
        'x' => ["...", "#.#", ".#.", "#.#", "..."],
        'y' => ["#.#", "#.#", "###", ".#.", ".#."],
        'z' => ["###", "..#", ".#.", "#..", "###"],
        _ => ["...", "...", "...", "...", "..."],
    }
}

struct Canvas {
    width: usize,
    height: usize,
    pixels: Vec<[u8; 3]>,
}

impl Canvas {
    fn rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, color: [u8; 3]) {
        for y in y0.max(0)..y1.min(self.height as i64) {
            for x in x0.max(0)..x1.min(self.width as i64) {
                self.pixels[y as usize * self.width + x as usize] = color;
            }
        }
    }

    /// Text at (x, y), 2× scaled glyphs, 8 px per character.
    fn text(&mut self, x: i64, y: i64, s: &str, color: [u8; 3]) {
        for (i, c) in s.chars().enumerate() {
            for (row, bits) in glyph(c).iter().enumerate() {
                for (col, b) in bits.bytes().enumerate() {
                    if b == b'#' {
                        let (px, py) = (x + i as i64 * 8 + col as i64 * 2, y + row as i64 * 2);
                        self.rect(px, py, px + 2, py + 2, color);
                    }
                }
            }
        }
    }
}

/// Draws the chart: `names` label the bars of every group (the legend), `title` the top line.
pub fn write_bar_chart(path: &Path, title: &str, names: &[String], groups: &[Group]) -> anyhow::Result<()> {
    let bar = 14i64;
    let group_width = (names.len() as i64 * bar + 24).max(110);
    let (left, top, plot_h) = (70i64, 70i64, 300i64);
    let width = (left + groups.len() as i64 * group_width + 20) as usize;
    let height = (top + plot_h + 40) as usize;
    let mut c = Canvas { width, height, pixels: vec![[255; 3]; width * height] };
    let finite = groups.iter().flat_map(|g| g.values.iter().copied()).filter(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = finite.fold((1.0f64, 1.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let (lo, hi) = (lo.log2().floor().min(0.0), hi.log2().ceil().max(1.0));
    let y_of = |v: f64| top + plot_h - ((v.log2() - lo) / (hi - lo) * plot_h as f64).round() as i64;
    c.text(10, 8, title, [0; 3]);
    for (i, n) in names.iter().enumerate() {
        let x = 10 + (i as i64 % 4) * 150;
        let y = 30 + (i as i64 / 4) * 16;
        c.rect(x, y, x + 10, y + 10, PALETTE[i % PALETTE.len()]);
        c.text(x + 14, y, n, [0; 3]);
    }
    // grid lines at powers of two, the 1x line darker
    let mut e = lo as i64;
    while e <= hi as i64 {
        let y = y_of(2f64.powi(e as i32));
        let shade = if e == 0 { [90; 3] } else { [225; 3] };
        c.rect(left, y, width as i64 - 10, y + 1, shade);
        let label = if e >= 0 { format!("{}x", 1u64 << e) } else { format!("1/{}x", 1u64 << -e) };
        c.text(8, y - 4, &label, [60; 3]);
        e += 1;
    }
    for (gi, g) in groups.iter().enumerate() {
        let x0 = left + gi as i64 * group_width + 12;
        let base = y_of(1.0);
        for (i, &v) in g.values.iter().enumerate() {
            if !(v.is_finite() && v > 0.0) {
                continue;
            }
            let (y, x) = (y_of(v), x0 + i as i64 * bar);
            c.rect(x, y.min(base), x + bar - 2, y.max(base) + 1, PALETTE[i % PALETTE.len()]);
        }
        let label: String = g.label.chars().take(((group_width - 8) / 8) as usize).collect();
        c.text(x0, top + plot_h + 12, &label, [0; 3]);
    }
    let bytes: Vec<u8> = c.pixels.iter().flatten().copied().collect();
    image::save_buffer(path, &bytes, width as u32, height as u32, image::ColorType::Rgb8)
        .with_context(|| format!("cannot write {}", path.display()))
}
