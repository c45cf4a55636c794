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

/// A run id must be usable inside file names of `/dev/shm`: ASCII letters, digits, `-`, `_`.
pub fn validate_run_id(run_id: &str) -> Result<(), String> {
    if run_id.is_empty() || run_id.len() > 40 {
        return Err(format!("run id `{run_id}` must have 1 to 40 characters"));
    }
    if let Some(c) = run_id.chars().find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(format!("run id `{run_id}` contains `{c}`; use letters, digits, `-` and `_`"));
    }
    Ok(())
}
