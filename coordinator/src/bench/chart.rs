//! The bar chart of `tessera bench equal-time --chart`: one group of bars per scene, one bar
//! per integrator, the speed-up over path tracing on a log₂ axis, as SVG (plotters; SVG needs
//! no font files).

use anyhow::Context;
use plotters::prelude::*;
use std::path::Path;

/// One scene's speed-ups, in the order of the legend.
pub struct Group {
    /// The scene's name.
    pub label: String,
    /// Speed-up of each integrator (finite and positive, or skipped).
    pub values: Vec<f64>,
}

const PALETTE: [RGBColor; 8] = [
    RGBColor(120, 120, 120),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(23, 190, 207),
];

/// Draws the chart into `path` (SVG): `names` label the bars of every group (the legend),
/// `title` the top line.
pub fn write_bar_chart(path: &Path, title: &str, names: &[String], groups: &[Group]) -> anyhow::Result<()> {
    draw(path, title, names, groups)
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("cannot write {}", path.display()))
}

fn draw(path: &Path, title: &str, names: &[String], groups: &[Group]) -> Result<(), Box<dyn std::error::Error>> {
    // the axis is log₂ of the speed-up, labelled with the powers of two
    let finite = groups.iter().flat_map(|g| g.values.iter().copied()).filter(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = finite.fold((1.0f64, 1.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let (lo, hi) = (lo.log2().floor().min(-1.0), hi.log2().ceil().max(1.0));
    let width = (120 + groups.len() * (names.len() * 16 + 40)).max(480) as u32;
    let root = SVGBackend::new(path, (width, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 16))
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..groups.len() as f64, lo..hi)?;
    let labels: Vec<String> = groups.iter().map(|g| g.label.clone()).collect();
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(groups.len() * 2 + 1)
        .x_label_formatter(&|x| {
            // group g's label sits at its centre, g + 0.5
            let g = x - 0.5;
            if g.fract().abs() < 1e-6 && g >= 0.0 {
                labels.get(g as usize).cloned().unwrap_or_default()
            } else {
                String::new()
            }
        })
        .y_desc("speed-up over pt")
        .y_labels((hi - lo) as usize + 1)
        .y_label_formatter(&|e| match e.round() as i32 {
            e if e >= 0 => format!("{}x", 1u64 << e),
            e => format!("1/{}x", 1u64 << -e),
        })
        .draw()?;
    let bar = 0.8 / names.len().max(1) as f64;
    for (i, name) in names.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let bars = groups.iter().enumerate().filter_map(|(g, group)| {
            let v = *group.values.get(i)?;
            let x0 = g as f64 + 0.1 + i as f64 * bar;
            (v.is_finite() && v > 0.0).then(|| Rectangle::new([(x0, 0.0), (x0 + bar * 0.9, v.log2())], color.filled()))
        });
        chart
            .draw_series(bars)?
            .label(name.as_str())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], color.filled()));
    }
    chart.draw_series(std::iter::once(PathElement::new(vec![(0.0, 0.0), (groups.len() as f64, 0.0)], BLACK)))?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_chart_is_an_svg_with_every_label() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("chart.svg");
        let names = vec!["pt".to_string(), "emis-vcm".to_string()];
        let groups = vec![
            Group { label: "cornell-box".into(), values: vec![1.0, 1.8] },
            Group { label: "veach-mis".into(), values: vec![1.0, f64::NAN] },
        ];
        write_bar_chart(&path, "speed-up at 20 s", &names, &groups).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..svg.len().min(80)]);
        for text in ["speed-up at 20 s", "cornell-box", "veach-mis", "emis-vcm"] {
            assert!(svg.contains(text), "{text} missing");
        }
    }
}
