//! The iceoryx2 glue every flockstep process shares: one node per process under a per-run
//! prefix, the run's services with explicit limits, the barrier's waiting strategy, and the
//! clean-up of a run's shared-memory files. No simulation logic lives here.
//!
//! The world creates every service up front ([`RunServices::create`]); agents and the
//! supervisor only open them ([`RunServices::open`], retrying until the world has created
//! them). Each role then takes its ports ([`RunServices::into_world`], `into_agent`,
//! `into_supervisor`): a publish is always followed by a notify on the reader's wake-up event,
//! so a reader can block in [`Waiter::wait`] instead of burning one of the two cores.
//! `docs/TRANSPORT.md` gives the limits, the QoS and the measured numbers behind them.
//!
//! This file holds what every part shares: the run's identity, its node, signal handling and
//! the error type.

mod cleanup;
mod ports;
mod process;
mod root;
mod run_services;
mod wait;

pub use cleanup::{cleanup_run, leftover_files, sweep_stale_runs, RunCleanup, SweepReport};
pub use ports::{
    ActionLoan, ActionSample, AgentPorts, FromWorld, ObservationSample, Peers, SenderNode,
    SupervisorPorts, WorldPorts, EPISODE_WAKE_EVERY,
};
pub use process::{process_of_node, process_stat};
pub use root::iceoryx_root;
pub use run_services::{DepartedNodes, RunServices, EPISODE_BUFFER, MAX_NODES, SPARE};
pub use wait::{Overdue, WaitPolicy, Waiter};

use crate::services;
use cleanup::LastOut;
use iceoryx2::prelude::*;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

type Ipc = ipc::Service;

/// Event services that wake one role up after another one published something for it.
const WAKE_WORLD: &str = "wake/world";
const WAKE_AGENTS: &str = "wake/agents";
const WAKE_SUPERVISOR: &str = "wake/supervisor";
/// How long the world's wait for an agent goes on before it looks for the agent's node
/// ([`RunServices::departed_nodes`]), and how often it looks again: a crashed agent is
/// dropped within tens of milliseconds.
pub const LOOK_FOR_GONE_AGENTS: (Duration, Duration) =
    (Duration::from_millis(20), Duration::from_millis(100));
/// The same for an agent's wait for the world. Every agent waits while one is slow, so the
/// agents look less often than the world: an attached agent still learns of a killed world
/// within about a second instead of at its `--world-timeout-ms` (30 s).
pub const LOOK_FOR_GONE_WORLD: (Duration, Duration) =
    (Duration::from_millis(200), Duration::from_secs(1));
/// Start of every file name a run leaves in `/dev/shm` and under the iceoryx2 root; `.` cannot
/// occur in a run id, so `flockstep.ab.` never matches the files of run `abc`.
const PREFIX_HEAD: &str = "flockstep.";

/// What can go wrong in the transport. Every variant names the run and, where there is one,
/// the service involved. A cause is in the message and not also a `source`: reports that
/// follow the chain (`{:#}`) would print it twice.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error("invalid run id: {0}")]
    InvalidRunId(String),
    #[error("run `{run}`: {what} failed: {cause}")]
    Setup { run: String, what: String, cause: Box<dyn std::error::Error + Send + Sync> },
    #[error("run `{run}`: no world created `{service}` within {waited:?}")]
    ServiceMissing { run: String, service: String, waited: Duration },
    #[error("run `{run}`: the world created no publisher on `{service}` within {waited:?}")]
    PublisherMissing { run: String, service: String, waited: Duration },
    #[error("run `{run}`: service `{service}` already exists: another live run uses this run id")]
    RunInUse { run: String, service: String },
    #[error("run `{run}`: {op} on `{service}` failed: {cause}")]
    Port {
        run: String,
        service: String,
        op: &'static str,
        cause: Box<dyn std::error::Error + Send + Sync>,
    },
    #[error("run `{run}`: `{service}` not drained for {waited:?}; stopping, not losing records")]
    ReportsStalled { run: String, service: String, waited: Duration },
    #[error("run `{run}`: timed out after {waited:?} waiting for {what} (woken by `{service}`)")]
    Timeout { run: String, service: String, what: String, waited: Duration },
    #[error("run `{run}`: the world ({world}) is gone; this agent was waiting for {what}")]
    WorldGone { run: String, world: String, what: String },
    #[error("run `{run}`: termination requested while waiting for {what}")]
    Terminated { run: String, what: String },
    #[error("run `{run}`: peers did not connect within {waited:?}: {missing}")]
    PeersMissing { run: String, missing: String, waited: Duration },
    #[error("parent process {parent} is gone (this process now belongs to {now})")]
    ParentGone { parent: u32, now: libc::pid_t },
    #[error("{what} failed: {cause}")]
    Io { what: String, cause: std::io::Error },
    /// This user's iceoryx2 root ([`iceoryx_root`]) exists but cannot be trusted with the
    /// run's files.
    #[error(
        "iceoryx2 root `{}` {problem}; it must be a private directory of this user: remove it \
         (its owner may have to) and a run makes one",
        path.display()
    )]
    UnsafeRoot { path: PathBuf, problem: String },
}

/// How a process wants SIGTERM and SIGINT handled while it uses the transport.
///
/// iceoryx2 itself is always told to leave signals alone (`SignalHandlingMode::Disabled`): its
/// own mode only changes what `Node::wait` and `WaitSet` report, flockstep uses neither, and
/// a single reader of the signal avoids two readers racing to consume it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalMode {
    /// A world or agent started by the supervisor. SIGTERM is latched and [`Waiter::wait`]
    /// returns [`TransportError::Terminated`], so the process leaves at its next wait and drops
    /// its ports (its files go with them); SIGKILL stays the supervisor's last resort. SIGINT
    /// is ignored: a terminal's Ctrl-C reaches the whole process group, and only the supervisor
    /// may turn it into an orderly stop at the same round for everyone.
    Supervised,
    /// An agent a user started in a terminal (`agent --attach`): Ctrl-C (SIGINT) and SIGTERM
    /// are both latched as in [`SignalMode::Supervised`], so either makes it leave the run
    /// at its next wait, its tables saved.
    Interactive,
    /// Signals are left as they are: the process owns them (the supervisor with `ctrlc`,
    /// tests, the benchmark's parent).
    Untouched,
}

/// How long the world may wait for the supervisor to make room for an episode record, unless
/// a test says otherwise ([`RunConfig::report_timeout`]).
pub const REPORT_TIMEOUT: Duration = Duration::from_secs(10);

/// Identity and timing of one run, as every process of the run sees it.
#[derive(Debug, Clone)]
pub struct RunConfig {
    /// Checked by [`services::validate_run_id`]; names the run's services and files.
    pub run_id: String,
    pub signals: SignalMode,
    /// How long [`RunServices::open`] waits for the world to create the services.
    pub open_timeout: Duration,
    /// How long the world may wait for the supervisor to make room for an episode record.
    pub report_timeout: Duration,
    pub wait: WaitPolicy,
}

impl RunConfig {
    pub fn new(run_id: impl Into<String>, signals: SignalMode) -> RunConfig {
        RunConfig {
            run_id: run_id.into(),
            signals,
            open_timeout: Duration::from_secs(10),
            report_timeout: REPORT_TIMEOUT,
            wait: WaitPolicy::default(),
        }
    }

    /// The error of a wait or an open of this run that a termination signal cut short.
    pub(crate) fn terminated(&self, what: &str) -> TransportError {
        TransportError::Terminated { run: self.run_id.clone(), what: what.to_string() }
    }
}

/// The iceoryx2 configuration of a run: defaults (no config file is read, so a user's or the
/// system's `iceoryx2.toml` cannot change a run) with this user's root and the run's own file
/// prefix.
pub fn iceoryx_config(run_id: &str) -> Result<Config, TransportError> {
    services::validate_run_id(run_id).map_err(TransportError::InvalidRunId)?;
    let mut config = default_config()?;
    config.global.prefix = FileName::new(run_prefix(run_id).as_bytes())
        .map_err(|e| TransportError::InvalidRunId(format!("run id `{run_id}`: {e:?}")))?;
    // Dead nodes are removed through `cleanup_run` and `RunServices::cleanup_dead_nodes`,
    // which first remove what iceoryx2 would wait on for good (see `remove_empty_segments`).
    config.global.node.cleanup_dead_nodes_on_creation = false;
    Ok(config)
}

/// iceoryx2's default configuration, with its log level at errors and its root moved to this
/// user's own directory (created and checked here; see [`iceoryx_root`]). Our configuration
/// does not come from a file, but iceoryx2 looks one up (on the first use of its global
/// configuration, and when it cleans a dead node without details) and warns on stderr.
fn default_config() -> Result<Config, TransportError> {
    set_log_level(LogLevel::Error);
    let root = root::ensure_root()?;
    // A trailing `/`, as in iceoryx2's own default root.
    let root_path = Path::new(format!("{}/", root.display()).as_bytes()).map_err(|e| {
        TransportError::UnsafeRoot {
            path: root,
            problem: format!("is not a valid iceoryx2 path: {e:?}"),
        }
    })?;
    let mut config = Config::default();
    config.global.set_root_path(&root_path);
    Ok(config)
}

fn run_prefix(run_id: &str) -> String {
    format!("{PREFIX_HEAD}{run_id}.")
}

/// This process's node of a run. Dropping the last `RunNode` of a run (in any process) also
/// removes the run's node-id counter segment; see [`cleanup_run`].
pub struct RunNode {
    node: Node<Ipc>,
    // Declared last so it runs once the node is gone.
    _last_out: LastOut,
}

/// The name of the world's node. The world makes its node before the run's services, so an
/// agent that opened them and finds no live node of this name knows the world is gone
/// ([`RunServices::departed_nodes`]), even if it never saw the world's publisher. The other
/// nodes of a run are unnamed.
pub const WORLD_NODE_NAME: &str = "world";

impl RunNode {
    /// Creates the node, named `name` (see [`WORLD_NODE_NAME`]), after installing the signal
    /// handling `run` asks for. Creating it does not remove the resources of dead nodes of
    /// the run ([`iceoryx_config`] turns that off): [`cleanup_run`] and
    /// [`RunServices::cleanup_dead_nodes`] do.
    pub fn new(run: &RunConfig, name: Option<&str>) -> Result<RunNode, TransportError> {
        let config = iceoryx_config(&run.run_id)?;
        if run.signals != SignalMode::Untouched {
            install_termination_signals(run.signals)?;
        }
        // Armed before the node exists, so a failure further on still cleans up.
        let last_out = LastOut::new(&run.run_id);
        let mut builder = NodeBuilder::new();
        if let Some(name) = name {
            let name = NodeName::new(name)
                .map_err(|e| setup(&run.run_id, format!("naming the node `{name}`"), e))?;
            builder = builder.name(&name);
        }
        let node = builder
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Ipc>()
            .map_err(|e| setup(&run.run_id, "creating the iceoryx2 node", e))?;
        Ok(RunNode { node, _last_out: last_out })
    }

    pub fn node(&self) -> &Node<Ipc> {
        &self.node
    }
}

static TERMINATION: AtomicBool = AtomicBool::new(false);

extern "C" fn latch_termination(_: libc::c_int) {
    TERMINATION.store(true, Ordering::Relaxed);
}

/// Latches SIGTERM, and SIGINT too in [`SignalMode::Interactive`] (ignored otherwise: see
/// [`SignalMode::Supervised`]).
fn install_termination_signals(mode: SignalMode) -> Result<(), TransportError> {
    // SAFETY: `sigaction` with a zeroed, then filled, struct; the handler only stores to an
    // atomic, which is async-signal-safe.
    let failed = unsafe {
        let mut term: libc::sigaction = std::mem::zeroed();
        term.sa_sigaction = latch_termination as extern "C" fn(libc::c_int) as libc::sighandler_t;
        libc::sigemptyset(&mut term.sa_mask);
        // No SA_RESTART: a listener blocked in its wait returns at once and sees the latch.
        term.sa_flags = 0;
        let mut ignore: libc::sigaction = std::mem::zeroed();
        ignore.sa_sigaction = libc::SIG_IGN;
        libc::sigemptyset(&mut ignore.sa_mask);
        let int = if mode == SignalMode::Interactive { &term } else { &ignore };
        libc::sigaction(libc::SIGTERM, &term, std::ptr::null_mut()) != 0
            || libc::sigaction(libc::SIGINT, int, std::ptr::null_mut()) != 0
    };
    if failed {
        return Err(TransportError::Io {
            what: "installing the SIGTERM and SIGINT handlers".into(),
            cause: std::io::Error::last_os_error(),
        });
    }
    Ok(())
}

/// True once a [`SignalMode::Supervised`] or [`SignalMode::Interactive`] process received a
/// signal it latches.
pub fn termination_requested() -> bool {
    TERMINATION.load(Ordering::Relaxed)
}

/// Orphan guard: the kernel sends this process SIGTERM when its parent dies (with
/// [`SignalMode::Supervised`] it then leaves at its next wait). Fails if the parent, whose pid
/// the parent passed down, is already gone. The signal fires when the parent *thread* that
/// spawned us exits, so spawn children from a thread that lives as long as they should.
#[cfg(target_os = "linux")]
pub fn exit_with_parent(parent_pid: u32) -> Result<(), TransportError> {
    // SAFETY: plain prctl/getppid calls without pointers.
    let (rc, ppid) = unsafe {
        (libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong), libc::getppid())
    };
    if rc != 0 {
        return Err(TransportError::Io {
            what: "prctl(PR_SET_PDEATHSIG)".into(),
            cause: std::io::Error::last_os_error(),
        });
    }
    // Checked after arming: a parent that died before the prctl would never signal us.
    if u32::try_from(ppid).ok() != Some(parent_pid) {
        return Err(TransportError::ParentGone { parent: parent_pid, now: ppid });
    }
    Ok(())
}

fn setup(
    run: &str,
    what: impl Into<String>,
    e: impl std::error::Error + Send + Sync + 'static,
) -> TransportError {
    TransportError::Setup { run: run.into(), what: what.into(), cause: Box::new(e) }
}
