//! `supervisor reproduce fig10|fig11`: the thesis's two result figures, each from one
//! command. Fig. 10 is scenario 1 with one UAV; Fig. 11 puts scenario 2 without
//! communication and scenario 3 with flags on one plot (UAV1's curves), with the exact
//! optima as reference lines. Every run is an ordinary run with its own results directory.

use crate::cli::{Figure, RunArgs};
use crate::config::RunConfig;
use crate::curve::{self, read_smoothed};
use crate::interrupt::Interrupts;
use crate::plot::{plot_curves, Reference, Series};
use crate::run::run_experiment;
use anyhow::{Context, Result};
use flockstep_proto::output;
use flockstep_world::optimum::{optimum, optimum_with_known_target};
use flockstep_world::Scenario;
use std::path::PathBuf;

/// One experiment of a figure: (directory name, label, scenario, UAVs, communication).
type Experiment = (&'static str, &'static str, &'static str, usize, &'static str);

const FIG10: &[Experiment] = &[("s1", "s1, one UAV, one target", "s1", 1, "none")];
const FIG11: &[Experiment] = &[
    ("s2-none", "s2, without communication", "s2", 1, "none"),
    ("s3-flags", "s3, with communication (UAV1)", "s3", 2, "flags"),
];

/// Runs the figure's experiments and draws it; returns false if a run was stopped early.
pub fn reproduce(
    figure: Figure,
    out: Option<PathBuf>,
    base: &RunArgs,
    stop: &Interrupts,
) -> Result<bool> {
    let (name, experiments) = match figure {
        Figure::Fig10 => ("fig10", FIG10),
        Figure::Fig11 => ("fig11", FIG11),
    };
    let out = out.unwrap_or_else(|| PathBuf::from("results").join(name));
    let mut curves = Vec::new();
    for &(dir, label, scenario, uavs, comm) in experiments {
        let args = RunArgs {
            scenario: Some(scenario.into()),
            uavs,
            comm: Some(comm.into()),
            out: Some(out.join(dir)),
            run_id: None,
            ..base.clone()
        };
        let config = RunConfig::resolve(&args)?;
        let outcome = run_experiment(&config, stop)?;
        output::message(&format!("{}: {}", label, config.out.display()));
        if !outcome.complete {
            return Ok(false);
        }
        let points = read_smoothed(&config.out.join("curve.csv"), 1)?;
        // Complete, it trained every planned episode: its curve's window (`run.rs`).
        let window = curve::window(config.smoothing, config.episodes.train_episodes);
        curves.push((label, window, points));
    }
    let references = references(figure)?;
    let series: Vec<Series> = curves
        .iter()
        .map(|(label, _, points)| Series::from_episodes(label.to_string(), points))
        .collect();
    let path = out.join(format!("{name}.svg"));
    let title = match figure {
        Figure::Fig10 => "Fig. 10: one UAV, one target, no communication (mean of trials)",
        Figure::Fig11 => "Fig. 11: learning without vs with communication (UAV1, mean of trials)",
    };
    plot_curves(&path, title, &series, &references)?;
    for (label, window, points) in &curves {
        // The first point whose trailing average spans a whole window: the points before
        // average fewer episodes, down to episode 0 alone (about twice the window's mean).
        let first =
            points.get(window.min(&points.len()).saturating_sub(1)).context("an empty curve")?.1;
        let last = points.last().context("an empty curve")?.1;
        output::line(&format!(
            "{label}: smoothed episode length {first:.1} (first full window of {window} \
             episodes) -> {last:.1}"
        ))?;
    }
    output::line(&path.display().to_string())?;
    Ok(true)
}

/// The exact optima of UAV1 as horizontal lines.
fn references(figure: Figure) -> Result<Vec<Reference>> {
    let scenario = |name| Scenario::builtin(name).context("a built-in scenario");
    let err = |e: flockstep_world::OptimumError| anyhow::anyhow!("{e}");
    Ok(match figure {
        Figure::Fig10 => vec![Reference {
            label: "optimum".into(),
            value: optimum(&scenario("s1")?, 0).map_err(err)?.expected_ticks,
            detail: None,
            curve: None,
        }],
        Figure::Fig11 => vec![
            Reference {
                label: "optimum without communication".into(),
                value: optimum(&scenario("s2")?, 0).map_err(err)?.expected_ticks,
                detail: None,
                curve: None,
            },
            Reference {
                label: "optimum knowing the target".into(),
                value: optimum_with_known_target(&scenario("s2")?, 0).map_err(err)?.expected_ticks,
                detail: None,
                curve: None,
            },
        ],
    })
}
