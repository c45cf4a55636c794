//! The supervisor's helper subcommands: `optimum`, `eval`, `generate` and `plot`.

use crate::curve::read_smoothed;
use crate::plot::{plot_curves, Series};
use anyhow::{Context, Result};
use flockstep_agents::comm::CommMode;
use flockstep_proto::output;
use flockstep_proto::{MAX_AGENTS, MAX_TRIALS};
use flockstep_world::optimum::route_optima;
use flockstep_world::scenario::Scenario;
use std::path::Path;

/// Prints the exact optimal expected episode length of each route flown alone, and the
/// optimal path. A route without an optimum (it cannot see some target) says why, and the
/// others' numbers are printed still: that is a fact about the map, not a failure.
pub fn optimum(spec: &str) -> Result<()> {
    let scenario = Scenario::resolve(spec).map_err(|e| anyhow::anyhow!("--scenario: {e}"))?;
    for route in route_optima(&scenario) {
        output::line(&format!("{} {route}", scenario.name()))?;
    }
    Ok(())
}

/// Draws UAV1's smoothed curve of several runs on one plot (`PATH=LABEL` each). The plot is
/// SVG, the one format drawn here: another extension is refused rather than given SVG.
pub fn plot(curves: &[String], out: &Path, title: &str) -> Result<()> {
    let svg = out.extension().is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    anyhow::ensure!(
        svg,
        "--out {}: plots are written as SVG only; give a file name ending in .svg",
        out.display()
    );
    let mut loaded = Vec::new();
    for spec in curves {
        let (path, label) = spec
            .split_once('=')
            .with_context(|| format!("--curve `{spec}`: expected PATH=LABEL"))?;
        loaded.push((label.to_string(), read_smoothed(Path::new(path), 1)?));
    }
    let series: Vec<Series> =
        loaded.iter().map(|(label, points)| Series::from_episodes(label.clone(), points)).collect();
    plot_curves(out, title, &series, &[])?;
    // As `generate`, a run and `reproduce` say what they wrote.
    Ok(output::line(&out.display().to_string())?)
}

/// Writes the generated scenario `spec` as a new `.map` file (it loads back as it is). An
/// existing file is refused, as a run refuses a directory holding results: a map may have
/// been edited by hand since it was generated.
pub fn generate(spec: &str, out: &Path) -> Result<()> {
    use std::io::Write;
    let text =
        flockstep_world::generate::generate_text(spec).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut file = match std::fs::OpenOptions::new().write(true).create_new(true).open(out) {
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            anyhow::bail!("--out {}: the file exists; remove it or choose another", out.display())
        }
        opened => opened.with_context(|| format!("cannot write {}", out.display()))?,
    };
    file.write_all(text.as_bytes()).with_context(|| format!("cannot write {}", out.display()))?;
    Ok(output::line(&out.display().to_string())?)
}

/// Evaluates the snapshots of the run in `dir` greedily: the same scenario (its
/// `scenario.map`), tree (`tree.bt`), agents, trials, seed and communication as recorded in
/// its `summary.json`, no training. Prints the greedy length of every agent. Returns whether
/// the evaluation ran to its end: stopped by Ctrl-C, what it evaluated so far is printed and
/// written, flagged `"complete": false` as a run's partial results are.
pub fn eval(
    dir: &Path,
    episodes: u64,
    out: Option<std::path::PathBuf>,
    transport: crate::cli::Transport,
    defaults: &crate::cli::RunArgs,
    stop: &crate::interrupt::Interrupts,
) -> Result<bool> {
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
    // The run's settings come from its summary.json: one that does not fit is named there,
    // not as the command-line flag it stands for.
    let comm =
        summary["comm"].as_str().with_context(|| format!("{}: no `comm`", path.display()))?;
    anyhow::ensure!(
        CommMode::parse(comm).is_some(),
        "{}: `comm` \"{comm}\" is none of none, flags, compact",
        path.display()
    );
    let uavs = summary_number(&summary, &path, "uavs", 1..=MAX_AGENTS as u64)?;
    let trials = summary_number(&summary, &path, "trials", 1..=MAX_TRIALS as u64)?;
    let seed = summary_number(&summary, &path, "seed", 0..=u64::MAX)?;
    let tick_cap = summary_number(&summary, &path, "tick_cap", 1..=u32::MAX.into())?;
    // Its errors name the file.
    let routes = Scenario::resolve(scenario).map_err(|e| anyhow::anyhow!("{e}"))?.n_routes();
    anyhow::ensure!(
        uavs <= routes,
        "{}: `uavs` {uavs}, but its scenario.map has {routes} route(s)",
        path.display()
    );
    let args = crate::cli::RunArgs {
        uavs,
        trials,
        seed,
        tick_cap,
        comm: Some(comm.to_string()),
        scenario: Some(scenario.to_string()),
        bt: Some(dir.join("tree.bt")),
        episodes: 0,
        eval_episodes: episodes,
        eval_every: 0,
        eval_block: None,
        resume: Some(dir.to_path_buf()),
        out: Some(out.unwrap_or_else(|| dir.join("eval"))),
        transport,
        run_id: None,
        ..defaults.clone()
    };
    let mut config = crate::config::RunConfig::resolve_resuming_as(&args, "eval --qtables")?;
    let notes = [incomplete_run(&summary, &path), attached_left_out(&summary, uavs)];
    for note in notes.into_iter().flatten() {
        output::message(&format!("supervisor: {note}"));
        config.notes.push(note);
    }
    let outcome = crate::run::run_experiment(&config, stop)?;
    let result = crate::summary::summary_file(&config.out)?;
    let agents = result["greedy_episode_length"].as_array().map_or(0, Vec::len);
    for agent in 0..agents {
        output::line(&crate::summary::greedy_line(&result, agent))?;
    }
    if !outcome.complete {
        output::message(&format!(
            "supervisor: the evaluation was stopped early: the lengths above are partial \
             ({} says \"complete\": false)",
            config.out.join("summary.json").display()
        ));
    }
    Ok(outcome.complete)
}

/// What `eval` says of a run whose `summary.json` (at `path`) has `"complete": false`: it
/// was stopped early or failed, so the tables evaluated are what it had learned by then, not
/// what it set out to learn. None for a complete run (or an older summary without the field).
fn incomplete_run(summary: &serde_json::Value, path: &Path) -> Option<String> {
    (summary["complete"].as_bool() == Some(false)).then(|| {
        format!(
            "eval evaluates the Q-tables of a run that did not complete ({} says \"complete\": \
             false): what it had learned when it stopped",
            path.display()
        )
    })
}

/// What `eval` leaves out of a run whose `summary.json` lists agents that attached (`agents`,
/// `attached`): it starts the `uavs` agents the run started, as the run did, and an agent
/// that attached joined a run in progress, which an evaluation has not. None if none did.
fn attached_left_out(summary: &serde_json::Value, uavs: usize) -> Option<String> {
    let attached: Vec<String> = summary["agents"]
        .as_array()?
        .iter()
        .filter(|agent| agent["attached"].as_bool() == Some(true))
        .filter_map(|agent| Some(format!("UAV{}", agent["uav"].as_u64()?)))
        .collect();
    let started: Vec<String> = (1..=uavs).map(|n| format!("UAV{n}")).collect();
    (!attached.is_empty()).then(|| {
        format!(
            "eval evaluates only the agents the run started ({}), not {}, which attached to it",
            started.join(", "),
            attached.join(", ")
        )
    })
}

/// Whole number `key` of the `summary.json` at `path`, as a `T`, checked to be in `range`.
fn summary_number<T: TryFrom<u64>>(
    summary: &serde_json::Value,
    path: &Path,
    key: &str,
    range: std::ops::RangeInclusive<u64>,
) -> Result<T> {
    let value = summary[key]
        .as_u64()
        .with_context(|| format!("{}: no whole number `{key}`", path.display()))?;
    anyhow::ensure!(
        range.contains(&value),
        "{}: `{key}` {value} is out of range {range:?}",
        path.display()
    );
    T::try_from(value)
        .ok()
        .with_context(|| format!("{}: `{key}` {value} is out of range", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_evaluation_says_which_attached_agents_it_leaves_out() {
        let summary = serde_json::json!({ "agents": [
            { "uav": 1, "attached": false },
            { "uav": 2, "attached": false },
            { "uav": 3, "attached": true },
        ] });
        assert_eq!(
            attached_left_out(&summary, 2).as_deref(),
            Some("eval evaluates only the agents the run started (UAV1, UAV2), not UAV3, which attached to it")
        );
        let none_attached = serde_json::json!({ "agents": [{ "uav": 1, "attached": false }] });
        assert_eq!(attached_left_out(&none_attached, 1), None);
        assert_eq!(attached_left_out(&serde_json::json!({}), 1), None, "an older summary");
    }

    #[test]
    fn an_evaluation_says_when_the_run_did_not_complete() {
        let path = Path::new("run/summary.json");
        let stopped = serde_json::json!({ "complete": false });
        assert_eq!(
            incomplete_run(&stopped, path).as_deref(),
            Some(
                "eval evaluates the Q-tables of a run that did not complete (run/summary.json \
                 says \"complete\": false): what it had learned when it stopped"
            )
        );
        assert_eq!(incomplete_run(&serde_json::json!({ "complete": true }), path), None);
        assert_eq!(incomplete_run(&serde_json::json!({}), path), None, "an older summary");
    }
}
