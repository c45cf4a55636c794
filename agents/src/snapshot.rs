//! Q-table snapshots: what one agent learned in one trial, as bytes (serde + bincode).
//!
//! A snapshot holds the state keys in id order and every learning selector's table, plus
//! what it was learned on (scenario, slot, communication mode, tree), which is checked when
//! it is loaded: a table learned on another tree or scenario is refused, not misread.

use crate::agent::TrialAgent;
use crate::comm::CommMode;
use crate::learning::QTable;
use crate::state::StateSpace;
use serde::{Deserialize, Serialize};

/// Format version; bump when the layout changes.
pub const FORMAT: u32 = 1;

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    pub format: u32,
    pub scenario: String,
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
    #[error("snapshot format {found}, this build reads format {FORMAT}")]
    Format { found: u32 },
    #[error("snapshot was learned with {what} `{found}`, this agent uses `{expected}`")]
    Mismatch { what: &'static str, found: String, expected: String },
    #[error("inconsistent snapshot: {0}")]
    Inconsistent(String),
    #[error("{path}: {source}")]
    File {
        path: String,
        #[source]
        source: Box<SnapshotError>,
    },
    #[error("cannot read {path}: {source}")]
    Io { path: String, source: std::io::Error },
}

impl Snapshot {
    pub fn encode(&self) -> Vec<u8> {
        bincode::serde::encode_to_vec(self, bincode::config::standard())
            .expect("a snapshot holds only plain data")
    }

    pub fn decode(bytes: &[u8]) -> Result<Snapshot, SnapshotError> {
        let (snapshot, _): (Snapshot, usize) =
            bincode::serde::decode_from_slice(bytes, bincode::config::standard())
                .map_err(|e| SnapshotError::Decode(e.to_string()))?;
        if snapshot.format != FORMAT {
            return Err(SnapshotError::Format { found: snapshot.format });
        }
        Ok(snapshot)
    }

    /// What `agent` has learned so far.
    pub fn of(
        agent: &TrialAgent,
        scenario: &str,
        trial: usize,
        comm: CommMode,
        tree: &str,
    ) -> Snapshot {
        Snapshot {
            format: FORMAT,
            scenario: scenario.to_string(),
            slot: agent.slot() as u32,
            trial: trial as u32,
            comm,
            tree: tree.to_string(),
            episodes: agent.trained_episodes(),
            states: agent.states().keys().map(<[u64]>::to_vec).collect(),
            tables: agent.tree().tables().into_iter().cloned().collect(),
        }
    }

    /// Loads this snapshot into `agent` after checking it was learned on the same setup.
    pub fn restore(
        &self,
        agent: &mut TrialAgent,
        scenario: &str,
        comm: CommMode,
        tree: &str,
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
        check("scenario", &self.scenario, scenario)?;
        check("communication mode", self.comm.name(), comm.name())?;
        check("agent slot", &self.slot.to_string(), &agent.slot().to_string())?;
        check("tree", &self.tree, tree)?;
        for table in &self.tables {
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
        Ok(())
    }
}

/// The snapshot file of agent `slot` (0-based) in trial `trial` under a results directory:
/// `<out>/qtables/uav<N>_trial<K>.bin`.
pub fn snapshot_path(out: &std::path::Path, slot: usize, trial: usize) -> std::path::PathBuf {
    out.join("qtables").join(format!("uav{}_trial{}.bin", slot + 1, trial))
}

/// Writes the snapshot of `agent` in trial `trial` under `out`, through a temporary file
/// and a rename, so a crash never leaves a torn snapshot behind.
pub fn write_snapshot(
    agent: &TrialAgent,
    out: &std::path::Path,
    trial: usize,
    scenario: &str,
    comm: CommMode,
    tree: &str,
) -> std::io::Result<()> {
    let path = snapshot_path(out, agent.slot(), trial);
    let partial = path.with_extension("bin.partial");
    let bytes = Snapshot::of(agent, scenario, trial, comm, tree).encode();
    path.parent()
        .map_or(Ok(()), std::fs::create_dir_all)
        .and_then(|()| std::fs::write(&partial, bytes))
        .and_then(|()| std::fs::rename(&partial, &path))
        .map_err(|e| std::io::Error::new(e.kind(), format!("cannot write {}: {e}", path.display())))
}

/// Writes the snapshot of every trial of `agent` under `out` (by whoever owns the agent:
/// the in-process runner, or the agent process itself).
pub fn write_snapshots(
    agent: &crate::agent::UavAgent,
    out: &std::path::Path,
    scenario: &str,
    comm: CommMode,
    tree: &str,
) -> std::io::Result<()> {
    for (trial, part) in agent.trials().iter().enumerate() {
        write_snapshot(part, out, trial, scenario, comm, tree)?;
    }
    Ok(())
}

/// Loads every trial of `agent` from the snapshots under `dir` (as [`write_snapshots`] lays
/// them out). Returns the trials that have no snapshot there (they keep empty tables).
pub fn restore_snapshots(
    agent: &mut crate::agent::UavAgent,
    dir: &std::path::Path,
    scenario: &str,
    comm: CommMode,
    tree: &str,
) -> Result<Vec<usize>, SnapshotError> {
    let mut missing = Vec::new();
    let slot = agent.slot();
    for (trial, part) in agent.trials_mut().iter_mut().enumerate() {
        let path = snapshot_path(dir, slot, trial);
        let file = |source| SnapshotError::File {
            path: path.display().to_string(),
            source: Box::new(source),
        };
        match std::fs::read(&path) {
            Ok(bytes) => Snapshot::decode(&bytes)
                .and_then(|s| s.restore(part, scenario, comm, tree))
                .map_err(file)?,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => missing.push(trial),
            Err(source) => {
                return Err(SnapshotError::Io { path: path.display().to_string(), source })
            }
        }
    }
    Ok(missing)
}
