//! Learning-curve plots (SVG, plotters): one line per curve, optional horizontal reference
//! lines (greedy lengths, optima).

use anyhow::{anyhow, Result};
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use std::path::Path;

/// A named line of the plot: (iteration, episode length) points.
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A line with one value per iteration, thinned to at most ~2000 points (the curves are
    /// smoothed already, and it keeps the SVG small).
    pub fn from_values(label: String, values: &[f64]) -> Series {
        let step = (values.len() / 2000).max(1);
        Series {
            label,
            points: values.iter().enumerate().step_by(step).map(|(x, &y)| (x as f64, y)).collect(),
        }
    }
}

/// A horizontal reference line, e.g. "optimum (11.50)", or "UAV1 greedy after training
/// (250.64; 967 of 4000 truncated)" with a detail.
pub struct Reference {
    pub label: String,
    pub value: f64,
    /// Shown after the value in the legend.
    pub detail: Option<String>,
}

impl Reference {
    fn legend(&self) -> String {
        match &self.detail {
            Some(detail) => format!("{} ({:.2}; {detail})", self.label, self.value),
            None => format!("{} ({:.2})", self.label, self.value),
        }
    }
}

const COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// Draws `series` (x = iteration, y = episode length) and `references` into an SVG file.
pub fn plot_curves(
    path: &Path,
    title: &str,
    series: &[Series],
    references: &[Reference],
) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("cannot draw {}: {e}", path.display());
    let episodes = series.iter().flat_map(|s| s.points.iter().map(|p| p.0)).fold(1.0f64, f64::max);
    let all = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .chain(references.iter().map(|r| r.value));
    let top = all.fold(1.0f64, f64::max) * 1.05;
    let root = SVGBackend::new(path, (960, 600)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d(0f64..episodes, 0f64..top)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc("iterations (episodes)")
        .y_desc("episode length (ticks)")
        // Episodes are whole numbers.
        .x_label_formatter(&|x| format!("{x:.0}"))
        .draw()
        .map_err(|e| err(&e))?;
    for (i, s) in series.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        chart
            .draw_series(LineSeries::new(s.points.iter().copied(), color.stroke_width(2)))
            .map_err(|e| err(&e))?
            .label(s.label.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    for (i, r) in references.iter().enumerate() {
        let color = COLORS[(series.len() + i) % COLORS.len()];
        let style = ShapeStyle { color: color.to_rgba(), filled: false, stroke_width: 1 };
        let (dash, gap) = (6, 4);
        chart
            .draw_series(DashedLineSeries::new(
                [(0.0, r.value), (episodes, r.value)],
                dash,
                gap,
                style,
            ))
            .map_err(|e| err(&e))?
            .label(r.legend())
            // The legend's sample is dashed like the line it names.
            .legend(move |(x, y)| {
                DashedPathElement::new(vec![(x, y), (x + 20, y)], dash, gap, style)
            });
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episode_axis_labels_are_whole_numbers() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("curve.svg");
        let values: Vec<f64> = (0..=10_000).map(|e| 100.0 - e as f64 / 200.0).collect();
        let series = [Series::from_values("UAV1".into(), &values)];
        let references = [
            Reference { label: "optimum".into(), value: 11.5, detail: None },
            Reference {
                label: "greedy".into(),
                value: 250.636,
                detail: Some("967 of 4000 truncated".into()),
            },
        ];
        plot_curves(&path, "test", &series, &references).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        // The SVG backend writes each text on a line of its own.
        let texts: Vec<&str> = svg.lines().map(str::trim).collect();
        let numbers: Vec<&&str> = texts.iter().filter(|t| t.parse::<f64>().is_ok()).collect();
        assert!(texts.contains(&"2000"), "no episode tick label 2000 among {numbers:?}");
        assert!(!texts.contains(&"2000.0"), "episode tick labels carry decimals");
        assert!(texts.contains(&"optimum (11.50)"), "the reference line's legend is missing");
        assert!(
            texts.contains(&"greedy (250.64; 967 of 4000 truncated)"),
            "the reference line's detail is missing from its legend"
        );
    }
}
