//! Names of a run's iceoryx2 services. Everything lives under a per-run prefix, so two runs,
//! or two tests, on one machine never meet.

/// Service name `flockstep/<run_id>/<what>`.
pub fn service_name(run_id: &str, what: &str) -> String {
    format!("flockstep/{run_id}/{what}")
}

pub const OBSERVATIONS: &str = "observations";
pub const ACTIONS: &str = "actions";
pub const EPISODES: &str = "episodes";
pub const CONTROL: &str = "control";
pub const JOIN: &str = "join";
pub const RUN_INFO: &str = "run-info";

/// The longest run id. iceoryx2 names a run's event sockets
/// `<root>/flockstep.<run id>.<listener id>.event`, and a Unix socket path has at most 108
/// bytes. The longest root is `/tmp/flockstep-4294967295/` (26 bytes), and a listener id
/// (a `u128` whose top 32 bits count the ids its process made) has at most 33 digits until a
/// process has made 12 000 of them: 32 bytes are left for the run id.
pub const MAX_RUN_ID: usize = 32;

/// A run id must be usable inside file names of `/dev/shm` and in socket paths: ASCII
/// letters, digits, `-`, `_`, at most [`MAX_RUN_ID`] of them.
pub fn validate_run_id(run_id: &str) -> Result<(), String> {
    if run_id.is_empty() || run_id.len() > MAX_RUN_ID {
        return Err(format!("run id `{run_id}` must have 1 to {MAX_RUN_ID} characters"));
    }
    if let Some(c) = run_id.chars().find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(format!("run id `{run_id}` contains `{c}`; use letters, digits, `-` and `_`"));
    }
    Ok(())
}
