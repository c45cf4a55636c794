//! Collects the world's episode reports into the results directory and the run's statistics.
//!
//! Training episodes stream into `episodes.csv` (trial, agent, episode, start_tick, length,
//! truncated) as they arrive, greedy-evaluation episodes into `greedy_episodes.csv`; lengths
//! are also kept in memory for the learning curve and the summary. Agents are numbered from
//! 1 (UAV1), trials and episodes from 0.

use anyhow::{Context, Result};
use flockstep_proto::{slots_in, EpisodeReport, Phase};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

const CSV_HEADER: &str = "trial,agent,episode,start_tick,length,truncated\n";

/// Everything a run writes into its results directory, and `eval/`, where `eval` writes by
/// default. `--overwrite` removes these (and nothing else) before the new run starts.
pub const RUN_OUTPUTS: [&str; 11] = [
    "summary.json",
    "episodes.csv",
    "greedy_episodes.csv",
    "curve.csv",
    "greedy_curve.csv",
    "curve.svg",
    "scenario.map",
    "tree.bt",
    "qtables",
    "logs",
    "eval",
];

/// The file that shows `dir` holds an earlier run's results, if it does: every run writes
/// `episodes.csv` at its start and `summary.json` at its end, even when stopped or failed.
pub fn earlier_results(dir: &Path) -> Option<&'static str> {
    ["summary.json", "episodes.csv"].into_iter().find(|file| dir.join(file).exists())
}

/// What `--overwrite` removes from `dir`: its [`RUN_OUTPUTS`], each whole (a directory with
/// whatever else was put in it).
fn removed_by_overwrite(dir: &Path) -> impl Iterator<Item = PathBuf> + '_ {
    RUN_OUTPUTS.into_iter().map(|name| dir.join(name))
}

/// The entry of `dir` that [`remove_earlier_results`] removes and that is or holds `path`,
/// if any, compared as canonical paths (links followed; a path that does not exist is in
/// none): a `--resume` directory there would be gone before the run reads its snapshots.
pub fn removed_entry_holding(dir: &Path, path: &Path) -> Option<PathBuf> {
    let path = path.canonicalize().ok()?;
    removed_by_overwrite(dir)
        .find(|entry| entry.canonicalize().is_ok_and(|entry| path.starts_with(entry)))
}

/// Removes what an earlier run wrote into `dir` ([`RUN_OUTPUTS`]).
pub fn remove_earlier_results(dir: &Path) -> Result<()> {
    for path in removed_by_overwrite(dir) {
        let removed = match std::fs::symlink_metadata(&path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(e) => Err(e),
            Ok(meta) if meta.is_dir() => std::fs::remove_dir_all(&path),
            Ok(_) => std::fs::remove_file(&path),
        };
        removed.with_context(|| format!("--overwrite: cannot remove {}", path.display()))?;
    }
    Ok(())
}

/// Greedy-evaluation results of one agent after training.
#[derive(Debug, Clone, PartialEq)]
pub struct GreedyStats {
    /// Greedy episodes over every trial.
    pub episodes: u64,
    pub truncated: u64,
    /// The mean over trials ([`OverTrials`]).
    mean: f64,
}

/// Greedy totals of one agent in one trial, or in one trial's periodic block: (episodes,
/// total length, truncated).
type Totals = (u64, u64, u64);

/// The mean length of one trial's greedy `totals`; None without episodes.
fn trial_mean((episodes, total, _): Totals) -> Option<f64> {
    (episodes > 0).then(|| total as f64 / episodes as f64)
}

/// A greedy mean over trials: the mean of each trial's mean length, as `curve.csv`'s "mean
/// over trials", so that every trial weighs the same whatever its count of episodes (an
/// agent restarted during an evaluation misses some); a trial without episodes is left out.
/// The one definition of the greedy lengths of `summary.json` and `greedy_curve.csv`.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct OverTrials {
    sum_of_means: f64,
    trials: u32,
    truncated: u64,
}

impl OverTrials {
    /// Adds one trial's totals.
    fn add(&mut self, totals: Totals) {
        if let Some(mean) = trial_mean(totals) {
            self.sum_of_means += mean;
            self.trials += 1;
        }
        self.truncated += totals.2;
    }

    /// None until a trial has episodes.
    fn mean(&self) -> Option<f64> {
        (self.trials > 0).then(|| self.sum_of_means / f64::from(self.trials))
    }
}

/// Periodic greedy evaluations a trial may have (`--eval-every`): the collector keeps a mean
/// over trials per agent and evaluation from the start (24 bytes each, 2.4 MB per agent at
/// this cap), and each is a row of `greedy_curve.csv` and a point of the plot.
pub const MAX_EVAL_BLOCKS: u64 = 100_000;

/// Where greedy-evaluation episodes belong: periodic blocks during training, then the final
/// evaluation. Evaluation episodes are numbered through all blocks of a trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EvalPlan {
    /// Periodic blocks per trial (after every `every` training episodes, before the last).
    pub blocks: u64,
    pub block: u64,
    pub every: u64,
}

impl EvalPlan {
    pub fn new(train_episodes: u64, every: u64, block: u64) -> EvalPlan {
        let blocks =
            if every > 0 && block > 0 { train_episodes.saturating_sub(1) / every } else { 0 };
        EvalPlan { blocks, block, every }
    }

    /// Greedy episodes a trial plays: every periodic block, then `final_episodes`; None past
    /// `u64`.
    pub fn greedy_episodes(&self, final_episodes: u64) -> Option<u64> {
        self.blocks.checked_mul(self.block)?.checked_add(final_episodes)
    }

    /// The periodic block of evaluation episode `index`, or None for the final evaluation.
    fn block_of(&self, index: u64) -> Option<usize> {
        // Saturating: past `u64`, every episode number is in a periodic block (a run's
        // settings are checked to stay below, see `RunConfig::resolve`).
        let periodic = self.blocks.saturating_mul(self.block);
        (index < periodic).then(|| (index / self.block) as usize)
    }
}

/// Writes one CSV line of whole numbers. The supervisor writes a line per agent and
/// episode while the run goes on, on the same two cores as the barrier, so the numbers are
/// formatted by `itoa` rather than through `fmt`.
fn write_csv_line(csv: &mut impl Write, fields: [u64; 6]) -> std::io::Result<()> {
    let mut digits = itoa::Buffer::new();
    for (i, field) in fields.into_iter().enumerate() {
        if i > 0 {
            csv.write_all(b",")?;
        }
        csv.write_all(digits.format(field).as_bytes())?;
    }
    csv.write_all(b"\n")
}

/// A CSV file the run streams into, with its path for the errors.
#[derive(Debug)]
struct Csv {
    path: PathBuf,
    file: BufWriter<File>,
}

impl Csv {
    /// Creates `dir/name` holding the header line.
    fn create(dir: &Path, name: &str) -> Result<Csv> {
        let path = dir.join(name);
        let file =
            File::create(&path).with_context(|| format!("cannot write {}", path.display()))?;
        let mut csv = Csv { path, file: BufWriter::new(file) };
        csv.file.write_all(CSV_HEADER.as_bytes()).with_context(|| csv.cannot_write())?;
        Ok(csv)
    }

    fn line(&mut self, fields: [u64; 6]) -> Result<()> {
        write_csv_line(&mut self.file, fields).with_context(|| self.cannot_write())
    }

    fn flush(&mut self) -> Result<()> {
        self.file.flush().with_context(|| self.cannot_write())
    }

    fn cannot_write(&self) -> String {
        format!("cannot write {}", self.path.display())
    }
}

/// One agent's training episode lengths in one trial, by the trial's episode numbers: an
/// agent that attached flies from a later episode on, one that was restarted misses the
/// episodes it was down. Kept as runs of consecutive episodes, 4 bytes an episode.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Flown {
    /// (first episode, lengths of it and the episodes after it), in episode order.
    runs: Vec<(u64, Vec<u32>)>,
}

impl Flown {
    /// Adds episode `episode`, which comes after every episode added before.
    pub fn push(&mut self, episode: u64, length: u32) {
        match self.runs.last_mut() {
            Some((first, lengths)) if *first + lengths.len() as u64 == episode => {
                lengths.push(length)
            }
            _ => self.runs.push((episode, vec![length])),
        }
    }

    /// The length of episode `episode`, if the agent flew it.
    pub fn get(&self, episode: u64) -> Option<u32> {
        let run = self.runs.partition_point(|(first, _)| *first <= episode).checked_sub(1)?;
        let (first, lengths) = &self.runs[run];
        lengths.get(usize::try_from(episode - first).ok()?).copied()
    }

    /// The episodes from the first flown to the last flown (empty if none).
    pub fn span(&self) -> std::ops::Range<u64> {
        match (self.runs.first(), self.runs.last()) {
            (Some((first, _)), Some((last, lengths))) => *first..last + lengths.len() as u64,
            _ => 0..0,
        }
    }

    /// The lengths of the last `n` episodes flown (fewer if it flew fewer), oldest first.
    pub fn last(&self, n: usize) -> Vec<u32> {
        let mut tail: Vec<u32> = self
            .runs
            .iter()
            .rev()
            .flat_map(|(_, lengths)| lengths.iter().rev().copied())
            .take(n)
            .collect();
        tail.reverse();
        tail
    }

    /// Episodes flown.
    pub fn len(&self) -> usize {
        self.runs.iter().map(|(_, lengths)| lengths.len()).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.runs.is_empty()
    }
}

/// Everything the run recorded.
#[derive(Debug)]
pub struct Collector {
    episodes_csv: Csv,
    greedy_csv: Csv,
    /// Training lengths: `train[agent][trial]`.
    train: Vec<Vec<Flown>>,
    train_truncated: Vec<u64>,
    /// Final greedy totals per agent and trial.
    greedy: Vec<Vec<Totals>>,
    /// Greedy episodes per agent and trial, periodic and final.
    greedy_flown: Vec<Vec<u64>>,
    plan: EvalPlan,
    /// Periodic greedy evaluations per agent and block, over the trials whose block is
    /// closed. A trial's blocks come in order, so only its latest is open, in `open_block`.
    periodic: Vec<Vec<OverTrials>>,
    /// Per agent and trial: the latest periodic block it was evaluated in, and its totals
    /// there; added to `periodic` when the trial's next block begins (read with it before).
    open_block: Vec<Vec<(usize, Totals)>>,
    /// Ticks of every trial, counting training and evaluation.
    ticks: Vec<u64>,
    /// The episode whose report comes next, per trial and phase (training, evaluation): the
    /// world numbers each phase's episodes of a trial from 0 and reports every one in
    /// order, so any other number means records were lost on the way.
    next_episode: Vec<[u64; 2]>,
}

impl Collector {
    pub fn create(dir: &Path, agents: usize, trials: usize, plan: EvalPlan) -> Result<Collector> {
        let mut collector = Collector {
            episodes_csv: Csv::create(dir, "episodes.csv")?,
            greedy_csv: Csv::create(dir, "greedy_episodes.csv")?,
            train: Vec::new(),
            train_truncated: Vec::new(),
            greedy: Vec::new(),
            greedy_flown: Vec::new(),
            plan,
            periodic: Vec::new(),
            open_block: Vec::new(),
            ticks: vec![0; trials],
            next_episode: vec![[0; 2]; trials],
        };
        collector.grow(agents);
        Ok(collector)
    }

    /// Records one finished episode of one trial.
    pub fn record(&mut self, report: &EpisodeReport) -> Result<()> {
        let trial = report.trial as usize;
        if trial >= self.trials() {
            anyhow::bail!(
                "episode report for trial {trial}, but the run has {} trials",
                self.trials()
            );
        }
        let phase = Phase::from_u8(report.phase)
            .with_context(|| format!("episode report with phase {}", report.phase))?;
        let next = &mut self.next_episode[trial][phase as usize];
        if report.episode != *next {
            anyhow::bail!(
                "episode records lost or out of order: trial {trial} reported {phase:?} episode \
                 {} where episode {next} was due",
                report.episode
            );
        }
        let mut end = report.start_tick;
        for slot in slots_in(report.members) {
            let length = report.lengths[slot];
            // The world's numbers: bad ones are an error, never an overflow.
            end = end.max(report.start_tick.checked_add(length.into()).with_context(|| {
                format!(
                    "episode report for trial {trial}: start tick {} plus length {length} is \
                     past the largest tick",
                    report.start_tick
                )
            })?);
        }
        *next += 1;
        self.ticks[trial] = self.ticks[trial].max(end);
        for slot in slots_in(report.members) {
            if slot >= self.train.len() {
                self.grow(slot + 1);
            }
            let length = report.lengths[slot];
            let truncated = report.truncated >> slot & 1;
            let csv = match phase {
                Phase::Train => &mut self.episodes_csv,
                Phase::Eval => &mut self.greedy_csv,
            };
            csv.line([
                report.trial.into(),
                slot as u64 + 1,
                report.episode,
                report.start_tick,
                length.into(),
                truncated,
            ])?;
            match phase {
                Phase::Train => {
                    self.train[slot][trial].push(report.episode, length);
                    self.train_truncated[slot] += truncated;
                }
                Phase::Eval => {
                    self.greedy_flown[slot][trial] += 1;
                    let entry = match self.plan.block_of(report.episode) {
                        Some(block) => {
                            let (open, totals) = &mut self.open_block[slot][trial];
                            if *open != block {
                                self.periodic[slot][*open].add(*totals);
                                (*open, *totals) = (block, (0, 0, 0));
                            }
                            totals
                        }
                        None => &mut self.greedy[slot][trial],
                    };
                    entry.0 += 1;
                    entry.1 += u64::from(length);
                    entry.2 += truncated;
                }
            }
        }
        Ok(())
    }

    /// Makes room for `agents` agents: those the run starts with, and any that join later.
    fn grow(&mut self, agents: usize) {
        let trials = self.trials();
        self.train.resize(agents, vec![Flown::default(); trials]);
        self.train_truncated.resize(agents, 0);
        self.greedy.resize(agents, vec![(0, 0, 0); trials]);
        self.greedy_flown.resize(agents, vec![0; trials]);
        self.periodic.resize(agents, vec![OverTrials::default(); self.plan.blocks as usize]);
        self.open_block.resize(agents, vec![(0, (0, 0, 0)); trials]);
    }

    pub fn flush(&mut self) -> Result<()> {
        self.episodes_csv.flush()?;
        self.greedy_csv.flush()
    }

    /// How many training episodes the run went through: the last one any agent flew, plus
    /// one.
    pub fn trained_episodes(&self) -> u64 {
        self.train.iter().flatten().map(|flown| flown.span().end).max().unwrap_or(0)
    }

    /// Where the run's greedy episodes belong.
    pub fn plan(&self) -> EvalPlan {
        self.plan
    }

    /// How many greedy episodes `agent` flew in `trial`: periodic and final.
    pub fn greedy_flown(&self, agent: usize, trial: usize) -> u64 {
        self.greedy_flown.get(agent).and_then(|trials| trials.get(trial)).copied().unwrap_or(0)
    }

    /// `train[agent][trial]`: the training lengths of each agent in each trial.
    pub fn train_lengths(&self) -> &[Vec<Flown>] {
        &self.train
    }

    pub fn train_truncated(&self, agent: usize) -> u64 {
        self.train_truncated.get(agent).copied().unwrap_or(0)
    }

    /// The mean over trials of each trial's mean of `agent`'s last training episodes, and
    /// how many episodes that is per trial: `window`, or fewer if a trial has fewer (the
    /// same number in every trial, so that no trial weighs more than another). Trials the
    /// agent flew no episode of (a run stopped at once) are left out.
    pub fn final_mean(&self, agent: usize, window: usize) -> Option<(f64, usize)> {
        let flown: Vec<&Flown> = self.train.get(agent)?.iter().filter(|t| !t.is_empty()).collect();
        let window = flown.iter().map(|t| t.len()).min()?.min(window);
        let trial_mean =
            |t: &&Flown| t.last(window).iter().map(|&l| f64::from(l)).sum::<f64>() / window as f64;
        let mean = flown.iter().map(trial_mean).sum::<f64>() / flown.len() as f64;
        Some((mean, window))
    }

    /// The periodic greedy evaluations of `agent`: (training episodes behind the policy,
    /// greedy mean length over trials ([`OverTrials`]), truncated episodes in all trials),
    /// for blocks run.
    pub fn greedy_curve(&self, agent: usize) -> Vec<(u64, f64, u64)> {
        let (Some(blocks), Some(open)) = (self.periodic.get(agent), self.open_block.get(agent))
        else {
            return Vec::new();
        };
        let mut blocks = blocks.clone();
        for &(block, totals) in open {
            // A run without periodic blocks has none to add to.
            if let Some(over) = blocks.get_mut(block) {
                over.add(totals);
            }
        }
        let after = |block: usize| (block as u64 + 1) * self.plan.every;
        blocks
            .iter()
            .enumerate()
            .filter_map(|(b, over)| Some((after(b), over.mean()?, over.truncated)))
            .collect()
    }

    /// Greedy results of `agent` after training (None if it was never evaluated).
    pub fn greedy(&self, agent: usize) -> Option<GreedyStats> {
        let trials = self.greedy.get(agent)?;
        let mut over = OverTrials::default();
        for &totals in trials {
            over.add(totals);
        }
        Some(GreedyStats {
            episodes: trials.iter().map(|t| t.0).sum(),
            truncated: over.truncated,
            mean: over.mean()?,
        })
    }

    /// `agent`'s mean greedy length after training in each trial, by trial: None for a trial
    /// it has no greedy episode of (one the run was stopped in before its evaluation), also
    /// when no trial has any.
    pub fn greedy_per_trial(&self, agent: usize) -> Vec<Option<f64>> {
        let trials = self.greedy.get(agent).map_or(&[][..], Vec::as_slice);
        trials.iter().copied().map(trial_mean).collect()
    }

    /// Barrier rounds: every round advances each trial that is not done by one tick, and
    /// all trials start together, so the rounds are the longest trial's ticks.
    pub fn rounds(&self) -> u64 {
        self.ticks.iter().copied().max().unwrap_or(0)
    }

    /// Ticks run in all trials together.
    pub fn ticks(&self) -> u64 {
        self.ticks.iter().sum()
    }

    pub fn agents(&self) -> usize {
        self.train.len()
    }

    /// The run's trial count: each trial has its entry in `ticks`.
    pub fn trials(&self) -> usize {
        self.ticks.len()
    }
}

impl GreedyStats {
    /// Mean over trials of each trial's mean greedy length ([`OverTrials`]).
    pub fn mean(&self) -> f64 {
        self.mean
    }
}

/// A collector of one agent and `trials` trials for a test, and the scratch directory that
/// holds its CSV files (removed when dropped).
#[cfg(test)]
pub(crate) fn scratch_collector(trials: usize) -> (tempfile::TempDir, Collector) {
    let dir = tempfile::tempdir().expect("a scratch directory");
    let collector = Collector::create(dir.path(), 1, trials, EvalPlan::default()).unwrap();
    (dir, collector)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(trial: u32, phase: Phase, episode: u64) -> EpisodeReport {
        let mut report = EpisodeReport { trial, phase: phase as u8, episode, ..Default::default() };
        report.members = 1;
        report.lengths[0] = 13;
        report
    }

    #[test]
    fn a_report_that_skips_an_episode_is_an_error_naming_both() {
        let (_dir, mut collector) = scratch_collector(2);
        for (trial, phase, episode) in
            [(0, Phase::Train, 0), (1, Phase::Train, 0), (0, Phase::Train, 1), (0, Phase::Eval, 0)]
        {
            collector.record(&report(trial, phase, episode)).expect("the next episode");
        }
        let error = collector.record(&report(1, Phase::Train, 2)).unwrap_err().to_string();
        assert!(
            error.contains("trial 1 reported Train episode 2 where episode 1 was due"),
            "{error}"
        );
        assert_eq!(
            collector.train_lengths()[0][1].last(9),
            vec![13],
            "the bad report was not recorded"
        );
    }

    /// A report of a trial the run does not have (the world sent a bad record) is an error
    /// naming the trial and the run's count, and nothing is recorded.
    #[test]
    fn a_report_of_an_unknown_trial_is_an_error_naming_the_count() {
        let (_dir, mut collector) = scratch_collector(2);
        let error = collector.record(&report(2, Phase::Train, 0)).unwrap_err().to_string();
        assert_eq!(error, "episode report for trial 2, but the run has 2 trials");
        assert_eq!(collector.ticks(), 0, "the bad report was not recorded");
    }

    #[test]
    fn an_agents_lengths_are_kept_by_episode_number_across_gaps() {
        let mut flown = Flown::default();
        assert_eq!((flown.span(), flown.len(), flown.get(0)), (0..0, 0, None));
        for (episode, length) in [(3, 30), (4, 40), (7, 70), (8, 80)] {
            flown.push(episode, length);
        }
        assert_eq!((flown.span(), flown.len()), (3..9, 4));
        let lengths: Vec<Option<u32>> = (0..10).map(|e| flown.get(e)).collect();
        let none = None;
        assert_eq!(
            lengths,
            [none, none, none, Some(30), Some(40), none, none, Some(70), Some(80), none]
        );
        assert_eq!(flown.last(3), vec![40, 70, 80]);
        assert_eq!(flown.last(9), vec![30, 40, 70, 80]);
    }

    /// `final_window` says how many episodes the final mean covers: every trial's last
    /// `window`, or fewer in every trial if one has fewer; trials with none are left out.
    #[test]
    fn the_final_mean_covers_the_same_last_episodes_of_every_trial_that_has_any() {
        let (_dir, mut collector) = scratch_collector(3);
        for (trial, lengths) in [(0, &[10, 20, 30][..]), (1, &[4, 6][..])] {
            for (episode, &length) in lengths.iter().enumerate() {
                let mut r = report(trial, Phase::Train, episode as u64);
                r.lengths[0] = length;
                collector.record(&r).unwrap();
            }
        }
        assert_eq!(collector.final_mean(0, 1000), Some(((25.0 + 5.0) / 2.0, 2)));
        assert_eq!(collector.final_mean(0, 1), Some(((30.0 + 6.0) / 2.0, 1)));
        assert_eq!(collector.final_mean(1, 1000), None, "no such agent");
    }

    /// A trial the run was stopped in before its final evaluation has no greedy episodes:
    /// its place in `greedy_episode_length_per_trial` is null, and the later trials' lengths
    /// stay at their own places (they used to move up into the empty ones).
    #[test]
    fn greedy_lengths_per_trial_keep_each_trials_place() {
        let (_dir, mut collector) = scratch_collector(4);
        for (trial, length) in [(2, 20), (3, 30)] {
            let mut r = report(trial, Phase::Eval, 0);
            r.lengths[0] = length;
            collector.record(&r).unwrap();
        }
        let greedy = collector.greedy(0).expect("greedy episodes in trials 2 and 3");
        assert_eq!(
            serde_json::json!(collector.greedy_per_trial(0)),
            serde_json::json!([null, null, 20.0, 30.0])
        );
        assert_eq!((greedy.mean(), greedy.episodes), (25.0, 2));
    }

    /// A run stopped before any trial's evaluation has a null for each trial, as one stopped
    /// before some trials' evaluation: the agent's entry was null, not one per trial.
    #[test]
    fn greedy_lengths_per_trial_are_one_per_trial_without_any_greedy_episode() {
        let (_dir, mut collector) = scratch_collector(2);
        collector.record(&report(0, Phase::Train, 0)).unwrap();
        assert_eq!(collector.greedy(0), None);
        assert_eq!(collector.greedy_per_trial(0), vec![None, None]);
    }

    /// A greedy report of `trial`'s evaluation episode `episode`: UAV2 flies it, UAV1 only
    /// if given its length and whether it was truncated (it was down otherwise).
    fn greedy_report(trial: u32, episode: u64, uav1: Option<(u32, bool)>) -> EpisodeReport {
        let mut report =
            EpisodeReport { trial, phase: Phase::Eval as u8, episode, ..Default::default() };
        report.members = 0b10;
        report.lengths[1] = 7;
        if let Some((length, truncated)) = uav1 {
            report.members |= 1;
            report.lengths[0] = length;
            report.truncated = u64::from(truncated);
        }
        report
    }

    /// An agent restarted during an evaluation has fewer of its greedy episodes in one
    /// trial: the periodic evaluations (`greedy_curve.csv`) and the final one (summary.json)
    /// are both the mean over trials of each trial's mean, whichever order the trials'
    /// blocks end in (the periodic ones pooled the episodes, weighing the fuller trial more).
    #[test]
    fn periodic_and_final_greedy_means_are_means_over_trials() {
        let dir = tempfile::tempdir().expect("a scratch directory");
        // Two blocks of two greedy episodes (0-1, 2-3), after training episodes 1 and 2;
        // then the final evaluation (4-5).
        let plan = EvalPlan::new(3, 1, 2);
        let mut collector = Collector::create(dir.path(), 2, 2, plan).unwrap();
        // Trial 1 runs behind trial 0; UAV1 is down (None) in half of trial 1's episodes.
        for (trial, episode, uav1) in [
            (0, 0, Some((10, false))),
            (0, 1, Some((10, false))),
            (0, 2, Some((20, false))),
            (1, 0, None),
            (1, 1, Some((40, false))),
            (0, 3, Some((20, false))),
            (1, 2, None),
            (1, 3, Some((60, true))),
            (0, 4, Some((30, false))),
            (1, 4, None),
            (0, 5, Some((30, false))),
            (1, 5, Some((50, false))),
        ] {
            collector.record(&greedy_report(trial, episode, uav1)).unwrap();
        }
        // Pooled: 60 / 3 = 20, 100 / 3 and 110 / 3.
        assert_eq!(collector.greedy_curve(0), vec![(1, 25.0, 0), (2, 40.0, 1)]);
        let greedy = collector.greedy(0).expect("the final evaluation");
        assert_eq!(greedy.mean(), 40.0);
        assert_eq!(collector.greedy_per_trial(0), vec![Some(30.0), Some(50.0)]);
        // Periodic and final episodes: UAV1 was down in three of trial 1's.
        assert_eq!((collector.greedy_flown(0, 0), collector.greedy_flown(0, 1)), (6, 3));
        assert_eq!((collector.greedy_flown(1, 0), collector.greedy_flown(1, 1)), (6, 6));
        assert_eq!(collector.greedy_curve(1), vec![(1, 7.0, 0), (2, 7.0, 0)]);
    }

    /// Reports come from another process: numbers past `u64` are an error, not a panic.
    #[test]
    fn a_report_whose_end_is_past_the_largest_tick_is_an_error() {
        let (_dir, mut collector) = scratch_collector(1);
        let late = EpisodeReport { start_tick: u64::MAX - 12, ..report(0, Phase::Train, 0) };
        let error = collector.record(&late).unwrap_err().to_string();
        assert!(error.contains("start tick 18446744073709551603 plus length 13"), "{error}");
        let fits = EpisodeReport { start_tick: u64::MAX - 13, ..late };
        collector.record(&fits).expect("the same episode, ending on the largest tick");
        assert_eq!(collector.rounds(), u64::MAX);
    }
}
