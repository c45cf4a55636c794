//! The multi-process transport: one `world` and N `agent` processes over iceoryx2.
//!
//! The supervisor sweeps the stale resources of crashed runs, starts the world (which creates
//! the run's services), opens the run as a reader of episode records, starts the agents, and
//! then records what the world reports until the world exits. Ctrl-C asks the world to stop
//! at the end of the current round; every child is then brought down by the shutdown ladder
//! and what is left of the run in shared memory is removed.

use crate::children::{shut_down, Process};
use crate::config::RunConfig;
use crate::recorder::Recorder;
use crate::run::Outcome;
use anyhow::{bail, Context, Result};
use flockstep_proto::supervisor_to_world::Control;
use flockstep_proto::transport::{
    cleanup_run, sweep_stale_runs, RunConfig as RunIdentity, RunServices, SignalMode,
    SupervisorPorts, TransportError,
};
use std::path::PathBuf;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long the world may take to create the run's services.
const WORLD_START: Duration = Duration::from_secs(30);
/// How long children may take to leave by themselves once the world is done.
const GRACE: Duration = Duration::from_secs(10);

pub fn run(config: &RunConfig, recorder: &mut Recorder, stop: &AtomicBool) -> Result<Outcome> {
    let swept = sweep_stale_runs().context("cleaning stale resources of earlier runs")?;
    if !swept.runs_cleaned.is_empty() {
        tracing::info!(runs = ?swept.runs_cleaned, "removed stale resources of dead runs");
    }
    let logs = config.out.join("logs");
    std::fs::create_dir_all(&logs).with_context(|| format!("cannot create {}", logs.display()))?;
    let mut processes =
        vec![Process::spawn("world", world_command(config)?, &logs.join("world.log"))?];
    let result = open_ports(config, &mut processes[0]).and_then(|ports| {
        for slot in 0..config.uavs {
            let name = format!("UAV{}", slot + 1);
            let log = logs.join(format!("uav{}.log", slot + 1));
            processes.push(Process::spawn(&name, agent_command(config, slot)?, &log)?);
        }
        recorder.set_live(config.uavs);
        supervise(&ports, &mut processes, recorder, stop)
    });
    let forced = shut_down(&mut processes, GRACE)?;
    cleanup_run(&config.run_id).context("removing the run's shared-memory resources")?;
    let mut outcome = result?;
    if !forced.is_empty() {
        outcome.notes.push(format!("had to signal {} to stop", forced.join(", ")));
    }
    Ok(outcome)
}

fn sibling(name: &str) -> Result<PathBuf> {
    let me = std::env::current_exe().context("cannot find the supervisor's own executable")?;
    let path = me.with_file_name(name);
    anyhow::ensure!(path.exists(), "the `{name}` executable is missing next to {}", me.display());
    Ok(path)
}

fn world_command(config: &RunConfig) -> Result<Command> {
    let mut command = Command::new(sibling("world")?);
    command
        .arg("--run-id")
        .arg(&config.run_id)
        .arg("--scenario")
        .arg(&config.scenario_arg)
        .args(["--uavs", &config.uavs.to_string()])
        .args(["--trials", &config.trials.to_string()])
        .args(["--seed", &config.seed.to_string()])
        .args(["--episodes", &config.episodes.train_episodes.to_string()])
        .args(["--eval-episodes", &config.episodes.eval_episodes.to_string()])
        .args(["--tick-cap", &config.episodes.tick_cap.to_string()])
        .args(["--parent-pid", &std::process::id().to_string()]);
    Ok(command)
}

fn agent_command(config: &RunConfig, slot: usize) -> Result<Command> {
    let mut command = Command::new(sibling("agent")?);
    command
        .arg("run")
        .arg("--run-id")
        .arg(&config.run_id)
        .args(["--uav", &(slot + 1).to_string()])
        .arg("--scenario")
        .arg(&config.scenario_arg)
        .args(["--trials", &config.trials.to_string()])
        .args(["--seed", &config.seed.to_string()])
        .args(["--comm", config.comm.name()])
        .args(["--alpha", &config.params.alpha.to_string()])
        .args(["--gamma", &config.params.gamma.to_string()])
        .args(["--epsilon", &config.params.epsilon.to_string()])
        .arg("--out")
        .arg(&config.out)
        .args(["--parent-pid", &std::process::id().to_string()]);
    if let Some(bt) = &config.bt_path {
        command.arg("--bt").arg(bt);
    }
    if let Some(dir) = &config.trace_dir {
        command.arg("--trace").arg(dir.join(format!("uav{}.trace.csv", slot + 1)));
    }
    Ok(command)
}

/// Opens the run once the world has created it; fails at once if the world dies first.
fn open_ports(config: &RunConfig, world: &mut Process) -> Result<SupervisorPorts> {
    let deadline = Instant::now() + WORLD_START;
    loop {
        let mut identity = RunIdentity::new(&config.run_id, SignalMode::Untouched);
        identity.open_timeout = Duration::from_millis(100);
        match RunServices::open(&identity) {
            Ok(services) => return Ok(services.into_supervisor()?),
            Err(TransportError::ServiceMissing { .. }) if Instant::now() < deadline => {}
            Err(e) => return Err(e.into()),
        }
        if let Some(status) = world.status()? {
            bail!(
                "the world process exited ({status}) before the run started: {}",
                world.last_words()
            );
        }
    }
}

/// Records episode reports until the world exits; asks it to stop on Ctrl-C.
fn supervise(
    ports: &SupervisorPorts,
    processes: &mut [Process],
    recorder: &mut Recorder,
    stop: &AtomicBool,
) -> Result<Outcome> {
    let mut stop_sent = false;
    let mut notes = Vec::new();
    let mut failed_agents = vec![false; processes.len()];
    loop {
        while let Some(report) = ports.try_episode()? {
            recorder.record(&report)?;
        }
        recorder.redraw();
        if stop.load(Ordering::Relaxed) && !stop_sent {
            ports.send_control(&Control { stop: 1, ..Control::default() })?;
            stop_sent = true;
        }
        for (i, p) in processes.iter_mut().enumerate().skip(1) {
            if let Some(status) = p.status()? {
                if !status.success() && !failed_agents[i] {
                    failed_agents[i] = true;
                    notes.push(format!("{} exited ({status}): {}", p.name, p.last_words()));
                }
            }
        }
        recorder.set_live(
            processes
                .iter_mut()
                .skip(1)
                .filter_map(|p| p.status().ok())
                .filter(Option::is_none)
                .count(),
        );
        if let Some(status) = processes[0].status()? {
            while let Some(report) = ports.try_episode()? {
                recorder.record(&report)?;
            }
            if !status.success() {
                bail!("the world process failed ({status}): {}", processes[0].last_words());
            }
            return Ok(Outcome { complete: !stop_sent, notes });
        }
        match ports
            .waiter()
            .wait(&"episode records", Duration::from_millis(50), || ports.try_episode())
        {
            Ok(report) => recorder.record(&report)?,
            Err(TransportError::Timeout { .. }) => {}
            Err(e) => return Err(e.into()),
        }
    }
}
