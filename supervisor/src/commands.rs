//! The supervisor's helper subcommands: `optimum`, `eval`, `generate` and `plot`.

use crate::curve::read_smoothed;
use crate::plot::{plot_curves, Series};
use anyhow::{Context, Result};
use flockstep_world::optimum::{optimum as memoryless_optimum, optimum_with_known_target};
use flockstep_world::scenario::Scenario;
use std::path::Path;

/// Prints the exact optimal expected episode length of each route flown alone, and the
/// optimal path.
pub fn optimum(spec: &str) -> Result<()> {
    let scenario = Scenario::resolve(spec).map_err(|e| anyhow::anyhow!("--scenario: {e}"))?;
    for uav in 0..scenario.n_routes() {
        let best = memoryless_optimum(&scenario, uav)
            .map_err(|e| anyhow::anyhow!("UAV{}: {e}", uav + 1))?;
        let known = optimum_with_known_target(&scenario, uav)
            .map_err(|e| anyhow::anyhow!("UAV{}: {e}", uav + 1))?;
        println!(
            "{} UAV{}: memoryless optimum {:.4} ticks (per target {:?}); knowing the target {:.4}",
            scenario.name(),
            uav + 1,
            best.expected_ticks,
            best.lengths,
            known.expected_ticks
        );
        println!("{best}");
    }
    Ok(())
}

/// Draws UAV1's smoothed curve of several runs on one plot (`PATH=LABEL` each).
pub fn plot(curves: &[String], out: &Path, title: &str) -> Result<()> {
    let mut loaded = Vec::new();
    for spec in curves {
        let (path, label) = spec
            .split_once('=')
            .with_context(|| format!("--curve `{spec}`: expected PATH=LABEL"))?;
        loaded.push((label.to_string(), read_smoothed(Path::new(path), 1)?));
    }
    let series: Vec<Series> =
        loaded.iter().map(|(label, values)| Series::from_values(label.clone(), values)).collect();
    plot_curves(out, title, &series, &[])
}

/// Writes the generated scenario `spec` as a `.map` file (it loads back as it is).
pub fn generate(spec: &str, out: &Path) -> Result<()> {
    let text =
        flockstep_world::generate::generate_text(spec).map_err(|e| anyhow::anyhow!("{e}"))?;
    std::fs::write(out, text).with_context(|| format!("cannot write {}", out.display()))?;
    println!("{}", out.display());
    Ok(())
}

/// Evaluates the snapshots of the run in `dir` greedily: the same scenario (its
/// `scenario.map`), tree (`tree.bt`), agents, trials, seed and communication as recorded in
/// its `summary.json`, no training. Prints the greedy length of every agent.
pub fn eval(
    dir: &Path,
    episodes: u64,
    out: Option<std::path::PathBuf>,
    transport: crate::cli::Transport,
    defaults: &crate::cli::RunArgs,
    stop: &std::sync::atomic::AtomicBool,
) -> Result<()> {
    anyhow::ensure!(episodes > 0, "eval --episodes must be at least 1 (greedy episodes per trial)");
    let summary = crate::summary::summary_file(dir)?;
    let path = dir.join("summary.json");
    for file in ["scenario.map", "tree.bt"] {
        anyhow::ensure!(
            dir.join(file).is_file(),
            "eval --qtables {}: no {file} (a finished run's results directory has one)",
            dir.display()
        );
    }
    // Absolute: never read as a built-in name or a `gen:` spec (`--qtables gen:x`).
    let map = dir.join("scenario.map");
    let map = map.canonicalize().with_context(|| format!("cannot read {}", map.display()))?;
    let scenario =
        map.to_str().with_context(|| format!("{}: the path is not UTF-8", map.display()))?;
    let args = crate::cli::RunArgs {
        uavs: summary_number(&summary, &path, "uavs")?,
        trials: summary_number(&summary, &path, "trials")?,
        seed: summary_number(&summary, &path, "seed")?,
        tick_cap: summary_number(&summary, &path, "tick_cap")?,
        comm: Some(
            summary["comm"]
                .as_str()
                .with_context(|| format!("{}: no `comm`", path.display()))?
                .to_string(),
        ),
        scenario: Some(scenario.to_string()),
        bt: Some(dir.join("tree.bt")),
        episodes: 0,
        eval_episodes: episodes,
        eval_every: 0,
        resume: Some(dir.to_path_buf()),
        out: Some(out.unwrap_or_else(|| dir.join("eval"))),
        transport,
        run_id: None,
        ..defaults.clone()
    };
    let config = crate::config::RunConfig::resolve_resuming_as(&args, "eval --qtables")?;
    let outcome = crate::run::run_experiment(&config, stop)?;
    let result = crate::summary::summary_file(&config.out)?;
    for (agent, length) in
        result["greedy_episode_length"].as_array().into_iter().flatten().enumerate()
    {
        let truncated = &result["greedy_truncated"][agent];
        println!(
            "UAV{} greedy episode length {length} ({truncated} of {} episodes truncated)",
            agent + 1,
            result["greedy_episodes"][agent]
        );
    }
    anyhow::ensure!(outcome.complete, "the evaluation was stopped early");
    Ok(())
}

/// Whole number `key` of the `summary.json` at `path`, as a `T` (a number that does not fit
/// is named, not cut short).
fn summary_number<T: TryFrom<u64>>(
    summary: &serde_json::Value,
    path: &Path,
    key: &str,
) -> Result<T> {
    let value = summary[key]
        .as_u64()
        .with_context(|| format!("{}: no whole number `{key}`", path.display()))?;
    T::try_from(value)
        .ok()
        .with_context(|| format!("{}: `{key}` {value} is out of range", path.display()))
}
