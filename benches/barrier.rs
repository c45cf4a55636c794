//! The raw lockstep barrier over iceoryx2, without any simulation work: one world process
//! and N agent processes exchange an `Observation` and N `Action`s per round through
//! `flockstep_proto::transport`, exactly as a run does. It measures rounds/s, round-trip
//! percentiles and CPU per round for several waiting strategies in one invocation, so their
//! ratios are meaningful on the machine at hand.
//!
//! `cargo bench --bench barrier -- [--agents N].. [--seconds S] [--repeats K] [--policy S/Y]..`
//! (S spins, Y yields) prints one line per configuration on stdout, e.g.
//! `barrier agents=2 strategy=yield-block spins=0 yields=16 rounds_per_s=... vs_first=...`.
//! Without `--bench` (as under `cargo test --all-targets`) it does a short smoke run. The
//! binary re-executes itself (`--child-world`, `--child-agent`) for the processes.

use flockstep_proto::transport::{
    cleanup_run, exit_with_parent, leftover_files, RunConfig, RunServices, SignalMode, WaitPolicy,
};
use flockstep_proto::{Action, Observation, ObservationKind, MAX_AGENTS};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A round slower than this means a process is gone, not slow.
const ROUND_TIMEOUT: Duration = Duration::from_secs(5);
/// Time for all agents to start and connect.
const START_TIMEOUT: Duration = Duration::from_secs(30);

type Error = Box<dyn std::error::Error>;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("--child-world") => child_world(&args[1..]),
        Some("--child-agent") => child_agent(&args[1..]),
        _ => parent(&args),
    };
    if let Err(e) = result {
        eprintln!("barrier: {e}");
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
        let [run_id, parent, agents, value, spins, yields] = args else {
            return Err(format!("child arguments: expected 6, got {args:?}").into());
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
            policy: WaitPolicy {
                spins: spins.parse()?,
                yields: yields.parse()?,
                ..WaitPolicy::default()
            },
        })
    }

    fn to_args(&self) -> Vec<String> {
        let p = &self.policy;
        [&self.run_id, &self.parent.to_string(), &self.agents.to_string(), &self.value.to_string()]
            .into_iter()
            .cloned()
            .chain([p.spins.to_string(), p.yields.to_string()])
            .collect()
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

fn child_world(args: &[String]) -> Result<(), Error> {
    let args = ChildArgs::parse(args)?;
    let world = RunServices::create(&args.run_config()?)?.into_world()?;
    world.wait_for_peers(args.agents, false, START_TIMEOUT)?;
    // One bit per agent slot; `agents` is 1..=64.
    let all = u64::MAX >> (64 - args.agents);
    let mut observation = Box::new(Observation { live: all, ..Observation::default() });
    let duration = Duration::from_millis(args.value);
    let mut round_trips = Vec::with_capacity(1 << 20);
    let start = Instant::now();
    while start.elapsed() < duration {
        let round = observation.round;
        let sent = Instant::now();
        world.publish_observation(&observation)?;
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
    world.publish_observation(&observation)?;
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
    let mut action = Box::new(Action::new(args.value as usize));
    loop {
        let (round, stop) = agent.waiter().wait(
            &format_args!("the observation after round {}", action.round),
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
        action.round = round;
        agent.publish_action(&action)?;
    }
}

fn parent(args: &[String]) -> Result<(), Error> {
    // `cargo bench` passes `--bench`; `cargo test --all-targets` runs this binary without it,
    // and then a short smoke run keeps the test suite fast while still exercising the barrier.
    let full = args.iter().any(|a| a == "--bench");
    let mut agents = Vec::new();
    let mut policies = Vec::new();
    let (mut seconds, mut repeats) = if full { (1.0_f64, 3_usize) } else { (0.2, 1) };
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{arg} needs a value"));
        match arg.as_str() {
            "--agents" => agents.push(value()?.parse::<usize>()?),
            "--seconds" => seconds = value()?.parse()?,
            "--repeats" => repeats = value()?.parse::<usize>()?.max(1),
            "--policy" => {
                let text = value()?;
                let (spins, yields) = text.split_once('/').ok_or("--policy takes SPINS/YIELDS")?;
                policies.push(WaitPolicy {
                    spins: spins.parse()?,
                    yields: yields.parse()?,
                    ..WaitPolicy::default()
                });
            }
            // Other harness flags mean nothing here.
            _ => {}
        }
    }
    if agents.is_empty() {
        agents = if full { vec![2, 8] } else { vec![2] };
    }
    if policies.is_empty() {
        // Blocking at once, the tuned default, and the default with a spin phase in front.
        policies = vec![
            WaitPolicy::BLOCK,
            WaitPolicy::default(),
            WaitPolicy { spins: 100, ..WaitPolicy::default() },
        ];
    }
    if let Some(n) = agents.iter().find(|&&n| n == 0 || n > MAX_AGENTS) {
        return Err(format!("--agents {n}: must be 1..={MAX_AGENTS}").into());
    }
    for &n in &agents {
        // Interleaved repeats: the machine is shared, so a burst of foreign load hits every
        // policy alike instead of skewing one, and the median discards the outliers.
        let mut runs: Vec<Vec<Measurement>> = policies.iter().map(|_| Vec::new()).collect();
        for repeat in 0..repeats {
            for (i, policy) in policies.iter().enumerate() {
                let run_id = format!("bench-{}-{n}-{i}-{repeat}", std::process::id());
                runs[i].push(measure(&run_id, n, *policy, seconds)?);
            }
        }
        let mut baseline = None;
        for (policy, mut measured) in policies.iter().zip(runs) {
            measured.sort_by(|a, b| a.rate().total_cmp(&b.rate()));
            let median = &measured[measured.len() / 2];
            let base = *baseline.get_or_insert(median.rate());
            println!(
                "barrier agents={n} strategy={} spins={} yields={} rounds_per_s={:.0} \
                 vs_first={:.2} min={:.0} max={:.0} p50_us={} p99_us={} cpu_us_per_round={:.1} \
                 repeats={repeats} load1={:.2} leftover_files={}",
                strategy(policy),
                policy.spins,
                policy.yields,
                median.rate(),
                median.rate() / base,
                measured[0].rate(),
                measured[measured.len() - 1].rate(),
                median.p50_us,
                median.p99_us,
                median.cpu_us / median.rounds.max(1) as f64,
                median.load1,
                measured.iter().map(|m| m.leftover).sum::<usize>(),
            );
        }
    }
    Ok(())
}

fn strategy(policy: &WaitPolicy) -> &'static str {
    match (policy.spins > 0, policy.yields > 0) {
        (false, false) => "block",
        (true, false) => "spin-block",
        (false, true) => "yield-block",
        (true, true) => "spin-yield-block",
    }
}

struct Measurement {
    rounds: u64,
    seconds: f64,
    p50_us: u64,
    p99_us: u64,
    /// User + system CPU of all children together.
    cpu_us: f64,
    /// Files of the run found after every child exited (then removed).
    leftover: usize,
    /// One-minute load average when the measurement started: foreign load skews it.
    load1: f64,
}

impl Measurement {
    fn rate(&self) -> f64 {
        self.rounds as f64 / self.seconds
    }
}

fn measure(
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
    let load1 = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next()?.parse().ok())
        .unwrap_or(f64::NAN);
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
        leftover,
        load1,
    })
}

/// CPU time of every child this process has waited for.
fn children_cpu_us() -> f64 {
    // SAFETY: getrusage fills the zeroed struct it is given.
    let usage = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage);
        usage
    };
    let us = |t: libc::timeval| t.tv_sec as f64 * 1e6 + t.tv_usec as f64;
    us(usage.ru_utime) + us(usage.ru_stime)
}
