//! Learning-curve plots (SVG, plotters): one line per curve, optional horizontal reference
//! lines (greedy lengths, optima).
//!
//! A plot has two panels. The first shows the whole run; its scale is set by the first
//! episodes (often ten times the final length), so the differences a researcher compares
//! late in training (a tick or two between communication modes) are flat lines there. The
//! second shows the rest of the run after its first tenth, with the episode-length axis
//! fitted to the curves there and to the reference lines up to twice their height.

use anyhow::{anyhow, Context, Result};
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use std::ops::Range;
use std::path::Path;

/// A named line of the plot: (iteration, episode length) points.
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    /// The series whose colour the line takes (an agent's periodic greedy lengths beside its
    /// learning curve); such a line does not shape the fitted panel either, which is drawn
    /// for the curves (a looping greedy policy sits near the tick cap). None: a curve of its
    /// own colour.
    pub of_curve: Option<usize>,
}

impl Series {
    /// A line through `points` (iteration, episode length), thinned to at most 2001 of them
    /// (the curves are smoothed already, and it keeps the SVG small); the last point is
    /// always kept, so the line reaches the end of the run.
    pub fn from_points(label: String, points: &[(f64, f64)]) -> Series {
        let step = points.len().div_ceil(2000).max(1);
        let mut kept: Vec<(f64, f64)> = points.iter().copied().step_by(step).collect();
        let last = points.len().saturating_sub(1);
        if !last.is_multiple_of(step) {
            kept.push(points[last]);
        }
        Series { label, points: kept, of_curve: None }
    }

    /// [`Series::from_points`] of a learning curve's (episode, episode length) points.
    pub fn from_episodes(label: String, points: &[(u64, f64)]) -> Series {
        let points: Vec<(f64, f64)> =
            points.iter().map(|&(e, length)| (e as f64, length)).collect();
        Series::from_points(label, &points)
    }
}

/// A horizontal reference line, e.g. "optimum (11.50)", or "UAV1 greedy after training
/// (250.64; 967 of 4000 truncated)" with a detail.
pub struct Reference {
    pub label: String,
    pub value: f64,
    /// Shown after the value in the legend.
    pub detail: Option<String>,
    /// The series whose colour the line takes: the curve it belongs to (an agent's greedy
    /// length after training beside its learning curve). None: a colour of its own.
    pub curve: Option<usize>,
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

/// The share of the run the second panel leaves out.
const ZOOM_SKIPS: f64 = 0.1;

/// Image size, and the height of the first panel (of the area below the title).
const SIZE: (u32, u32) = (960, 960);
const FIRST_PANEL_HEIGHT: u32 = 530;

/// Draws `series` (x = iteration, y = episode length) and `references` into an SVG file:
/// the whole run, then, if at least two points are that late, the run after its first tenth
/// with a fitted episode-length axis; one panel takes the whole image otherwise. A series
/// without points (an evaluation has no learning curve) is left out, legend and all; without
/// any, the plot shows the references alone, with no iterations axis.
pub fn plot_curves(
    path: &Path,
    title: &str,
    series: &[Series],
    references: &[Reference],
) -> Result<()> {
    let err = |e: &dyn std::fmt::Display| anyhow!("cannot draw {}: {e}", path.display());
    // plotters never finishes laying out an axis over a range that is not finite, so every
    // point must be finite, every length >= 0 too (which keeps the second panel's range
    // finite), and the axis top, 5% above the largest length, finite.
    let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
    if let Some(bad) = xs.clone().find(|x| !x.is_finite()) {
        return Err(err(&format!("iteration {bad} is not finite")));
    }
    let episodes = xs.fold(1.0f64, f64::max);
    let all = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .chain(references.iter().map(|r| r.value));
    if let Some(bad) = all.clone().find(|y| !(y.is_finite() && *y >= 0.0)) {
        return Err(err(&format!("episode length {bad} is not a finite number >= 0")));
    }
    let highest = all.fold(1.0f64, f64::max);
    let top = highest * 1.05;
    if !top.is_finite() {
        return Err(err(&format!("episode length {highest:e} is too large to plot")));
    }
    let iterations = series.iter().any(|s| !s.points.is_empty());
    // Drawn into memory, then written: a file that cannot be written is named with the
    // reason alone, not inside plotters' "backend error: Drawing backend error: ...".
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let root = root.titled(title, ("sans-serif", 22)).map_err(|e| err(&e))?;
        let whole =
            Panel { caption: None, x: 0.0..episodes, y: 0.0..top, legend: true, iterations };
        let from = (episodes * ZOOM_SKIPS).round();
        match zoom(series, references, from) {
            Some(y) => {
                let (full, zoomed) = root.split_vertically(FIRST_PANEL_HEIGHT);
                whole.draw(&full, series, references).map_err(|e| err(&e))?;
                let caption = format!("after episode {from:.0}, episode length axis fitted");
                let x = from..episodes;
                let tail = Panel { caption: Some(caption), x, y, legend: false, iterations };
                tail.draw(&zoomed, series, references).map_err(|e| err(&e))?;
            }
            None => whole.draw(&root, series, references).map_err(|e| err(&e))?,
        }
        root.present().map_err(|e| err(&e))?;
    }
    std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))
}

/// Labels of an axis of whole numbers (episodes) over `range`: at most one per whole number
/// in it, so that plotters steps by at least 1 (it steps by 1, 2 or 5 times a power of ten,
/// as few as fit the count) and no two labels round to the same number; 10 at most.
fn whole_labels(range: &Range<f64>) -> usize {
    ((range.end - range.start).floor() as usize + 1).min(10)
}

/// The episode-length range of the second panel: the curves (not the lines drawn in a
/// curve's colour, [`Series::of_curve`]) from episode `from` on, and the references up to
/// twice their highest point (an optimum below the curves is what they are
/// read against; the greedy mean of a policy that loops, often near the tick cap, would
/// squash them). None when fewer than two points are that late.
fn zoom(series: &[Series], references: &[Reference], from: f64) -> Option<Range<f64>> {
    let curves = series.iter().filter(|s| s.of_curve.is_none());
    let late = curves.flat_map(|s| s.points.iter().filter(|p| p.0 >= from).map(|p| p.1));
    let (count, lo, hi) = late
        .fold((0usize, f64::INFINITY, f64::NEG_INFINITY), |(n, lo, hi), y| {
            (n + 1, lo.min(y), hi.max(y))
        });
    if count < 2 {
        return None;
    }
    let (lo, hi) = references
        .iter()
        .map(|r| r.value)
        .filter(|&v| v <= 2.0 * hi)
        .fold((lo, hi), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = (hi - lo).max(1.0) * 0.05;
    Some((lo - pad).max(0.0)..hi + pad)
}

/// One chart of a plot: its ranges, whether it carries the legend, and whether it has an
/// iterations axis (some series has points).
struct Panel {
    caption: Option<String>,
    x: Range<f64>,
    y: Range<f64>,
    legend: bool,
    iterations: bool,
}

type DrawResult = Result<(), DrawingAreaErrorKind<std::io::Error>>;

impl Panel {
    /// Draws the series that have points (one of a single point as a dot), then as dashed
    /// lines the references within the panel's range, each in its curve's color or else the
    /// color its place in `references` gives it, the same in every panel.
    fn draw(
        &self,
        area: &DrawingArea<SVGBackend, Shift>,
        series: &[Series],
        references: &[Reference],
    ) -> DrawResult {
        let mut builder = ChartBuilder::on(area);
        if let Some(caption) = &self.caption {
            builder.caption(caption, ("sans-serif", 16));
        }
        let mut chart = builder
            .margin(16)
            .x_label_area_size(44)
            .y_label_area_size(56)
            .build_cartesian_2d(self.x.clone(), self.y.clone())?;
        let mut mesh = chart.configure_mesh();
        mesh.y_desc("episode length (ticks)");
        if self.iterations {
            // Episodes are whole numbers.
            mesh.x_desc("iterations (episodes)")
                .x_labels(whole_labels(&self.x))
                .x_label_formatter(&|x| format!("{x:.0}"));
        } else {
            mesh.x_labels(0);
        }
        mesh.draw()?;
        let x = self.x.clone();
        for (i, s) in series.iter().enumerate().filter(|(_, s)| !s.points.is_empty()) {
            let color = COLORS[s.of_curve.unwrap_or(i) % COLORS.len()];
            let points: Vec<(f64, f64)> =
                s.points.iter().copied().filter(|p| p.0 >= x.start).collect();
            // A line through one point draws nothing.
            if let [point] = points[..] {
                chart.draw_series([Circle::new(point, 4, color.filled())])?;
            }
            chart
                .draw_series(LineSeries::new(points, color.stroke_width(2)))?
                .label(s.label.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
        }
        let shown = references.iter().enumerate().filter(|(_, r)| self.y.contains(&r.value));
        for (i, r) in shown {
            let color = COLORS[r.curve.unwrap_or(series.len() + i) % COLORS.len()];
            let style = ShapeStyle { color: color.to_rgba(), filled: false, stroke_width: 1 };
            let (dash, gap) = (6, 4);
            chart
                .draw_series(DashedLineSeries::new(
                    [(x.start, r.value), (x.end, r.value)],
                    dash,
                    gap,
                    style,
                ))?
                .label(r.legend())
                // The legend's sample is dashed like the line it names.
                .legend(move |(x, y)| {
                    DashedPathElement::new(vec![(x, y), (x + 20, y)], dash, gap, style)
                });
        }
        if self.legend {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::UpperRight)
                .draw()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn episode_axis_labels_are_whole_numbers() {
        let points: Vec<(f64, f64)> =
            (0..=10_000).map(|e| (e as f64, 100.0 - e as f64 / 200.0)).collect();
        let series = [Series::from_points("UAV1".into(), &points)];
        let references = [
            Reference { label: "optimum".into(), value: 11.5, detail: None, curve: None },
            Reference {
                label: "greedy".into(),
                value: 250.636,
                detail: Some("967 of 4000 truncated".into()),
                curve: None,
            },
        ];
        let texts = drawn_texts(&series, &references);
        let numbers: Vec<&String> = texts.iter().filter(|t| t.parse::<f64>().is_ok()).collect();
        let has = |text: &str| texts.iter().any(|t| t == text);
        assert!(has("2000"), "no episode tick label 2000 among {numbers:?}");
        assert!(!has("2000.0"), "episode tick labels carry decimals");
        assert!(has("optimum (11.50)"), "the reference line's legend is missing");
        assert!(
            has("greedy (250.64; 967 of 4000 truncated)"),
            "the reference line's detail is missing from its legend"
        );
    }

    #[test]
    fn thinned_lines_reach_the_last_episode() {
        for len in [1usize, 1999, 4000, 5001, 10_000] {
            let points: Vec<(f64, f64)> = (0..len).map(|e| (e as f64, e as f64)).collect();
            let series = Series::from_points("UAV1".into(), &points);
            assert!(series.points.len() <= 2001, "{len} values kept {}", series.points.len());
            assert_eq!(series.points.last(), Some(&((len - 1) as f64, (len - 1) as f64)));
        }
        assert!(Series::from_points("none".into(), &[]).points.is_empty());
    }

    /// 100 ticks for the first 1000 episodes, then between 12 and 13.
    fn learned_by_episode_1000() -> Series {
        let points: Vec<(f64, f64)> = (0..10_000)
            .map(|e| (e as f64, if e < 1000 { 100.0 } else { 12.0 + (e % 2) as f64 }))
            .collect();
        Series::from_points("UAV1".into(), &points)
    }

    #[test]
    fn the_second_panel_fits_the_late_curves_and_the_references_below_twice_their_top() {
        let curves = [learned_by_episode_1000()];
        let range = zoom(&curves, &[], 1000.0).unwrap();
        assert!(range.start > 11.5 && range.start < 12.0, "{range:?} is not fitted to 12..13");
        assert!(range.end > 13.0 && range.end < 13.5, "{range:?} is not fitted to 12..13");
        let optimum = Reference { label: "optimum".into(), value: 8.0, detail: None, curve: None };
        let looping = Reference { label: "greedy".into(), value: 250.0, detail: None, curve: None };
        let range = zoom(&curves, &[optimum, looping], 1000.0).unwrap();
        assert!(range.start < 8.0 && range.start > 7.0, "{range:?} leaves out the optimum");
        assert!(range.end > 13.0 && range.end < 13.5, "{range:?} makes room for the loop");
    }

    /// The texts of the SVG `plot_curves` draws (the backend writes each on a line of its own).
    fn drawn_texts(series: &[Series], references: &[Reference]) -> Vec<String> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("curve.svg");
        plot_curves(&path, "test", series, references).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        svg.lines().map(|l| l.trim().to_string()).collect()
    }

    /// A reference tied to a curve is drawn in the curve's colour, one of its own otherwise.
    #[test]
    fn a_greedy_line_takes_its_curves_colour() {
        let curve = [learned_by_episode_1000()];
        let stroke = |c: RGBColor| format!("stroke=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        let (own, next) = (stroke(COLORS[0]), stroke(COLORS[1]));
        for (tied, expected) in [(Some(0), false), (None, true)] {
            let greedy =
                Reference { label: "greedy".into(), value: 12.0, detail: None, curve: tied };
            let svg = drawn_texts(&curve, &[greedy]).join("\n");
            assert!(svg.contains(&own), "the curve's colour {own} is missing");
            assert_eq!(svg.contains(&next), expected, "curve {tied:?}: {next} drawn?");
        }
    }

    /// An agent's periodic greedy lengths are drawn in its curve's colour, and a greedy
    /// policy that loops (lengths at the tick cap) does not stretch the fitted panel.
    #[test]
    fn a_greedy_series_takes_its_curves_colour_and_leaves_the_fitted_panel_to_the_curves() {
        let looping = Series {
            label: "UAV1 greedy".into(),
            points: vec![(2000.0, 1000.0), (6000.0, 1000.0)],
            of_curve: Some(0),
        };
        let range = zoom(&[learned_by_episode_1000(), looping], &[], 1000.0).unwrap();
        assert!(range.end < 13.5, "{range:?} is stretched by the greedy lengths");
        let stroke = |c: RGBColor| format!("stroke=\"#{:02X}{:02X}{:02X}\"", c.0, c.1, c.2);
        for (tied, next_drawn) in [(Some(0), false), (None, true)] {
            let greedy = Series {
                label: "UAV1 greedy".into(),
                points: vec![(2000.0, 14.0), (6000.0, 13.0)],
                of_curve: tied,
            };
            let svg = drawn_texts(&[learned_by_episode_1000(), greedy], &[]).join("\n");
            assert_eq!(svg.contains(&stroke(COLORS[1])), next_drawn, "of curve {tied:?}");
        }
    }

    #[test]
    fn the_second_panel_starts_after_the_first_tenth_of_the_run() {
        let texts = drawn_texts(&[learned_by_episode_1000()], &[]);
        let caption = "after episode 1000, episode length axis fitted";
        assert!(texts.iter().any(|t| t == caption), "no panel captioned `{caption}`");
        // Only the fitted axis of the second panel has a tick between 12 and 13.
        assert!(texts.iter().any(|t| t == "12.5"), "no tick label 12.5 in {texts:?}");
    }

    /// plotters never returns from an axis over a range that is not finite (tried: 0..inf).
    #[test]
    fn lengths_that_are_not_finite_or_too_large_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("curve.svg");
        for (value, expected) in [
            (f64::INFINITY, "episode length inf is not a finite number >= 0"),
            (f64::NAN, "episode length NaN is not a finite number >= 0"),
            (-1.0, "episode length -1 is not a finite number >= 0"),
            // 5% above it is past f64::MAX.
            (1.75e308, "episode length 1.75e308 is too large to plot"),
        ] {
            let series = [Series::from_points("UAV1".into(), &[(0.0, 40.0), (1.0, value)])];
            let e = plot_curves(&path, "test", &series, &[]).unwrap_err().to_string();
            assert!(e.ends_with(expected), "{value}: {e}");
            let reference =
                [Reference { label: "optimum".into(), value, detail: None, curve: None }];
            let ok = [Series::from_points("UAV1".into(), &[(0.0, 40.0), (1.0, 30.0)])];
            let e = plot_curves(&path, "test", &ok, &reference).unwrap_err().to_string();
            assert!(e.ends_with(expected), "reference {value}: {e}");
        }
    }

    #[test]
    fn a_run_of_one_episode_gets_one_panel() {
        let one = Series { label: "UAV1".into(), points: vec![(0.0, 40.0)], of_curve: None };
        assert!(zoom(std::slice::from_ref(&one), &[], 0.0).is_none());
        let texts = drawn_texts(&[one], &[]);
        assert!(!texts.iter().any(|t| t.starts_with("after episode")), "a second panel: {texts:?}");
        assert!(texts.iter().any(|t| t == "UAV1"), "the legend is missing");
    }

    /// A run of 7 episodes (0 to 6): plotters' default of 10 labels would step by 0.5, and
    /// `{:.0}` printed "1 2 2 3 4 4 5 6".
    #[test]
    fn whole_number_axis_labels_do_not_repeat() {
        for episodes in [2u64, 7, 13, 31, 100] {
            let points: Vec<(u64, f64)> = (0..episodes).map(|e| (e, 500.0 - e as f64)).collect();
            let texts = drawn_texts(&[Series::from_episodes("UAV1".into(), &points)], &[]);
            // The second panel's texts follow its caption.
            for panel in texts.split(|t| t.starts_with("after episode")) {
                let mut labels: Vec<&String> =
                    panel.iter().filter(|t| t.parse::<u64>().is_ok()).collect();
                let all = labels.len();
                assert!(all >= 2, "{episodes} episodes: labels {labels:?}");
                labels.sort();
                labels.dedup();
                assert_eq!(labels.len(), all, "{episodes} episodes: repeated labels {panel:?}");
            }
        }
    }

    /// `eval` has no training: its plot has the greedy lengths alone, on one panel, with no
    /// iterations axis and no legend entry for the empty learning curves.
    #[test]
    fn a_plot_without_points_shows_its_references_alone() {
        let empty =
            [Series { label: "UAV1 (mean of 4 trials)".into(), points: vec![], of_curve: None }];
        let greedy = Reference {
            label: "UAV1 greedy after training".into(),
            value: 250.0,
            detail: None,
            curve: Some(0),
        };
        let texts = drawn_texts(&empty, &[greedy]);
        let has = |text: &str| texts.iter().any(|t| t == text);
        assert!(has("UAV1 greedy after training (250.00)"), "{texts:?}");
        assert!(!has("UAV1 (mean of 4 trials)"), "a legend for a curve without data");
        assert!(!has("iterations (episodes)"), "an iterations axis without iterations");
        assert!(!texts.iter().any(|t| t.starts_with("after episode")), "a second panel");
    }

    /// A line through one point draws nothing: the point is drawn as a dot.
    #[test]
    fn a_series_of_one_point_is_drawn_as_a_dot() {
        let one = [Series { label: "one".into(), points: vec![(0.0, 4.0)], of_curve: None }];
        let svg = drawn_texts(&one, &[]).join("\n");
        assert!(svg.contains("<circle"), "no dot in {svg}");
        let two =
            [Series { label: "two".into(), points: vec![(0.0, 4.0), (1.0, 3.0)], of_curve: None }];
        assert!(!drawn_texts(&two, &[]).join("\n").contains("<circle"), "a dot on a line");
    }

    /// The error says why the file cannot be written, once, without plotters' wrappers.
    #[test]
    fn a_plot_that_cannot_be_written_says_why_once() {
        let path = Path::new("/nonexistent/curve.svg");
        let series =
            [Series { label: "UAV1".into(), points: vec![(0.0, 4.0), (1.0, 3.0)], of_curve: None }];
        let e = format!("{:#}", plot_curves(path, "test", &series, &[]).unwrap_err());
        assert_eq!(
            e,
            "cannot write /nonexistent/curve.svg: No such file or directory (os error 2)"
        );
    }
}
