//! The raw lockstep barrier over iceoryx2, shared by the `barrier` and `throughput` benches
//! (each includes this file with `#[path = "common/raw_barrier.rs"] mod raw_barrier;`).
//!
//! One world process and N agent processes exchange an `Observation` and N `Action`s per
//! round through `flockstep_proto::transport`, exactly as a run does, but without any
//! simulation work. The bench binary re-executes itself for the processes: its `main` first
//! hands its arguments to [`run_child`], which runs the world (`--child-world`) or an agent
//! (`--child-agent`), and only otherwise acts as the parent that calls [`measure`].

use flockstep_proto::transport::{
    cleanup_run, exit_with_parent, leftover_files, RunConfig, RunServices, SignalMode, WaitPolicy,
};
use flockstep_proto::{Observation, ObservationKind, MAX_AGENTS};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A round slower than this means a process is gone, not slow.
const ROUND_TIMEOUT: Duration = Duration::from_secs(5);
/// Time for all agents to start and connect.
const START_TIMEOUT: Duration = Duration::from_secs(30);

pub type Error = Box<dyn std::error::Error>;

/// Runs this process as a barrier child if `args` (without the program name) ask for one;
/// `None` if this process is the parent.
pub fn run_child(args: &[String]) -> Option<Result<(), Error>> {
    match args.first().map(String::as_str) {
        Some("--child-world") => Some(child_world(&args[1..])),
        Some("--child-agent") => Some(child_agent(&args[1..])),
        _ => None,
    }
}

/// A bench's `main`: runs this process as a barrier child if its arguments ask for one,
/// else as the parent (`parent`); prints an error as `<bench>: <error>` and exits with 1.
pub fn bench_main(bench: &str, parent: impl FnOnce(&[String]) -> Result<(), Error>) {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Err(e) = run_child(&args).unwrap_or_else(|| parent(&args)) {
        eprintln!("{bench}: {e}");
        std::process::exit(1);
    }
}

/// What one child process needs to know, passed as positional arguments.
struct ChildArgs {
    run_id: String,
    parent: u32,
    agents: usize,
    /// World: how long to run. Agent: its slot.
    value: u64,
    policy: WaitPolicy,
}

impl ChildArgs {
    fn parse(args: &[String]) -> Result<ChildArgs, Error> {
        let [run_id, parent, agents, value, policy] = args else {
            return Err(format!("child arguments: expected 5, got {args:?}").into());
        };
        let agents: usize = agents.parse()?;
        if !(1..=MAX_AGENTS).contains(&agents) {
            return Err(format!("{agents} agents: must be 1..={MAX_AGENTS}").into());
        }
        Ok(ChildArgs {
            run_id: run_id.clone(),
            parent: parent.parse()?,
            agents,
            value: value.parse()?,
            policy: parse_policy(policy)?,
        })
    }

    fn to_args(&self) -> Vec<String> {
        let policy = format_policy(&self.policy);
        vec![
            self.run_id.clone(),
            self.parent.to_string(),
            self.agents.to_string(),
            self.value.to_string(),
            policy,
        ]
    }

    /// A supervised child: leaves at its next wait on SIGTERM, and gets SIGTERM when the
    /// benchmark's parent dies.
    fn run_config(&self) -> Result<RunConfig, Error> {
        exit_with_parent(self.parent)?;
        let mut run = RunConfig::new(self.run_id.clone(), SignalMode::Supervised);
        run.wait = self.policy;
        Ok(run)
    }
}

/// A waiting strategy written `SPINS/YIELDS[/YIELD_FOR_US[/BACKOFF_MS]]` (the rest, and
/// the fields left out, as in the product's default): the `barrier` bench's `--policy` and
/// the form in which a child gets its strategy.
pub fn parse_policy(text: &str) -> Result<WaitPolicy, Error> {
    let fields: Vec<&str> = text.split('/').collect();
    if !(2..=4).contains(&fields.len()) {
        return Err(
            format!("--policy {text}: expected SPINS/YIELDS[/YIELD_FOR_US[/BACKOFF_MS]]").into()
        );
    }
    let number = |i: usize| -> Result<Option<u32>, String> {
        let parse =
            |field: &&str| field.parse().map_err(|e| format!("--policy {text}: `{field}`: {e}"));
        fields.get(i).map(parse).transpose()
    };
    let default = WaitPolicy::default();
    Ok(WaitPolicy {
        spins: number(0)?.unwrap_or(default.spins),
        yields: number(1)?.unwrap_or(default.yields),
        yield_for: number(2)?.map_or(default.yield_for, |us| Duration::from_micros(us.into())),
        backoff: number(3)?.map_or(default.backoff, |ms| Duration::from_millis(ms.into())),
        ..default
    })
}

/// `policy` as [`parse_policy`] reads it.
pub fn format_policy(p: &WaitPolicy) -> String {
    format!("{}/{}/{}/{}", p.spins, p.yields, p.yield_for.as_micros(), p.backoff.as_millis())
}

/// Writes what the agents read of a round, as the product's world does (only the parts in
/// use, straight into the shared-memory sample).
fn header(out: &mut Observation, round: &Observation) {
    out.round = round.round;
    out.live = round.live;
    out.kind = round.kind;
    out.n_trials = round.n_trials;
}

fn child_world(args: &[String]) -> Result<(), Error> {
    let args = ChildArgs::parse(args)?;
    let world = RunServices::create(&args.run_config()?)?.into_world()?;
    world.wait_for_peers(args.agents, false, START_TIMEOUT)?;
    // One bit per agent slot; `agents` is 1..=64.
    let all = u64::MAX >> (64 - args.agents);
    let mut observation = Observation { live: all, ..Observation::default() };
    let duration = Duration::from_millis(args.value);
    let mut round_trips = Vec::with_capacity(1 << 20);
    let start = Instant::now();
    while start.elapsed() < duration {
        let round = observation.round;
        let sent = Instant::now();
        world.publish_observation(|o| header(o, &observation))?;
        let mut pending = all;
        world.waiter().wait(&format_args!("actions of round {round}"), ROUND_TIMEOUT, || {
            while let Some(action) = world.try_action()? {
                if action.round == round && (action.agent as usize) < args.agents {
                    pending &= !(1u64 << action.agent);
                }
            }
            Ok((pending == 0).then_some(()))
        })?;
        round_trips.push(sent.elapsed().as_nanos() as u64);
        observation.round += 1;
    }
    let seconds = start.elapsed().as_secs_f64();
    observation.kind = ObservationKind::Stop as u8;
    world.publish_observation(|o| header(o, &observation))?;
    round_trips.sort_unstable();
    let percentile =
        |p: usize| round_trips.get(round_trips.len() * p / 100).map_or(0, |ns| ns / 1000);
    println!(
        "rounds={} seconds={seconds:.3} p50_us={} p99_us={}",
        round_trips.len(),
        percentile(50),
        percentile(99)
    );
    Ok(())
}

fn child_agent(args: &[String]) -> Result<(), Error> {
    let args = ChildArgs::parse(args)?;
    let agent = RunServices::open(&args.run_config()?)?.into_agent()?;
    let slot = args.value as u32;
    let mut last_round = 0;
    loop {
        let (round, stop) = agent.waiter().wait(
            &format_args!("the observation after round {last_round}"),
            START_TIMEOUT,
            || {
                Ok(agent
                    .try_observation()?
                    .map(|o| (o.round, o.kind() == Some(ObservationKind::Stop))))
            },
        )?;
        if stop {
            return Ok(());
        }
        // What the product's agent writes besides its trials: the header.
        let mut action = agent.loan_action()?;
        action.round = round;
        action.agent = slot;
        action.n_trials = 0;
        action.send()?;
        last_round = round;
    }
}

/// One barrier run of a world and its agents.
pub struct Measurement {
    pub rounds: u64,
    pub seconds: f64,
    pub p50_us: u64,
    pub p99_us: u64,
    /// User + system CPU of all children together.
    pub cpu_us: f64,
    /// One-minute load average when the measurement started: foreign load skews it.
    pub load1: f64,
}

impl Measurement {
    pub fn rate(&self) -> f64 {
        self.rounds as f64 / self.seconds
    }

    /// The fields both benches print for repeats of one barrier configuration, sorted by
    /// rate: the median's rate, the range, the median's latencies and CPU.
    pub fn describe(sorted: &[&Measurement]) -> String {
        let median = sorted[sorted.len() / 2];
        format!(
            "rounds_per_s={:.0} min={:.0} max={:.0} p50_us={} p99_us={} cpu_us_per_round={:.2} \
             repeats={} load1={:.2}",
            median.rate(),
            sorted[0].rate(),
            sorted[sorted.len() - 1].rate(),
            median.p50_us,
            median.p99_us,
            median.cpu_us / median.rounds.max(1) as f64,
            sorted.len(),
            median.load1,
        )
    }
}

/// Runs the barrier of one world and `agents` agents, all waiting with `policy`, for
/// `seconds`, as run `run_id` (children of this executable, see [`run_child`]).
pub fn measure(
    run_id: &str,
    agents: usize,
    policy: WaitPolicy,
    seconds: f64,
) -> Result<Measurement, Error> {
    let exe = std::env::current_exe()?;
    let spawn = |mode: &str, value: u64, stdout: Stdio| -> Result<Child, Error> {
        let args =
            ChildArgs { run_id: run_id.into(), parent: std::process::id(), agents, value, policy };
        Ok(Command::new(&exe).arg(mode).args(args.to_args()).stdout(stdout).spawn()?)
    };
    let load1 = load1();
    let cpu_before = children_cpu_us();
    let world = spawn("--child-world", (seconds * 1000.0) as u64, Stdio::piped())?;
    let agent_children: Vec<Child> = (0..agents)
        .map(|slot| spawn("--child-agent", slot as u64, Stdio::null()))
        .collect::<Result<_, _>>()?;
    let output = world.wait_with_output()?;
    let mut failed = Vec::new();
    if !output.status.success() {
        failed.push(format!("world: {}", output.status));
    }
    for (slot, mut child) in agent_children.into_iter().enumerate() {
        let status = child.wait()?;
        if !status.success() {
            failed.push(format!("agent {slot}: {status}"));
        }
    }
    let cpu_us = children_cpu_us() - cpu_before;
    // Every child is gone: whatever is left would stay in /dev/shm.
    let leftover = leftover_files(run_id)?.len();
    if leftover > 0 {
        cleanup_run(run_id)?;
        failed.push(format!("{leftover} files left in shared memory (now removed)"));
    }
    let stdout = String::from_utf8_lossy(&output.stdout);
    if !failed.is_empty() {
        return Err(format!(
            "run {run_id}: {} (world stdout: {stdout:?}; stderr above)",
            failed.join(", ")
        )
        .into());
    }
    let field = |name: &str| -> Result<f64, Error> {
        let value = stdout
            .split_whitespace()
            .find_map(|kv| kv.strip_prefix(name)?.strip_prefix('='))
            .ok_or_else(|| format!("world output {stdout:?} lacks {name}"))?;
        Ok(value.parse()?)
    };
    Ok(Measurement {
        rounds: field("rounds")? as u64,
        seconds: field("seconds")?,
        p50_us: field("p50_us")? as u64,
        p99_us: field("p99_us")? as u64,
        cpu_us,
        load1,
    })
}

/// The one-minute load average (NaN if unknown).
pub fn load1() -> f64 {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next()?.parse().ok())
        .unwrap_or(f64::NAN)
}

/// CPU time of every descendant this process has waited for (a waited-for child counts
/// the descendants it waited for in turn).
pub fn children_cpu_us() -> f64 {
    // SAFETY: getrusage fills the zeroed struct it is given.
    let usage = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage);
        usage
    };
    let us = |t: libc::timeval| t.tv_sec as f64 * 1e6 + t.tv_usec as f64;
    us(usage.ru_utime) + us(usage.ru_stime)
}
