//! What the supervisor does with each episode report while a run goes on: record it and
//! show progress (episodes, mean episode length, ticks/s, live agents).

use crate::results::Collector;
use anyhow::Result;
use flockstep_proto::{EpisodeReport, Phase};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::{Duration, Instant};

/// Training episodes of UAV1 in the progress bar's "mean length" window.
const RECENT: usize = 200;

pub struct Recorder {
    collector: Collector,
    bar: ProgressBar,
    quiet: bool,
    started: Instant,
    last_draw: Instant,
    env_steps: u64,
    live: usize,
    /// Training episodes recorded since the bar last moved: it moves at each redraw, since
    /// a move reads the clock and records come by the thousand.
    unshown: u64,
    /// What went wrong on the way (lost or restarted agents...), for `summary.json`. Kept
    /// here rather than returned by the transport so that a run that fails keeps them too.
    notes: Vec<String>,
}

impl Recorder {
    /// `total` is the number of training episodes over every trial.
    pub fn new(collector: Collector, total: u64, quiet: bool) -> Recorder {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr())
        };
        bar.set_style(
            ProgressStyle::with_template(
                "{elapsed_precise} [{bar:30}] {pos}/{len} episodes  {msg}",
            )
            .expect("a valid template")
            .progress_chars("=> "),
        );
        let now = Instant::now();
        Recorder {
            collector,
            bar,
            quiet,
            started: now,
            last_draw: now,
            env_steps: 0,
            live: 0,
            unshown: 0,
            notes: Vec::new(),
        }
    }

    /// Prints `line` on stderr above the progress bar, unless the run is quiet.
    pub fn say(&self, line: &str) {
        if !self.quiet {
            self.bar.suspend(|| flockstep_proto::output::message(&format!("supervisor: {line}")));
        }
    }

    /// Notes `note` in the summary and prints it on stderr as it happens, once, also when the
    /// run is quiet (`--quiet` hides the progress, not what went wrong).
    pub fn note(&mut self, note: String) {
        self.bar.suspend(|| flockstep_proto::output::message(&format!("supervisor: {note}")));
        self.notes.push(note);
    }

    /// Everything [`Recorder::note`] noted, in order.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    pub fn record(&mut self, report: &EpisodeReport) -> Result<()> {
        self.collector.record(report)?;
        let duration = flockstep_proto::slots_in(report.members)
            .map(|slot| u64::from(report.lengths[slot]))
            .max()
            .unwrap_or(0);
        self.env_steps += duration * u64::from(report.members.count_ones());
        self.live = report.live.count_ones() as usize;
        if report.phase == Phase::Train as u8 {
            self.unshown += 1;
        }
        Ok(())
    }

    /// Redraws the progress message, at most a few times a second.
    pub fn redraw(&mut self) {
        self.bar.inc(std::mem::take(&mut self.unshown));
        if self.last_draw.elapsed() < Duration::from_millis(200) {
            return;
        }
        self.last_draw = Instant::now();
        let recent = self.collector.train_lengths().first().map(|trials| {
            let tail: Vec<u32> =
                trials.iter().flat_map(|t| t.last(RECENT / trials.len().max(1))).collect();
            tail.iter().map(|&l| f64::from(l)).sum::<f64>() / tail.len().max(1) as f64
        });
        let ticks_per_s =
            self.collector.ticks() as f64 / self.started.elapsed().as_secs_f64().max(1e-9);
        self.bar.set_message(format!(
            "mean length {:.1}  {:.0} ticks/s  {} live agents",
            recent.unwrap_or(0.0),
            ticks_per_s,
            self.live
        ));
    }

    pub fn set_live(&mut self, live: usize) {
        self.live = live;
    }

    pub fn finish(&mut self) -> Result<()> {
        self.bar.finish_and_clear();
        self.collector.flush()
    }

    pub fn collector(&self) -> &Collector {
        &self.collector
    }

    pub fn env_steps(&self) -> u64 {
        self.env_steps
    }
}
