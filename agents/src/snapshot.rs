//! Q-table snapshots: what one agent learned in one trial, as bytes (serde + bincode).
//!
//! A snapshot holds the state keys in id order and every learning selector's table, plus
//! what it was learned on (scenario name and map, slot, communication mode, tree), which is
//! checked when it is loaded: a table learned on another tree or map is refused, not
//! misread, also when the map's `name:` line is the same.

use crate::agent::TrialAgent;
use crate::comm::CommMode;
use crate::learning::QTable;
use crate::state::StateSpace;
use flockstep_world::Scenario;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Format version; bump when the layout changes. 2: the map's canonical text.
pub const FORMAT: u32 = 2;

/// Most bytes a snapshot may decode to. bincode allocates a text field as long as the file
/// says before it reads the text, so without a bound one damaged length asks for up to
/// 2^64 bytes and the process aborts. Decoding counts 8 bytes for every number, however
/// few it takes in the file, so files up to 128 MiB read; a snapshot of the thesis's
/// scenarios takes about 40 KB.
const DECODE_LIMIT: usize = 1 << 30;

/// What an agent's tables are learned on, and what a snapshot it loads must have been
/// learned on too.
#[derive(Debug, Clone, Copy)]
pub struct Learned<'a> {
    pub scenario: &'a Scenario,
    pub comm: CommMode,
    /// The tree in canonical text form.
    pub tree: &'a str,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    pub format: u32,
    /// The scenario's name, and its map in canonical text form (as in a run's scenario.map).
    pub scenario: String,
    pub map: String,
    /// Agent slot (0-based).
    pub slot: u32,
    pub trial: u32,
    pub comm: CommMode,
    /// The tree in canonical text form.
    pub tree: String,
    /// Training episodes behind these tables.
    pub episodes: u64,
    /// State keys in id order (pose word, then communication words).
    pub states: Vec<Vec<u64>>,
    /// One table per learning selector, in pre-order.
    pub tables: Vec<QTable>,
}

/// Why a snapshot cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    #[error("not a flockstep Q-table snapshot: {0}")]
    Decode(String),
    /// A file of another build's format, or not a snapshot at all: neither has a format
    /// number this build reads where the number goes.
    #[error("not a snapshot this build reads: it starts with format number {found}, this build reads format {FORMAT}")]
    Format { found: u32 },
    #[error("snapshot was learned with {what} `{found}`, this agent uses `{expected}`")]
    Mismatch { what: &'static str, found: String, expected: String },
    /// Slots counted from 0, named as users see them: UAV1 is slot 0.
    #[error("snapshot was learned by UAV{}, this agent is UAV{}", .found + 1, .expected + 1)]
    Slot { found: u32, expected: usize },
    /// The first line where the two trees' canonical texts differ (one node a line, in
    /// pre-order; a run's `tree.bt` is in this form), `None` past a tree's end: the whole
    /// trees would take a screen.
    #[error("snapshot was learned with another tree: {0}")]
    Tree(TextDifference),
    /// A map of the same name whose text differs (a copy of a map edited).
    #[error("snapshot was learned on another map named `{name}`: {difference}")]
    Map { name: String, difference: TextDifference },
    #[error("snapshot holds trial {found}, read here for trial {expected} (a renamed file?)")]
    Trial { found: u32, expected: usize },
    #[error("inconsistent snapshot: {0}")]
    Inconsistent(String),
    /// The error of one file. Its cause is in the message, not also a `source`: error
    /// reports that follow the chain would print it twice.
    #[error("{path}: {cause}")]
    File { path: String, cause: Box<SnapshotError> },
    /// The I/O error is in the message, not also a `source` (a field named `source` is one
    /// to thiserror): reports that follow the chain would print it twice.
    #[error("cannot read {path}: {error}")]
    Io { path: String, error: std::io::Error },
}

impl Snapshot {
    /// The bytes of this snapshot as a file holds them (what [`Snapshot::decode`] reads).
    pub fn encode(&self) -> Vec<u8> {
        bincode::serde::encode_to_vec(self, bincode::config::standard())
            .expect("a snapshot holds only plain data")
    }

    /// Reads a snapshot from a file's bytes. The format number, which every format puts
    /// first, is checked before the rest is decoded: a file of another format is laid out
    /// differently and would otherwise fail on some field in its middle.
    pub fn decode(bytes: &[u8]) -> Result<Snapshot, SnapshotError> {
        let decode_error = |e: bincode::error::DecodeError| SnapshotError::Decode(decode_cause(&e));
        let config = bincode::config::standard().with_limit::<DECODE_LIMIT>();
        let (format, _): (u32, usize) =
            bincode::decode_from_slice(bytes, config).map_err(decode_error)?;
        if format != FORMAT {
            return Err(SnapshotError::Format { found: format });
        }
        let (snapshot, _): (Snapshot, usize) =
            bincode::serde::decode_from_slice(bytes, config).map_err(decode_error)?;
        Ok(snapshot)
    }

    /// Loads this snapshot into `agent`, trial `trial` of its run, after checking it was
    /// learned on the same setup and in that trial. The agent goes on counting its training
    /// episodes from the snapshot's, so the snapshots it writes next say how much training
    /// is behind them, a restart or a resume included.
    pub fn restore(
        &self,
        agent: &mut TrialAgent,
        trial: usize,
        learned: &Learned,
    ) -> Result<(), SnapshotError> {
        let check = |what, found: &str, expected: &str| {
            if found == expected {
                Ok(())
            } else {
                Err(SnapshotError::Mismatch {
                    what,
                    found: found.to_string(),
                    expected: expected.to_string(),
                })
            }
        };
        check("scenario", &self.scenario, learned.scenario.name())?;
        if let Some(difference) = TextDifference::of(&self.map, learned.scenario.map_text(), "") {
            return Err(SnapshotError::Map { name: self.scenario.clone(), difference });
        }
        check("communication mode", self.comm.name(), learned.comm.name())?;
        if self.slot as usize != agent.slot() {
            return Err(SnapshotError::Slot { found: self.slot, expected: agent.slot() });
        }
        let tree_bt = " (as in a run's tree.bt)";
        if let Some(difference) = TextDifference::of(&self.tree, learned.tree, tree_bt) {
            return Err(SnapshotError::Tree(difference));
        }
        if self.trial as usize != trial {
            return Err(SnapshotError::Trial { found: self.trial, expected: trial });
        }
        for (i, table) in self.tables.iter().enumerate() {
            table.check().map_err(|e| {
                SnapshotError::Inconsistent(format!("learning selector {}: {e}", i + 1))
            })?;
            if table.n_rows() > self.states.len() {
                return Err(SnapshotError::Inconsistent(format!(
                    "a table has {} rows for {} states",
                    table.n_rows(),
                    self.states.len()
                )));
            }
        }
        let states = StateSpace::from_keys(agent.comm().words().len(), &self.states)
            .map_err(SnapshotError::Inconsistent)?;
        agent.tree_mut().set_tables(self.tables.clone()).map_err(SnapshotError::Inconsistent)?;
        agent.set_states(states);
        agent.set_trained_episodes(self.episodes);
        Ok(())
    }
}

/// What made bincode refuse a snapshot's bytes, in words: bincode's own `Display` is its
/// `Debug` form (`UnexpectedEnd { additional: 4 }`). A file cut short, the usual damage,
/// says "truncated"; serde's own messages (an unknown communication mode) are kept.
fn decode_cause(error: &bincode::error::DecodeError) -> String {
    use bincode::error::DecodeError;
    match error {
        DecodeError::UnexpectedEnd { .. } | DecodeError::Io { .. } => "truncated".to_string(),
        DecodeError::Utf8 { .. } => "a text field is not UTF-8".to_string(),
        DecodeError::UnexpectedVariant { type_name, found, .. } => {
            format!("no {type_name} is numbered {found}")
        }
        DecodeError::LimitExceeded | DecodeError::OutsideUsizeRange(_) => {
            format!(
                "a length field asks for more than the {} GiB a snapshot may hold",
                DECODE_LIMIT >> 30
            )
        }
        DecodeError::Other(message) => message.to_string(),
        DecodeError::OtherString(message) => message.clone(),
        _ => "malformed bytes".to_string(),
    }
}

/// Where two canonical texts (a tree's, a map's: one item a line) first differ: the whole
/// texts would take a screen.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line {line} of their canonical form{where_seen} is {} in the snapshot's, {} in this agent's", quoted(.found), quoted(.expected))]
pub struct TextDifference {
    /// Where a user sees that form, if anywhere: " (as in a run's tree.bt)".
    pub where_seen: &'static str,
    pub line: usize,
    /// The snapshot's line and the agent's, `None` past a text's end.
    pub found: Option<String>,
    pub expected: Option<String>,
}

impl TextDifference {
    /// The first line where `found` (the snapshot's) and `expected` (the agent's) part, if
    /// they differ.
    fn of(found: &str, expected: &str, where_seen: &'static str) -> Option<TextDifference> {
        // Split at every newline, not `lines()`: two different texts then differ in some
        // part, a missing final newline included.
        let (mut found_lines, mut expected_lines) = (found.split('\n'), expected.split('\n'));
        for line in 1.. {
            match (found_lines.next(), expected_lines.next()) {
                (None, None) => break,
                (f, e) if f != e => {
                    let (found, expected) = (f.map(str::to_string), e.map(str::to_string));
                    return Some(TextDifference { where_seen, line, found, expected });
                }
                _ => {}
            }
        }
        None
    }
}

/// One side of a [`TextDifference`]: the line quoted, or "missing" past its text's end.
fn quoted(line: &Option<String>) -> String {
    line.as_ref().map_or_else(|| "missing".to_string(), |line| format!("`{line}`"))
}

/// The bytes of a [`Snapshot`] of what `agent` has learned so far, encoded from the agent's
/// own tables and keys: no copy of them, no vector per state (a snapshot is written while
/// every process of the barrier waits).
fn encode_snapshot(agent: &TrialAgent, trial: usize, learned: &Learned) -> Vec<u8> {
    let snapshot = SnapshotOf {
        format: FORMAT,
        scenario: learned.scenario.name(),
        map: learned.scenario.map_text(),
        slot: agent.slot() as u32,
        trial: trial as u32,
        comm: learned.comm,
        tree: learned.tree,
        episodes: agent.trained_episodes(),
        states: Keys(agent.states()),
        tables: agent.tree().tables(),
    };
    bincode::serde::encode_to_vec(&snapshot, bincode::config::standard())
        .expect("a snapshot holds only plain data")
}

/// [`Snapshot`]'s fields in its order, borrowed: serde writes both alike.
#[derive(Serialize)]
struct SnapshotOf<'a> {
    format: u32,
    scenario: &'a str,
    map: &'a str,
    slot: u32,
    trial: u32,
    comm: CommMode,
    tree: &'a str,
    episodes: u64,
    states: Keys<'a>,
    tables: Vec<&'a QTable>,
}

/// State keys in id order, written as a sequence of sequences like `Vec<Vec<u64>>`.
struct Keys<'a>(&'a StateSpace);

impl Serialize for Keys<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(self.0.keys())
    }
}

/// The snapshot file of agent `slot` (0-based) in trial `trial` under a results directory:
/// `<out>/qtables/uav<N>_trial<K>.bin`.
pub fn snapshot_path(out: &Path, slot: usize, trial: usize) -> PathBuf {
    out.join("qtables").join(format!("uav{}_trial{}.bin", slot + 1, trial))
}

/// Writes the snapshot of `agent` in trial `trial` under `out`. The bytes go to
/// `<file>.partial` first; then the old file is removed and the partial one renamed in its
/// place. A crash never leaves a torn snapshot as the only one: between the removal and the
/// rename only the complete `.partial` is there, and [`read_snapshot`] falls back to it.
///
/// Why not rename over the old file: on ext4 (with its default `auto_da_alloc`), replacing a
/// file by a rename makes the kernel allocate the new file's blocks and start writing them
/// at once. Measured here (s3, 4 trials), that rename took 245 µs (median) against 27 µs for
/// removal and rename, while every process of the barrier waits for the agent. A snapshot
/// replaced before the kernel's own writeback now never reaches the disk at all.
pub fn write_snapshot(
    agent: &TrialAgent,
    out: &Path,
    trial: usize,
    learned: &Learned,
) -> std::io::Result<()> {
    let path = snapshot_path(out, agent.slot(), trial);
    let partial = partial_path(&path);
    let bytes = encode_snapshot(agent, trial, learned);
    // The directory is there but for the first snapshot: look for it only then.
    let write = || std::fs::write(&partial, &bytes);
    match write() {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            path.parent().map_or(Ok(()), std::fs::create_dir_all).and_then(|()| write())
        }
        written => written,
    }
    .and_then(|()| match std::fs::remove_file(&path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
        _ => Ok(()),
    })
    .and_then(|()| std::fs::rename(&partial, &path))
    .map_err(|e| std::io::Error::new(e.kind(), format!("cannot write {}: {e}", path.display())))
}

/// Where [`write_snapshot`] puts the bytes before they take the place of `path`.
fn partial_path(path: &Path) -> PathBuf {
    path.with_extension("bin.partial")
}

/// The snapshot at `path` or, if that file is missing, the complete `.partial` a crash left
/// between [`write_snapshot`]'s removal and rename. None if neither is there, or if only a
/// `.partial` is there and it does not decode (a crash while writing the first snapshot).
/// A file at `path` that does not decode is an error: it was complete once.
pub fn read_snapshot(path: &Path) -> Result<Option<Snapshot>, SnapshotError> {
    let read = |path: &Path| match std::fs::read(path) {
        Ok(bytes) => Ok(Some(bytes)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(error) => Err(SnapshotError::Io { path: path.display().to_string(), error }),
    };
    if let Some(bytes) = read(path)? {
        return Snapshot::decode(&bytes).map(Some).map_err(in_file(path));
    }
    Ok(read(&partial_path(path))?.and_then(|bytes| Snapshot::decode(&bytes).ok()))
}

/// Names the file an error is about.
fn in_file(path: &Path) -> impl FnOnce(SnapshotError) -> SnapshotError + '_ {
    move |cause| SnapshotError::File { path: path.display().to_string(), cause: Box::new(cause) }
}

/// Writes the snapshot of every trial of `agent` under `out` (by whoever owns the agent:
/// the in-process runner, or the agent process itself).
pub fn write_snapshots(
    agent: &crate::agent::UavAgent,
    out: &Path,
    learned: &Learned,
) -> std::io::Result<()> {
    for (trial, part) in agent.trials().iter().enumerate() {
        write_snapshot(part, out, trial, learned)?;
    }
    Ok(())
}

/// Loads every trial of `agent` from the snapshots under `dir` (as [`write_snapshots`] lays
/// them out). Returns the trials that have no snapshot there (they keep empty tables).
pub fn restore_snapshots(
    agent: &mut crate::agent::UavAgent,
    dir: &Path,
    learned: &Learned,
) -> Result<Vec<usize>, SnapshotError> {
    let mut missing = Vec::new();
    let slot = agent.slot();
    for (trial, part) in agent.trials_mut().iter_mut().enumerate() {
        let path = snapshot_path(dir, slot, trial);
        match read_snapshot(&path)? {
            Some(snapshot) => snapshot.restore(part, trial, learned).map_err(in_file(&path))?,
            None => missing.push(trial),
        }
    }
    Ok(missing)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::{AgentSpec, UavAgent};
    use crate::learning::LearnParams;
    use crate::uav::load_uav_tree;
    use flockstep_world::scenario::Scenario;
    use std::sync::Arc;

    impl Snapshot {
        /// What `agent` has learned so far, built field by field: what the borrowed encoding
        /// must decode to.
        fn of(agent: &TrialAgent, trial: usize, learned: &Learned) -> Snapshot {
            Snapshot {
                format: FORMAT,
                scenario: learned.scenario.name().to_string(),
                map: learned.scenario.map_text().to_string(),
                slot: agent.slot() as u32,
                trial: trial as u32,
                comm: learned.comm,
                tree: learned.tree.to_string(),
                episodes: agent.trained_episodes(),
                states: agent.states().keys().map(<[u64]>::to_vec).collect(),
                tables: agent.tree().tables().into_iter().cloned().collect(),
            }
        }
    }

    static S3: std::sync::LazyLock<Scenario> =
        std::sync::LazyLock::new(|| Scenario::resolve("s3").expect("s3 is built in"));

    /// What the tests' tables are learned on: s3, flags, a stand-in tree text.
    fn s3() -> Learned<'static> {
        Learned { scenario: &S3, comm: CommMode::Flags, tree: "tree" }
    }

    fn uav1() -> UavAgent {
        UavAgent::new(&AgentSpec {
            slot: 0,
            scenario: Arc::new(Scenario::resolve("s3").expect("s3 is built in")),
            tree: load_uav_tree(None).expect("the Fig. 5 tree loads"),
            comm: CommMode::Flags,
            params: LearnParams::default(),
            seed: 1,
            trials: 1,
        })
        .expect("UAV1 of s3")
    }

    fn write(agent: &UavAgent, dir: &Path) -> PathBuf {
        write_snapshot(&agent.trials()[0], dir, 0, &s3()).unwrap();
        snapshot_path(dir, 0, 0)
    }

    #[test]
    fn a_written_snapshot_reads_back_and_replaces_the_previous_one() {
        let dir = tempfile::tempdir().unwrap();
        let mut agent = uav1();
        let path = write(&agent, dir.path());
        assert!(read_snapshot(&path).unwrap().expect("the first snapshot").states.is_empty());
        learn_one_state(&mut agent);
        write(&agent, dir.path());
        let read = read_snapshot(&path).unwrap().expect("the second snapshot");
        assert_eq!(read, Snapshot::of(&agent.trials()[0], 0, &s3()));
        assert_eq!(read.states.len(), 1);
        assert!(!partial_path(&path).exists(), "the partial file was renamed into place");
    }

    /// Gives trial 0 one state, so its next snapshot differs from an empty one.
    fn learn_one_state(agent: &mut UavAgent) {
        let words = agent.trials()[0].comm().words().len();
        let states = StateSpace::from_keys(words, &[vec![0; words + 1]]).unwrap();
        agent.trials_mut()[0].set_states(states);
    }

    #[test]
    fn the_borrowed_encoding_writes_the_bytes_of_the_snapshot() {
        let mut agent = uav1();
        let part = &mut agent.trials_mut()[0];
        let words = part.comm().words().len();
        let keys: Vec<Vec<u64>> = (0..5).map(|i| vec![i; words + 1]).collect();
        part.set_states(StateSpace::from_keys(words, &keys).unwrap());
        let mut table = QTable::new(5);
        table.step(4, 2, -3.5, 1.0);
        table.step(1, 0, -0.25, 1.0);
        part.tree_mut().set_tables(vec![table]).unwrap();
        let owned = Snapshot::of(part, 0, &s3());
        let expected = bincode::serde::encode_to_vec(&owned, bincode::config::standard()).unwrap();
        assert_eq!(encode_snapshot(part, 0, &s3()), expected);
        assert_eq!(owned.states.len(), 5);
        assert_eq!(owned.tables[0].get(4, 2), -3.5);
    }

    #[test]
    fn a_crash_between_removal_and_rename_leaves_a_snapshot_to_read() {
        let dir = tempfile::tempdir().unwrap();
        let agent = uav1();
        let path = write(&agent, dir.path());
        std::fs::rename(&path, partial_path(&path)).unwrap();
        let read = read_snapshot(&path).unwrap().expect("the complete partial file is used");
        assert_eq!(read, Snapshot::of(&agent.trials()[0], 0, &s3()));
    }

    #[test]
    fn a_torn_partial_file_is_never_used() {
        let dir = tempfile::tempdir().unwrap();
        let mut agent = uav1();
        let path = write(&agent, dir.path());
        learn_one_state(&mut agent);
        let bytes = encode_snapshot(&agent.trials()[0], 0, &s3());
        std::fs::write(partial_path(&path), &bytes[..bytes.len() / 2]).unwrap();
        let read = read_snapshot(&path).unwrap().expect("the snapshot before the crash");
        assert!(read.states.is_empty(), "the torn write was read");
        std::fs::remove_file(&path).unwrap();
        assert!(read_snapshot(&path).unwrap().is_none(), "a torn first snapshot counts as none");
    }

    #[test]
    fn a_snapshot_holding_a_non_finite_q_value_is_refused() {
        let mut agent = uav1();
        learn_one_state(&mut agent);
        let mut snapshot = Snapshot::of(&agent.trials()[0], 0, &s3());
        let mut table = QTable::new(5);
        table.step(0, 3, f64::NAN, 1.0);
        snapshot.tables = vec![table];
        let err = snapshot.restore(&mut agent.trials_mut()[0], 0, &s3()).unwrap_err().to_string();
        assert_eq!(
            err,
            "inconsistent snapshot: learning selector 1: Q(state 0, child 4) is NaN; \
             Q-values are finite"
        );
    }

    /// A restored agent counts its training on from the snapshot: the next snapshot it
    /// writes says how many episodes are behind it in all, not since the restart.
    #[test]
    fn a_restored_agent_goes_on_counting_its_training_episodes() {
        let dir = tempfile::tempdir().unwrap();
        let mut agent = uav1();
        learn_one_state(&mut agent);
        agent.trials_mut()[0].set_trained_episodes(10_000);
        write(&agent, dir.path());
        let mut restarted = uav1();
        let missing = restore_snapshots(&mut restarted, dir.path(), &s3()).unwrap();
        assert!(missing.is_empty());
        assert_eq!(restarted.trials()[0].trained_episodes(), 10_000);
        let path = write(&restarted, dir.path());
        assert_eq!(read_snapshot(&path).unwrap().expect("written").episodes, 10_000);
    }

    /// A snapshot of another trial (a file renamed or copied by hand) is refused with the
    /// file named, not loaded into the wrong trial.
    #[test]
    fn a_snapshot_of_another_trial_is_refused_naming_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let agent = uav1();
        write_snapshot(&agent.trials()[0], dir.path(), 3, &s3()).unwrap();
        std::fs::rename(snapshot_path(dir.path(), 0, 3), snapshot_path(dir.path(), 0, 0)).unwrap();
        let err = restore_snapshots(&mut uav1(), dir.path(), &s3()).unwrap_err().to_string();
        assert!(
            err.ends_with(
                "uav1_trial0.bin: snapshot holds trial 3, read here for trial 0 (a renamed file?)"
            ),
            "{err}"
        );
    }

    /// The error of restoring into UAV1 of s3 (tree `tree`) a snapshot of it changed by
    /// `change`.
    fn refusal(change: impl FnOnce(&mut Snapshot)) -> String {
        let mut agent = uav1();
        let mut snapshot = Snapshot::of(&agent.trials()[0], 0, &s3());
        change(&mut snapshot);
        let part = &mut agent.trials_mut()[0];
        snapshot.restore(part, 0, &s3()).unwrap_err().to_string()
    }

    /// Slots are numbered from 0 inside, UAVs from 1 for users. Before, the message said
    /// "agent slot `1`, this agent uses `0`" of UAV2's snapshot read for UAV1.
    #[test]
    fn a_snapshot_of_another_uav_names_both_as_uavs() {
        let err = refusal(|snapshot| snapshot.slot = 1);
        assert_eq!(err, "snapshot was learned by UAV2, this agent is UAV1");
    }

    /// Another tree is named by its first differing line, in one line. Before, the message
    /// quoted both trees whole, about 20 lines for the thesis's tree.
    #[test]
    fn a_snapshot_of_another_tree_names_the_first_differing_line() {
        let err = refusal(|snapshot| snapshot.tree = "OR 2\n- A-rotate 0\n".to_string());
        assert_eq!(
            err,
            "snapshot was learned with another tree: line 1 of their canonical form (as in a \
             run's tree.bt) is `OR 2` in the snapshot's, `tree` in this agent's"
        );
        let err = refusal(|snapshot| snapshot.tree = "tree\n- A-rotate 0".to_string());
        let end = "line 2 of their canonical form (as in a run's tree.bt) is `- A-rotate 0` in \
                   the snapshot's, missing in this agent's";
        assert!(err.ends_with(end), "{err}");
    }

    /// A map edited but for its `name:` line is another map: its tables are refused,
    /// naming the first line that differs. Before, only the name was compared.
    #[test]
    fn a_snapshot_of_another_map_of_the_same_name_names_the_first_differing_line() {
        let map = S3.map().to_text();
        let line = map.split('\n').count();
        let err = refusal(|snapshot| snapshot.map.push_str("UAV1: 0,0 0,1"));
        assert_eq!(
            err,
            format!(
                "snapshot was learned on another map named `{}`: line {line} of their canonical \
                 form is `UAV1: 0,0 0,1` in the snapshot's, `` in this agent's",
                S3.name()
            )
        );
    }

    /// A cut file says "truncated". Before, it said bincode's `UnexpectedEnd { additional: 4 }`.
    #[test]
    fn a_truncated_snapshot_says_so_in_words() {
        let bytes = encode_snapshot(&uav1().trials()[0], 0, &s3());
        let err = Snapshot::decode(&bytes[..bytes.len() - 1]).unwrap_err().to_string();
        assert_eq!(err, "not a flockstep Q-table snapshot: truncated");
    }

    #[test]
    fn a_damaged_snapshot_is_an_error_naming_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = write(&uav1(), dir.path());
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.truncate(bytes.len() / 2);
        std::fs::write(&path, bytes).unwrap();
        let err = read_snapshot(&path).unwrap_err().to_string();
        assert_eq!(err, format!("{}: not a flockstep Q-table snapshot: truncated", path.display()));
    }

    /// A file that is not a snapshot at all says what it starts with: here the text's `n`.
    #[test]
    fn a_file_of_text_is_refused_by_its_first_byte() {
        let err = Snapshot::decode(b"not a snapshot").unwrap_err().to_string();
        assert_eq!(
            err,
            "not a snapshot this build reads: it starts with format number 110, this build \
             reads format 2"
        );
    }

    /// A snapshot of another format is refused by its number before any other field is
    /// read: format 1 had no map, so its fields would fail in the middle, for a reason that
    /// says nothing of the format. Here everything after the number is cut.
    #[test]
    fn a_snapshot_of_another_format_is_refused_before_its_fields_are_read() {
        let mut bytes = encode_snapshot(&uav1().trials()[0], 0, &s3());
        assert_eq!(bytes[0], 2, "the format number leads, in one byte");
        bytes[0] = 1;
        let err = Snapshot::decode(&bytes[..1]).unwrap_err().to_string();
        assert_eq!(err, "not a snapshot this build reads: it starts with format number 1, this build reads format 2");
    }

    /// A damaged length field of a text (here the scenario name's, asking for 2^62 bytes) is
    /// an error. Before, bincode allocated what it asked for and the process aborted.
    #[test]
    fn a_length_past_the_decode_limit_is_an_error_not_an_abort() {
        let mut bytes = vec![2, 253]; // format 2, then a length in the next 8 bytes
        bytes.extend_from_slice(&(1u64 << 62).to_le_bytes());
        let err = Snapshot::decode(&bytes).unwrap_err().to_string();
        assert_eq!(
            err,
            "not a flockstep Q-table snapshot: a length field asks for more than the 1 GiB a \
             snapshot may hold"
        );
    }
}
