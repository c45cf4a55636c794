//! One experiment from start to results: prepare the results directory, run the chosen
//! transport, then write the learning curve, its plot and the summary. Results are written
//! also when the run is stopped early (Ctrl-C), flagged `"complete": false`.

use crate::cli::Transport;
use crate::config::RunConfig;
use crate::curve;
use crate::interrupt::Interrupts;
use crate::out_lock::OutDirLock;
use crate::plot::{plot_curves, Reference, Series};
use crate::recorder::Recorder;
use crate::results::{Collector, EvalPlan};
use crate::summary;
use anyhow::{Context, Result};
use flockstep_agents::snapshot::{read_snapshot, snapshot_path};
use flockstep_proto::Phase;
use std::path::Path;
use std::time::Instant;

/// How a run ended. What went wrong on the way but did not stop it (lost agents...) is in
/// the recorder's notes ([`Recorder::note`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outcome {
    /// Every trial ran its whole budget.
    pub complete: bool,
    /// Peak resident memory of each process of the run (name, KiB).
    pub peak_rss_kib: Vec<(String, u64)>,
}

/// This process's own peak resident memory in KiB: `VmHWM` of `/proc/self/status`, the
/// high-water mark of this program's memory. `getrusage` would report the peak of the
/// program this one was exec'd from if that was larger: under `cargo run` that is cargo's
/// (about 60 MB, where the supervisor itself stays near 10 MB). It is the fallback where
/// `/proc` cannot be read.
pub fn own_peak_rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|status| vm_hwm_kib(&status))
        .unwrap_or_else(|| {
            // SAFETY: getrusage with a valid out-pointer.
            let usage = unsafe {
                let mut usage: libc::rusage = std::mem::zeroed();
                libc::getrusage(libc::RUSAGE_SELF, &mut usage);
                usage
            };
            usage.ru_maxrss as u64
        })
}

/// The `VmHWM:` line of a `/proc/<pid>/status` text, in KiB.
fn vm_hwm_kib(status: &str) -> Option<u64> {
    let line = status.lines().find_map(|line| line.strip_prefix("VmHWM:"))?;
    line.trim().strip_suffix("kB")?.trim().parse().ok()
}

pub fn run_experiment(config: &RunConfig, stop: &Interrupts) -> Result<Outcome> {
    if config.transport == Transport::Shm {
        // Before anything is written or started: this run would read the other's records.
        crate::shm::prepare(&config.run_id)?;
    }
    // Held until the results are written.
    let _out_lock = prepare_out_dir(config)?;
    let e = &config.episodes;
    let plan = EvalPlan::new(e.train_episodes, e.eval_every, e.eval_block);
    let collector = Collector::create(&config.out, config.uavs, config.trials, plan)?;
    // Every episode the run plays, training and greedy, is on the progress bar. Only its
    // length: `RunConfig::resolve` refuses counts past `u64`.
    let per_trial = plan.greedy_episodes(e.eval_episodes).unwrap_or(u64::MAX);
    let total = per_trial.saturating_add(e.train_episodes).saturating_mul(config.trials as u64);
    let first = if e.train_episodes > 0 { Phase::Train } else { Phase::Eval };
    let mut recorder = Recorder::new(collector, total, first, config.quiet);
    let started = Instant::now();
    let result = match config.transport {
        Transport::Inproc => crate::inproc::run(config, &mut recorder, stop)
            .map(|complete| Outcome { complete, peak_rss_kib: vec![] }),
        Transport::Shm => crate::shm::run(config, &mut recorder, stop),
    };
    let wall = started.elapsed().as_secs_f64();
    // Whatever happened, what was collected is written before the error is reported; the
    // first error is the one reported (a full disk fails the run, then every write after).
    let finished = recorder.finish();
    let mut outcome = result
        .as_ref()
        .map(Outcome::clone)
        .unwrap_or_else(|_| Outcome { complete: false, peak_rss_kib: vec![] });
    outcome.peak_rss_kib.insert(0, ("supervisor".to_string(), own_peak_rss_kib()));
    let error = result.as_ref().err().map(|e| format!("{e:#}"));
    let written = write_results(config, &recorder, wall, &outcome, error.as_deref());
    let unwritten = [finished.err(), written.err()].into_iter().flatten().next();
    one_error(result, unwritten)
}

/// One error line: what failed the run, and what could not be written of its results.
fn one_error(result: Result<Outcome>, unwritten: Option<anyhow::Error>) -> Result<Outcome> {
    match (result, unwritten) {
        (Ok(outcome), None) => Ok(outcome),
        (Ok(_), Some(unwritten)) => Err(unwritten),
        (Err(failed), None) => Err(failed),
        // A full disk fails the run and then the results with the same words: said once.
        (Err(failed), Some(unwritten)) if format!("{failed:#}") == format!("{unwritten:#}") => {
            Err(failed)
        }
        (Err(failed), Some(unwritten)) => {
            Err(anyhow::anyhow!("{failed:#}; and its results could not be written: {unwritten:#}"))
        }
    }
}

/// Creates the results directory and locks it for the run (see [`OutDirLock`]), removes an
/// earlier run's results there if asked to, and checks it can be written, before any
/// process starts.
fn prepare_out_dir(config: &RunConfig) -> Result<OutDirLock> {
    std::fs::create_dir_all(&config.out)
        .with_context(|| format!("cannot create results directory {}", config.out.display()))?;
    let lock = OutDirLock::take(&config.out)?;
    if config.overwrite {
        crate::results::remove_earlier_results(&config.out)?;
    }
    let probe = config.out.join(".write-test");
    std::fs::write(&probe, b"")
        .with_context(|| format!("cannot write to results directory {}", config.out.display()))?;
    std::fs::remove_file(&probe).ok();
    std::fs::write(config.out.join("scenario.map"), config.scenario.source_text())
        .with_context(|| format!("cannot write to results directory {}", config.out.display()))?;
    std::fs::write(config.out.join("tree.bt"), config.tree_text())
        .with_context(|| format!("cannot write to results directory {}", config.out.display()))?;
    if let Some(resume) = &config.resume {
        copy_resumed_snapshots(config, resume)?;
    }
    Ok(lock)
}

/// Copies the snapshots a resumed run starts from into its own `qtables/`, unless they are
/// there already (`--resume` is `--out`). Its agents then read their tables from `--out`
/// only, and an agent restarted before it wrote a snapshot of its own goes on from these
/// rather than from empty tables. Each is read as the agents read it (a complete `.partial`
/// a crash left stands for a missing file) and written whole.
fn copy_resumed_snapshots(config: &RunConfig, resume: &Path) -> Result<()> {
    if crate::config::same_dir(resume, &config.out) {
        return Ok(());
    }
    for slot in 0..config.uavs {
        for trial in 0..config.trials {
            let from = snapshot_path(resume, slot, trial);
            let to = snapshot_path(&config.out, slot, trial);
            // Checked by `RunConfig::resolve`; read again, it must still be there.
            let snapshot = read_snapshot(&from)
                .with_context(|| format!("--resume {}", resume.display()))?
                .with_context(|| {
                    format!("--resume {}: no snapshot {}", resume.display(), from.display())
                })?;
            let bytes = snapshot.encode();
            if let Some(dir) = to.parent() {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("cannot create {}", dir.display()))?;
            }
            std::fs::write(&to, bytes).with_context(|| format!("cannot write {}", to.display()))?;
        }
    }
    Ok(())
}

/// Agents drawn on the curve plot (more lines would hide each other).
const PLOTTED_AGENTS: usize = 8;

/// Writes the curves, the plot and `summary.json`; `error` is what failed the run, if
/// anything did (a note of the summary). Each file is written even if one before it could
/// not be (the first such error is returned): `summary.json` alone keeps the run's timings
/// and notes.
fn write_results(
    config: &RunConfig,
    recorder: &Recorder,
    wall: f64,
    outcome: &Outcome,
    error: Option<&str>,
) -> Result<()> {
    let collector = recorder.collector();
    let window = curve::window(config.smoothing, collector.trained_episodes());
    let curves = curve::curves(collector.train_lengths(), window);
    let curves_written = curve::write_csv(&config.out.join("curve.csv"), &curves);
    let greedy: Vec<_> = (0..collector.agents()).map(|a| collector.greedy_curve(a)).collect();
    let greedy_written = curve::write_greedy_csv(&config.out.join("greedy_curve.csv"), &greedy);
    let mut series: Vec<Series> = curves
        .iter()
        .take(PLOTTED_AGENTS)
        .map(|c| {
            let points: Vec<(u64, f64)> =
                c.episodes.iter().copied().zip(c.smoothed.iter().copied()).collect();
            Series::from_episodes(
                format!(
                    "UAV{} (mean of {} trial{})",
                    c.agent,
                    config.trials,
                    if config.trials == 1 { "" } else { "s" }
                ),
                &points,
            )
        })
        .collect();
    for (agent, points) in
        greedy.iter().enumerate().take(PLOTTED_AGENTS).filter(|(_, p)| !p.is_empty())
    {
        series.push(Series {
            label: format!("UAV{} greedy", agent + 1),
            points: points.iter().map(|&(x, y, _)| (x as f64, y)).collect(),
            // Agent a's curve is series a.
            of_curve: Some(agent),
        });
    }
    let references: Vec<Reference> = (0..collector.agents())
        .take(PLOTTED_AGENTS)
        .filter_map(|a| {
            let stats = collector.greedy(a)?;
            Some(Reference {
                label: format!("UAV{} greedy after training", a + 1),
                value: stats.mean(),
                // A truncated episode counts the tick cap: the mean then understates a policy
                // that never ends. None truncated is said too, so no legend leaves it open.
                detail: Some(format!("{} of {} truncated", stats.truncated, stats.episodes)),
                // Agent a's curve is series a: the dashed line is read beside it.
                curve: Some(a),
            })
        })
        .collect();
    let title = format!(
        "{} | comm {} | {} episodes",
        config.scenario.name(),
        config.comm.name(),
        config.episodes.train_episodes
    );
    let plotted = plot_curves(&config.out.join("curve.svg"), &title, &series, &references);
    let value = summary::summary(config, recorder, wall, outcome, error);
    let summarized = summary::write(&config.out.join("summary.json"), &value);
    [curves_written, greedy_written, plotted, summarized].into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_and_the_results_it_kept_from_being_written_make_one_error_line() {
        let failed = || Err(anyhow::anyhow!("cannot write episodes.csv: No space left on device"));
        let same = one_error(failed(), failed().err()).unwrap_err();
        assert_eq!(format!("{same:#}"), "cannot write episodes.csv: No space left on device");
        let other =
            one_error(failed(), Some(anyhow::anyhow!("cannot write curve.csv"))).unwrap_err();
        assert_eq!(
            format!("{other:#}"),
            "cannot write episodes.csv: No space left on device; and its results could not be \
             written: cannot write curve.csv"
        );
    }
}
