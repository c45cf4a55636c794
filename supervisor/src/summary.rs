//! `summary.json`: the run's configuration, timings and headline results, for people and
//! for scripts (tests and the results report read it). Beside each agent's greedy length
//! stand the exact optima of its route flown alone: with a memoryless policy, and knowing
//! the target in advance (a lower bound for any communication).

use crate::cli::Transport;
use crate::config::RunConfig;
use crate::curve;
use crate::recorder::Recorder;
use crate::results::Flown;
use crate::run::Outcome;
use anyhow::{Context, Result};
use clap::ValueEnum;
use flockstep_world::optimum::{optimum, optimum_with_known_target};
use serde_json::{json, Value};
use std::path::Path;

/// The iceoryx2 version the workspace requires (`Cargo.toml`), recorded in every summary;
/// a test keeps the two in step.
const ICEORYX2_VERSION: &str = "0.10";

/// Window of `final_mean_episode_length`: UAV1's last 1000 training episodes per trial
/// (fewer if it flew fewer; `final_window` says how many).
pub const FINAL_WINDOW: usize = 1000;

/// The summary of a run; `error` is what failed it, if anything did (the last note).
pub fn summary(
    config: &RunConfig,
    recorder: &Recorder,
    wall_seconds: f64,
    outcome: &Outcome,
    error: Option<&str>,
) -> Value {
    let collector = recorder.collector();
    let agents = collector.agents();
    let greedy: Vec<_> = (0..agents).map(|a| collector.greedy(a)).collect();
    let ticks = collector.ticks();
    let per_second = |n: u64| if wall_seconds > 0.0 { n as f64 / wall_seconds } else { 0.0 };
    let finals: Vec<_> = (0..agents).map(|a| collector.final_mean(a, FINAL_WINDOW)).collect();
    let final_means: Vec<_> = finals.iter().map(|f| f.map(|(mean, _)| mean)).collect();
    let final_windows: Vec<_> = finals.iter().map(|f| f.map(|(_, window)| window)).collect();
    let mut notes = config.notes.clone();
    notes.extend(recorder.notes().iter().cloned());
    notes.extend(error.map(str::to_string));
    // Settings of agent processes: an in-process run has none, and refuses them.
    let processes = config.transport == Transport::Shm;
    // As typed: `never` or `on-failure`.
    let restart = processes
        .then(|| config.restart.to_possible_value().map(|v| v.get_name().to_string()))
        .flatten();
    json!({
        "flockstep_version": env!("CARGO_PKG_VERSION"),
        "iceoryx2_version": ICEORYX2_VERSION,
        "run_id": config.run_id,
        "transport": format!("{:?}", config.transport).to_lowercase(),
        "complete": outcome.complete,
        "every_agent_flew_every_episode":
            every_agent_flew_every_episode(config, recorder, outcome.complete),
        "notes": notes,
        "peak_rss_kib": outcome.peak_rss_kib.iter().map(|(name, kib)| json!({ "process": name, "kib": kib })).collect::<Vec<_>>(),
        "scenario": config.scenario_arg,
        "scenario_name": config.scenario.name(),
        "seed": config.seed,
        "uavs": config.uavs,
        "agents": agents_that_flew(config, recorder),
        "trials": config.trials,
        "episodes": config.episodes.train_episodes,
        "eval_episodes": config.episodes.eval_episodes,
        "tick_cap": config.episodes.tick_cap,
        "comm": config.comm.name(),
        "alpha": config.params.alpha,
        "gamma": config.params.gamma,
        "epsilon": config.params.epsilon,
        "tree": config.tree_text(),
        "tree_file": config.bt_path.as_deref().map(absolute),
        "smoothing_window": curve::window(config.smoothing, collector.trained_episodes()),
        "eval_every": config.episodes.eval_every,
        "eval_block": (config.episodes.eval_every > 0).then_some(config.episodes.eval_block),
        "restart": restart,
        "snapshot_every": processes.then_some(config.snapshot_every),
        "agent_timeout_ms": processes.then_some(config.agent_timeout_ms),
        "resume": config.resume.as_deref().map(absolute),
        "ticks": ticks,
        "rounds": collector.rounds(),
        "env_steps": recorder.env_steps(),
        "wall_seconds": wall_seconds,
        "ticks_per_second": per_second(ticks),
        "rounds_per_second": per_second(collector.rounds()),
        "env_steps_per_second": per_second(recorder.env_steps()),
        "final_window": final_windows.first().copied().flatten(),
        "final_window_per_agent": final_windows,
        "final_mean_episode_length": final_means.first().copied().flatten(),
        "final_mean_episode_length_per_agent": final_means,
        "train_truncated": (0..agents).map(|a| collector.train_truncated(a)).collect::<Vec<_>>(),
        "greedy_episode_length": greedy.iter().map(|g| g.as_ref().map(|g| g.mean())).collect::<Vec<_>>(),
        "greedy_episode_length_per_trial": (0..agents).map(|a| collector.greedy_per_trial(a)).collect::<Vec<_>>(),
        "greedy_episodes": greedy.iter().map(|g| g.as_ref().map_or(0, |g| g.episodes)).collect::<Vec<_>>(),
        "greedy_truncated": greedy.iter().map(|g| g.as_ref().map_or(0, |g| g.truncated)).collect::<Vec<_>>(),
        "optimum_memoryless": (0..agents).map(|a| optimum(&config.scenario, a).ok().map(|o| o.expected_ticks)).collect::<Vec<_>>(),
        "optimum_known_target": (0..agents).map(|a| optimum_with_known_target(&config.scenario, a).ok().map(|o| o.expected_ticks)).collect::<Vec<_>>(),
    })
}

/// `path` made absolute, so that the record still leads to the file from another directory
/// (as is when it cannot be: it was there when the run started).
fn absolute(path: &Path) -> String {
    path.canonicalize().unwrap_or_else(|_| path.to_path_buf()).display().to_string()
}

/// Whether every agent the run started flew every training and greedy episode (periodic and
/// final) of every trial: of the run's plan if it is `complete`, else of those the run flew
/// before it was stopped. A run that lost an agent, for good or until its restart, may
/// still have run to its end; its results are then those of fewer agents for a while, which
/// this says without reading `notes`.
fn every_agent_flew_every_episode(config: &RunConfig, recorder: &Recorder, complete: bool) -> bool {
    let collector = recorder.collector();
    let lengths = collector.train_lengths();
    let trained = |slot: usize, trial: usize| {
        lengths.get(slot).and_then(|trials| trials.get(trial)).map_or(0, |f| f.len() as u64)
    };
    let evaluated = |slot: usize, trial: usize| collector.greedy_flown(slot, trial);
    let e = &config.episodes;
    let greedy_planned = collector.plan().greedy_episodes(e.eval_episodes).unwrap_or(u64::MAX);
    let (uavs, trials) = (config.uavs, config.trials);
    each_flew_its_due(trained, uavs, trials, complete.then_some(e.train_episodes))
        && each_flew_its_due(evaluated, uavs, trials, complete.then_some(greedy_planned))
}

/// Whether each of the first `agents` agents flew, in each of `trials`, the episodes due
/// there (`flown(agent, trial)` of them): `planned` of a run's plan, or without a plan (a run
/// that did not complete) as many as any of those agents flew in that trial.
fn each_flew_its_due(
    flown: impl Fn(usize, usize) -> u64,
    agents: usize,
    trials: usize,
    planned: Option<u64>,
) -> bool {
    (0..trials).all(|trial| {
        let due =
            planned.unwrap_or_else(|| (0..agents).map(|a| flown(a, trial)).max().unwrap_or(0));
        (0..agents).all(|agent| flown(agent, trial) == due)
    })
}

/// Every agent that flew a training episode: its number, whether it attached to the run (on
/// a route the supervisor started no agent for) and, per trial, the first episode it flew
/// and how many it flew. The curves and per-agent results are read against these: an
/// attached agent's start late, and `uavs` counts only the agents the run started.
fn agents_that_flew(config: &RunConfig, recorder: &Recorder) -> Vec<Value> {
    let lengths = recorder.collector().train_lengths();
    lengths
        .iter()
        .enumerate()
        .filter(|(_, trials)| trials.iter().any(|t| !t.is_empty()))
        .map(|(slot, trials)| {
            let first: Vec<_> =
                trials.iter().map(|t| (!t.is_empty()).then(|| t.span().start)).collect();
            let flown: Vec<_> = trials.iter().map(Flown::len).collect();
            json!({
                "uav": slot + 1,
                "attached": slot >= config.uavs,
                "first_episode_per_trial": first,
                "episodes_per_trial": flown,
            })
        })
        .collect()
}

/// UAV `agent`'s greedy result in a `summary.json`, as a person reads it: the mean length
/// and how many of its greedy episodes hit the tick cap. `eval` prints it, and a run says it
/// when it ends.
pub fn greedy_line(summary: &Value, agent: usize) -> String {
    let uav = agent + 1;
    match summary["greedy_episode_length"][agent].as_f64() {
        Some(length) => format!(
            "UAV{uav} greedy episode length {length:.2} ({} of {} episodes truncated)",
            summary["greedy_truncated"][agent], summary["greedy_episodes"][agent]
        ),
        None => format!("UAV{uav} flew no greedy episode"),
    }
}

/// What a run says when it ends, under its progress bar (which it clears): how long it
/// took and how fast it went, whether it ran to its end, and per agent its greedy result
/// and its mean over its last training episodes. All from its `summary.json`, which holds
/// more.
pub fn closing_lines(summary: &Value) -> Vec<String> {
    let how = if summary["complete"].as_bool() == Some(true) {
        "finished"
    } else {
        "stopped before its end (partial results, \"complete\": false)"
    };
    let mut lines = vec![format!(
        "{how} in {:.2} s: {} rounds, {:.0} ticks/s",
        summary["wall_seconds"].as_f64().unwrap_or(0.0),
        summary["rounds"],
        summary["ticks_per_second"].as_f64().unwrap_or(0.0)
    )];
    let agents = summary["greedy_episode_length"].as_array().map_or(0, Vec::len);
    for agent in 0..agents {
        let mut line = greedy_line(summary, agent);
        let mean = summary["final_mean_episode_length_per_agent"][agent].as_f64();
        let window = &summary["final_window_per_agent"][agent];
        if let Some(mean) = mean {
            line += &format!("; training mean {mean:.2} over its last {window} episodes");
        }
        lines.push(line);
    }
    lines
}

pub fn write(path: &Path, value: &Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value).expect("JSON values serialise");
    std::fs::write(path, text + "\n").with_context(|| format!("cannot write {}", path.display()))
}

/// Reads back the `summary.json` of a results directory (at most
/// [`flockstep_world::map::MAX_INPUT_BYTES`]: `eval` reads one a user names).
pub fn summary_file(dir: &Path) -> Result<Value> {
    let path = dir.join("summary.json");
    let text = flockstep_world::map::read_input(&path)
        .with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not JSON", path.display()))
}

#[cfg(test)]
mod tests {
    use super::{closing_lines, each_flew_its_due};
    use serde_json::{json, Value};

    /// Episodes flown by agent and trial, as `each_flew_its_due` reads them.
    fn flown(counts: &[[u64; 2]]) -> impl Fn(usize, usize) -> u64 + '_ {
        move |agent, trial| counts[agent][trial]
    }

    /// A complete run is held to its plan; one stopped early to what the agents flew, in
    /// each trial apart: an agent one episode short in one trial is enough to say no.
    #[test]
    fn every_agent_must_fly_the_planned_episodes_or_those_any_agent_flew() {
        let even = [[5, 5], [5, 5]];
        assert!(each_flew_its_due(flown(&even), 2, 2, Some(5)));
        assert!(!each_flew_its_due(flown(&even), 2, 2, Some(6)));
        assert!(each_flew_its_due(flown(&even), 2, 2, None));
        let one_short = [[5, 5], [5, 4]];
        assert!(!each_flew_its_due(flown(&one_short), 2, 2, None));
        assert!(!each_flew_its_due(flown(&one_short), 2, 2, Some(5)));
        let trials_apart = [[5, 3], [5, 3]];
        assert!(each_flew_its_due(flown(&trials_apart), 2, 2, None));
        // An agent the run did not start (the third here) is not held to anything.
        assert!(each_flew_its_due(flown(&[[5, 5], [5, 5], [0, 0]]), 2, 2, Some(5)));
    }

    #[test]
    fn the_recorded_iceoryx2_version_is_the_workspace_requirement() {
        let manifest = include_str!("../../Cargo.toml");
        let requirement = format!("\niceoryx2 = \"{}\"\n", super::ICEORYX2_VERSION);
        assert!(
            manifest.contains(&requirement),
            "the workspace Cargo.toml has no `{}`: update ICEORYX2_VERSION",
            requirement.trim()
        );
    }

    /// The fields `closing_lines` reads, as a run of two agents writes them.
    fn summary_of(
        complete: bool,
        greedy: [Option<f64>; 2],
        final_means: [Option<f64>; 2],
    ) -> Value {
        json!({
            "complete": complete,
            "wall_seconds": 5.5308,
            "rounds": 780_567,
            "ticks_per_second": 554_308.9,
            "greedy_episode_length": greedy,
            "greedy_truncated": [3, 0],
            "greedy_episodes": greedy.map(|g| if g.is_some() { 4000 } else { 0 }),
            "final_mean_episode_length_per_agent": final_means,
            "final_window_per_agent": final_means.map(|m| m.map(|_| 1000)),
        })
    }

    #[test]
    fn a_finished_run_says_its_time_speed_and_each_agents_greedy_and_training_means() {
        let summary =
            summary_of(true, [Some(10.4225), Some(4.4535)], [Some(12.455), Some(5.33375)]);
        assert_eq!(
            closing_lines(&summary),
            [
                "finished in 5.53 s: 780567 rounds, 554309 ticks/s",
                "UAV1 greedy episode length 10.42 (3 of 4000 episodes truncated); training mean \
                 12.46 over its last 1000 episodes",
                "UAV2 greedy episode length 4.45 (0 of 4000 episodes truncated); training mean \
                 5.33 over its last 1000 episodes",
            ]
        );
    }

    #[test]
    fn a_run_stopped_early_says_its_results_are_partial_and_what_it_did_not_fly() {
        let summary = summary_of(false, [None, Some(4.0)], [Some(20.0), None]);
        assert_eq!(
            closing_lines(&summary),
            [
                "stopped before its end (partial results, \"complete\": false) in 5.53 s: \
                 780567 rounds, 554309 ticks/s",
                "UAV1 flew no greedy episode; training mean 20.00 over its last 1000 episodes",
                "UAV2 greedy episode length 4.00 (0 of 4000 episodes truncated)",
            ]
        );
    }
}
