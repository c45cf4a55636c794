//! Learning curves: episode length against iterations (episodes), mean over trials,
//! smoothed by a trailing moving average, as the thesis plots them (Fig. 10, Fig. 11).

use crate::results::Flown;
use anyhow::{Context, Result};
use std::fmt::Write as _;
use std::io::{BufRead as _, Read as _};
use std::path::Path;

/// One agent's curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    /// 1-based agent number.
    pub agent: usize,
    /// The trials' episode numbers the curve has a point for: those every trial has a length
    /// of this agent for. An agent that attached starts late; the episodes some trial lacks
    /// (an agent restarted after a failure was down in them) are left out.
    pub episodes: Vec<u64>,
    /// Mean over trials of the length of each of `episodes`.
    pub mean: Vec<f64>,
    /// Trailing moving average of `mean` over `window` points.
    pub smoothed: Vec<f64>,
}

/// The smoothing window of a run that trained `trained` episodes: `explicit` (`--smoothing`)
/// if given, else a hundredth of them. A run stopped early is smoothed by what it trained,
/// not by what it planned: 1 000 episodes of a planned 50 000 smoothed over 500 would show
/// little more than their running mean.
pub fn window(explicit: Option<usize>, trained: u64) -> usize {
    explicit.unwrap_or((trained / 100).max(1) as usize)
}

/// Curves of every agent from `lengths[agent][trial]`.
pub fn curves(lengths: &[Vec<Flown>], window: usize) -> Vec<Curve> {
    lengths
        .iter()
        .enumerate()
        .map(|(slot, trials)| {
            let from = trials.iter().map(|t| t.span().start).max().unwrap_or(0);
            let to = trials.iter().map(|t| t.span().end).min().unwrap_or(0);
            let (episodes, mean): (Vec<u64>, Vec<f64>) = (from..to)
                .filter_map(|e| {
                    let sum: f64 =
                        trials.iter().map(|t| t.get(e).map(f64::from)).sum::<Option<_>>()?;
                    Some((e, sum / trials.len() as f64))
                })
                .unzip();
            Curve {
                agent: slot + 1,
                smoothed: moving_average(&mean, window.max(1)),
                episodes,
                mean,
            }
        })
        .collect()
}

/// Trailing moving average: entry i is the mean of entries max(0, i+1-window)..=i.
pub fn moving_average(values: &[f64], window: usize) -> Vec<f64> {
    let mut sum = 0.0;
    values
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            sum += v;
            if i >= window {
                sum -= values[i - window];
            }
            sum / (i + 1).min(window) as f64
        })
        .collect()
}

/// The first line of a `curve.csv`.
const CURVE_HEADER: &str = "episode,agent,mean_length,smoothed_length";

/// Writes `curve.csv`: `CURVE_HEADER`, then one row per agent and episode.
pub fn write_csv(path: &Path, curves: &[Curve]) -> Result<()> {
    let mut text = format!("{CURVE_HEADER}\n");
    for curve in curves {
        for ((e, mean), smooth) in curve.episodes.iter().zip(&curve.mean).zip(&curve.smoothed) {
            writeln!(text, "{e},{},{mean:.4},{smooth:.4}", curve.agent)
                .expect("writing to a String");
        }
    }
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `greedy_curve.csv`: `train_episodes,agent,greedy_mean_length,truncated`, one row
/// per periodic greedy evaluation (`greedy[agent]`).
pub fn write_greedy_csv(path: &Path, greedy: &[Vec<(u64, f64, u64)>]) -> Result<()> {
    let mut text = String::from("train_episodes,agent,greedy_mean_length,truncated\n");
    for (agent, points) in greedy.iter().enumerate() {
        for (episodes, mean, truncated) in points {
            writeln!(text, "{episodes},{},{mean:.4},{truncated}", agent + 1)
                .expect("writing to a String");
        }
    }
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Longest line a `curve.csv` may have; `write_csv` writes rows of under 60 bytes. A curve
/// is read a line at a time, so its length has no bound (one of 64 UAVs and 50 000 episodes
/// takes 80 MB), while a file without line ends, such as a mistaken `/dev/zero`, is
/// refused at its first line.
const MAX_CURVE_LINE: u64 = 256;

/// Reads agent `agent`'s smoothed curve back from a `curve.csv`: (episode, smoothed length)
/// points. Every field of every row is checked, also those not drawn: a file that is not
/// what `write_csv` writes is refused at its first bad field, named with file and line.
pub fn read_smoothed(path: &Path, agent: usize) -> Result<Vec<(u64, f64)>> {
    let file =
        std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut lines =
        Lines { reader: std::io::BufReader::new(file), path, number: 0, line: String::new() };
    let header = lines.next_line()?.map_or("", |(_, header)| header);
    anyhow::ensure!(
        header == CURVE_HEADER,
        "{}:1: not a curve.csv: expected the header `{CURVE_HEADER}`, found `{header}`",
        path.display()
    );
    let mut points = Vec::new();
    while let Some((number, line)) = lines.next_line()? {
        let row = Row { path, line: number, fields: line.split(',').collect() };
        anyhow::ensure!(
            row.fields.len() == 4,
            "{}:{}: {} fields, expected 4: {CURVE_HEADER}",
            path.display(),
            row.line,
            row.fields.len()
        );
        let episode: u64 = row.parse(0, "an episode number")?;
        let row_agent: usize = row.parse(1, "an agent number")?;
        row.length(2)?;
        let smoothed = row.length(3)?;
        if row_agent == agent {
            points.push((episode, smoothed));
        }
    }
    anyhow::ensure!(!points.is_empty(), "{}: no rows for agent {agent}", path.display());
    Ok(points)
}

/// The lines of a `curve.csv` being read, each at most [`MAX_CURVE_LINE`] bytes.
struct Lines<'a> {
    reader: std::io::BufReader<std::fs::File>,
    path: &'a Path,
    /// The number of the line last read, from 1.
    number: usize,
    line: String,
}

impl Lines<'_> {
    /// The next line's number and text without its line end; `None` at the end of the file.
    fn next_line(&mut self) -> Result<Option<(usize, &str)>> {
        self.line.clear();
        self.number += 1;
        let (path, number) = (self.path.display(), self.number);
        let read = (&mut self.reader)
            .take(MAX_CURVE_LINE + 1)
            .read_line(&mut self.line)
            .with_context(|| format!("cannot read {path}:{number}"))?;
        anyhow::ensure!(
            read as u64 <= MAX_CURVE_LINE || self.line.ends_with('\n'),
            "{path}:{number}: a line longer than {MAX_CURVE_LINE} bytes, not a curve.csv"
        );
        Ok((read > 0).then(|| (self.number, self.line.trim_end())))
    }
}

/// One data row of a `curve.csv` being read, for errors that name its place and field.
struct Row<'a> {
    path: &'a Path,
    line: usize,
    fields: Vec<&'a str>,
}

impl Row<'_> {
    /// Field `k` as a `T`, which it must be (`what` says what that is).
    fn parse<T: std::str::FromStr>(&self, k: usize, what: &str) -> Result<T> {
        self.fields[k].parse().map_err(|_| self.not(k, what))
    }

    /// Field `k` as an episode length. `inf`, `NaN` and `1e400` parse as numbers, but are no
    /// episode length to plot.
    fn length(&self, k: usize) -> Result<f64> {
        const WHAT: &str = "an episode length (a finite number >= 0)";
        let length: f64 = self.parse(k, WHAT)?;
        anyhow::ensure!(length.is_finite() && length >= 0.0, self.not(k, WHAT));
        Ok(length)
    }

    /// The error of field `k`, which is not `what` it should be.
    fn not(&self, k: usize, what: &str) -> anyhow::Error {
        let name = CURVE_HEADER.split(',').nth(k).unwrap_or_default();
        anyhow::anyhow!(
            "{}:{}: {name} `{}` is not {what}",
            self.path.display(),
            self.line,
            self.fields[k]
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_average_is_trailing_and_starts_with_partial_windows() {
        assert_eq!(moving_average(&[2.0, 4.0, 6.0, 8.0], 2), vec![2.0, 3.0, 5.0, 7.0]);
        assert_eq!(moving_average(&[1.0, 2.0, 3.0], 1), vec![1.0, 2.0, 3.0]);
    }

    /// An agent's lengths in one trial: `runs` of (first episode, lengths).
    fn flown(runs: &[(u64, &[u32])]) -> Flown {
        let mut flown = Flown::default();
        for &(first, lengths) in runs {
            for (e, &length) in (first..).zip(lengths) {
                flown.push(e, length);
            }
        }
        flown
    }

    #[test]
    fn a_written_curve_reads_back_and_other_files_are_refused_with_their_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("curve.csv");
        let c = curves(&[vec![flown(&[(0, &[4, 2])])], vec![flown(&[(5, &[9, 7])])]], 2);
        write_csv(&path, &c).unwrap();
        assert_eq!(read_smoothed(&path, 2).unwrap(), vec![(5, 9.0), (6, 8.0)]);
        let refused = |text: &str| {
            std::fs::write(&path, text).unwrap();
            read_smoothed(&path, 1).unwrap_err().to_string()
        };
        let e = refused("a hostname\n");
        assert!(e.ends_with("curve.csv:1: not a curve.csv: expected the header `episode,agent,mean_length,smoothed_length`, found `a hostname`"), "{e}");
        for (bad_row, expected) in [
            ("1,one,2,3", "agent `one` is not an agent number"),
            ("one,1,2,3", "episode `one` is not an episode number"),
            ("1,1,2", "3 fields, expected 4: episode,agent,mean_length,smoothed_length"),
            ("1,1,2,3,4", "5 fields, expected 4"),
        ] {
            let e = refused(&format!("{CURVE_HEADER}\n0,1,4,4\n{bad_row}\n"));
            assert!(e.contains(&format!("curve.csv:3: {expected}")), "{e}");
        }
        for bad in ["inf", "NaN", "1e400", "-1", "abc", ""] {
            for (row, field) in [
                (format!("1,1,4,{bad}"), "smoothed_length"),
                (format!("1,1,{bad},4"), "mean_length"),
            ] {
                let e = refused(&format!("{CURVE_HEADER}\n0,1,4,4\n{row}\n"));
                let expected = format!("curve.csv:3: {field} `{bad}` is not an episode length");
                assert!(e.contains(&expected), "{e}");
            }
        }
        let e = refused(&format!("{CURVE_HEADER}\n0,2,4,4\n"));
        assert!(e.ends_with("curve.csv: no rows for agent 1"), "{e}");
        let e = refused(&format!("{CURVE_HEADER}\n0,1,4,4\n{}", "9".repeat(1000)));
        assert!(e.ends_with("curve.csv:3: a line longer than 256 bytes, not a curve.csv"), "{e}");
        let e = refused("");
        assert!(e.ends_with("curve.csv:1: not a curve.csv: expected the header `episode,agent,mean_length,smoothed_length`, found ``"), "{e}");
    }

    /// A curve is read a line at a time, whatever its length. Before, it was read whole up
    /// to the 16 MiB bound of input files, and `reproduce` refused the curve of its own run
    /// past about 680 000 rows, after the run.
    #[test]
    fn a_curve_larger_than_the_input_file_bound_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("curve.csv");
        let lengths: Vec<u32> = (0..400_000).map(|e| 100 - (e % 90)).collect();
        let trial = || vec![flown(&[(0, lengths.as_slice())])];
        write_csv(&path, &curves(&[trial(), trial()], 1)).unwrap();
        let size = std::fs::metadata(&path).unwrap().len();
        assert!(size > flockstep_world::map::MAX_INPUT_BYTES, "only {size} bytes");
        let points = read_smoothed(&path, 2).unwrap();
        assert_eq!(points.len(), lengths.len());
        assert_eq!(points.last(), Some(&(399_999, 61.0)));
    }

    #[test]
    fn curves_average_over_trials_up_to_the_shortest_trial() {
        let lengths = vec![vec![flown(&[(0, &[10, 20, 30])]), flown(&[(0, &[30, 40])])]];
        let c = curves(&lengths, 1);
        assert_eq!(c[0].agent, 1);
        assert_eq!(c[0].episodes, vec![0, 1]);
        assert_eq!(c[0].mean, vec![20.0, 30.0]);
    }

    /// An agent that attached flies from a later episode in each trial (trials reach their
    /// episode boundaries at different rounds); one restarted misses the episodes it was down.
    /// Its curve is placed at the trials' episode numbers, from the first episode every trial
    /// has for it, and leaves out the episodes a trial lacks.
    #[test]
    fn a_late_or_interrupted_agent_is_placed_at_the_trials_episode_numbers() {
        let attached = vec![flown(&[(3, &[8, 6, 4, 2])]), flown(&[(4, &[10, 6, 2])])];
        let c = &curves(&[attached], 2)[0];
        assert_eq!((c.episodes.clone(), c.mean.clone()), (vec![4, 5, 6], vec![8.0, 5.0, 2.0]));
        assert_eq!(c.smoothed, vec![8.0, 6.5, 3.5]);
        let restarted =
            vec![flown(&[(0, &[9, 9]), (4, &[5, 5])]), flown(&[(0, &[7, 7, 7, 7, 3, 3])])];
        let c = &curves(&[restarted], 1)[0];
        assert_eq!(
            (c.episodes.clone(), c.mean.clone()),
            (vec![0, 1, 4, 5], vec![8.0, 8.0, 4.0, 4.0])
        );
    }
}
