//! What the supervisor does with each episode report while a run goes on: record it and
//! show progress (phase, episodes, mean episode length, ticks/s, live agents).

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
    /// When the message was last redrawn, the prefix it drew and whether the bar was full;
    /// None until the first redraw, which is at once.
    last_draw: Option<(Instant, &'static str, bool)>,
    env_steps: u64,
    live: usize,
    /// Episodes recorded since the bar last moved: it moves at each redraw, since a move
    /// reads the clock and records come by the thousand.
    unshown: u64,
    /// The phase of each trial's latest record, or before its first one the phase it
    /// starts in. The bar names the phase before it: a final greedy evaluation of policies
    /// that hit the tick cap can take a while after the last training episode. Trials go
    /// through their episodes at their own pace, so the run is training while any of them is.
    trial_phases: Vec<Phase>,
    /// What went wrong on the way (lost or restarted agents...), for `summary.json`. Kept
    /// here rather than returned by the transport so that a run that fails keeps them too.
    notes: Vec<String>,
}

impl Recorder {
    /// `total` is the number of episodes, training and greedy, over every trial; `first` is
    /// the phase the trials start in (greedy when the run only evaluates).
    pub fn new(collector: Collector, total: u64, first: Phase, quiet: bool) -> Recorder {
        let target =
            if quiet { ProgressDrawTarget::hidden() } else { ProgressDrawTarget::stderr() };
        Recorder::drawing_to(target, collector, total, first, quiet)
    }

    /// [`Recorder::new`] drawing its bar to `target`.
    fn drawing_to(
        target: ProgressDrawTarget,
        collector: Collector,
        total: u64,
        first: Phase,
        quiet: bool,
    ) -> Recorder {
        let bar = ProgressBar::with_draw_target(Some(total), target);
        bar.set_style(
            ProgressStyle::with_template(
                "{elapsed_precise} {prefix:8} [{bar:30}] {pos}/{len} episodes  {msg}",
            )
            .expect("a valid template")
            .progress_chars("=> "),
        );
        bar.set_prefix("starting");
        Recorder {
            trial_phases: vec![first; collector.trials()],
            collector,
            bar,
            quiet,
            started: Instant::now(),
            last_draw: None,
            env_steps: 0,
            live: 0,
            unshown: 0,
            notes: Vec::new(),
        }
    }

    /// A recorder whose bar draws to a terminal in memory, for the tests of what it shows.
    /// The terminal takes one draw a second once the rate limit's burst is spent, as a long
    /// run spends it.
    #[cfg(test)]
    pub(crate) fn on_test_terminal(
        collector: Collector,
        total: u64,
        first: Phase,
    ) -> (Recorder, indicatif::InMemoryTerm) {
        let terminal = indicatif::InMemoryTerm::new(2, 200);
        let target = ProgressDrawTarget::term_like_with_hz(Box::new(terminal.clone()), 1);
        (Recorder::drawing_to(target, collector, total, first, false), terminal)
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
        self.unshown += 1;
        // The collector refused a record of no known phase or trial.
        self.trial_phases[report.trial as usize] =
            Phase::from_u8(report.phase).unwrap_or(Phase::Train);
        Ok(())
    }

    /// Training while any trial trains; greedy once every trial evaluates.
    fn phase(&self) -> Phase {
        if self.trial_phases.contains(&Phase::Train) {
            Phase::Train
        } else {
            Phase::Eval
        }
    }

    /// What the bar's prefix says: `starting` until the first record (the processes start
    /// and join), then `phase`.
    fn prefix(&self, phase: Phase) -> &'static str {
        match (self.bar.position(), phase) {
            (0, _) => "starting",
            (_, Phase::Train) => "training",
            (_, Phase::Eval) => "greedy",
        }
    }

    /// Redraws the progress message, at most a few times a second, and at once when the
    /// prefix changed or the bar became full: the bar counts every episode as it comes, and
    /// a prefix redrawn up to 200 ms late would call the greedy episodes that end a run
    /// "training" (a learned policy's final evaluation is often over in less), while a full
    /// bar would show the greedy mean of up to 200 ms before the last episode. Those two
    /// frames are drawn past the terminal's rate limit (20 a second, which the bar's moves
    /// use up): dropped, the last frame before the bar clears could show an episode count
    /// short of the total.
    pub fn redraw(&mut self) {
        self.bar.inc(std::mem::take(&mut self.unshown));
        let phase = self.phase();
        let prefix = self.prefix(phase);
        let full = self.bar.length() == Some(self.bar.position());
        let changed =
            self.last_draw.is_none_or(|(_, drawn, was_full)| (drawn, was_full) != (prefix, full));
        let stale =
            self.last_draw.is_none_or(|(last, ..)| last.elapsed() >= Duration::from_millis(200));
        if !changed && !stale {
            return;
        }
        self.last_draw = Some((Instant::now(), prefix, full));
        self.bar.set_prefix(prefix);
        let lengths = uav1_lengths(phase, &self.collector);
        let ticks_per_s =
            self.collector.ticks() as f64 / self.started.elapsed().as_secs_f64().max(1e-9);
        self.bar
            .set_message(format!("{lengths}  {ticks_per_s:.0} ticks/s  {} live agents", self.live));
        if changed {
            self.bar.force_draw();
        }
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

/// What the progress says of UAV1's lengths: the mean of its recent training ones, or in the
/// final evaluation its greedy mean so far and how many hit the tick cap (a periodic block
/// shows the training ones). `-` until it has finished an episode: a mean of none is no
/// number (it showed `-0.0`, the sum of no lengths).
fn uav1_lengths(phase: Phase, collector: &Collector) -> String {
    if let (Phase::Eval, Some(greedy)) = (phase, collector.greedy(0)) {
        return format!("greedy mean length {:.1}, {} truncated", greedy.mean(), greedy.truncated);
    }
    let trials = collector.train_lengths().first().map_or(&[][..], Vec::as_slice);
    // Divided among the trials there are (the closure runs for one, if any).
    let recent: Vec<u32> = trials.iter().flat_map(|t| t.last(RECENT / trials.len())).collect();
    if recent.is_empty() {
        return "mean length -".to_string();
    }
    let mean = recent.iter().map(|&l| f64::from(l)).sum::<f64>() / recent.len() as f64;
    format!("mean length {mean:.1}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::results::scratch_collector;

    fn report(phase: Phase, episode: u64, length: u32, truncated: bool) -> EpisodeReport {
        let mut report = EpisodeReport { phase: phase as u8, episode, ..Default::default() };
        report.members = 1;
        report.lengths[0] = length;
        report.truncated = u64::from(truncated);
        report
    }

    /// Before UAV1 has finished an episode its mean length is `-`, in training and in an
    /// evaluation alike.
    #[test]
    fn no_mean_length_is_shown_before_uav1_finished_an_episode() {
        let (_dir, mut collector) = scratch_collector(2);
        for phase in [Phase::Train, Phase::Eval] {
            assert_eq!(uav1_lengths(phase, &collector), "mean length -", "{phase:?}");
        }
        collector.record(&report(Phase::Train, 0, 20, false)).unwrap();
        assert_eq!(uav1_lengths(Phase::Train, &collector), "mean length 20.0");
    }

    /// A recorder of one agent and two trials starting in `first`, redrawn once before any
    /// record: it says `starting`. The directory holds its CSV files.
    fn two_trial_recorder(total: u64, first: Phase) -> (tempfile::TempDir, Recorder) {
        let (dir, collector) = scratch_collector(2);
        let mut recorder = Recorder::new(collector, total, first, true);
        recorder.redraw();
        assert_eq!(recorder.bar.prefix(), "starting");
        (dir, recorder)
    }

    /// The bar says "greedy" once every trial evaluates, at the redraw that sees it, even
    /// within 200 ms of the last one.
    #[test]
    fn the_progress_counts_greedy_episodes_and_names_the_phase_at_once() {
        let (_dir, mut recorder) = two_trial_recorder(6, Phase::Train);
        let mut record = |trial: u32, phase, episode, length, truncated| {
            let report = EpisodeReport { trial, ..report(phase, episode, length, truncated) };
            recorder.record(&report).unwrap();
            recorder.redraw();
            (recorder.bar.position(), recorder.bar.prefix(), recorder.bar.message())
        };
        record(0, Phase::Train, 0, 20, false);
        let (position, prefix, message) = record(1, Phase::Train, 0, 20, false);
        assert_eq!((position, prefix.as_str()), (2, "training"));
        assert!(message.starts_with("mean length 20.0 "), "{message}");

        // Trial 1 still trains: so does the run.
        record(0, Phase::Train, 1, 20, false);
        let (position, prefix, _) = record(0, Phase::Eval, 0, 10, false);
        assert_eq!((position, prefix.as_str()), (4, "training"));
        record(1, Phase::Train, 1, 20, false);
        let (position, prefix, message) = record(1, Phase::Eval, 0, 1000, true);
        assert_eq!((position, prefix.as_str()), (6, "greedy"));
        assert!(message.starts_with("greedy mean length 505.0, 1 truncated "), "{message}");
    }

    /// The record that fills the bar is drawn at once, however soon after the last redraw
    /// and however many draws the terminal's rate limit let through before: the last frame
    /// before the bar clears has the full count and the final greedy mean, not those of up
    /// to 200 ms before.
    #[test]
    fn the_record_that_fills_the_bar_is_drawn_at_once() {
        let (_dir, collector) = scratch_collector(2);
        let (mut recorder, terminal) = Recorder::on_test_terminal(collector, 3, Phase::Eval);
        // Spends the burst.
        for _ in 0..100 {
            recorder.bar.tick();
        }
        for (trial, episode, length) in [(0, 0, 10), (1, 0, 20), (0, 1, 60)] {
            let report = EpisodeReport { trial, ..report(Phase::Eval, episode, length, false) };
            recorder.record(&report).unwrap();
            recorder.redraw();
        }
        // The mean of the trials' means: (10 + 60) / 2 and 20.
        let screen = terminal.contents();
        assert!(
            screen.contains("greedy   [==============================] 3/3 episodes  greedy mean length 27.5, 0 truncated "),
            "the frame of the full bar was not drawn; the terminal shows:\n{screen}"
        );
    }

    /// A run that only evaluates (`supervisor eval`) is greedy from its first record on,
    /// before every trial has one.
    #[test]
    fn an_evaluation_is_greedy_from_its_first_record() {
        let (_dir, mut recorder) = two_trial_recorder(4, Phase::Eval);
        recorder.record(&report(Phase::Eval, 0, 10, false)).unwrap();
        recorder.redraw();
        assert_eq!((recorder.bar.position(), recorder.bar.prefix()), (1, "greedy".into()));
    }
}
