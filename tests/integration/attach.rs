//! `agent --attach` asking for a route it cannot have: the world refuses it with the reason,
//! and the agent exits at once saying it, while the run goes on.

use crate::harness::{
    assert_nothing_left, run_id, scratch, wait_for_agent, world_log, Spawned, AGENT, SUPERVISOR,
};
use std::time::{Duration, Instant};

/// Bound of one process here: only a hang reaches it.
const BOUND: Duration = Duration::from_secs(120);

/// A run of two starting agents on `scenario` that lasts until it is stopped (Ctrl-C).
fn run_until_stopped(id: &str, out: &str, scenario: &str) -> Spawned {
    let args = ["--transport", "shm", "--run-id", id, "--out", out, "--quiet", "--scenario"];
    let rest = [scenario, "--uavs", "2", "--episodes", "10000000", "--trials", "1"];
    Spawned::start(SUPERVISOR, &[&args[..], &rest[..]].concat())
}

/// Before, an agent that asked for a route of its own (`--uav N`) ignored the world's
/// refusal and asked again until its 30 s wait ran out, then said only that it timed out
/// waiting for admission. Now each refusal ends it at once with one line naming the flag
/// and the problem.
#[test]
fn an_agent_asking_for_a_route_it_cannot_have_exits_at_once_saying_why() {
    let dir = scratch();
    let (id, out) = (run_id("refused"), dir.path().display().to_string());
    // s3 has two routes, both taken by the starting agents; the run lasts until stopped.
    let run = run_until_stopped(&id, &out, "s3");
    // Both routes are taken once the last starting agent runs.
    wait_for_agent(&id, 2);
    let cases = [
        (vec!["--uav", "9"], format!("--uav 9: run `{id}` has 2 routes")),
        (vec!["--uav", "2"], format!("--uav 2: route 2 of run `{id}` is taken by another agent")),
        (
            vec![],
            format!(
                "run `{id}`: the world refused this agent: every route of the scenario is taken"
            ),
        ),
    ];
    for (flags, expected) in cases {
        let args = [&["--attach", id.as_str(), "--out", out.as_str()][..], &flags].concat();
        // The refusal itself, not the 30 s wait for admission running out, ends it.
        let (output, report) = Spawned::start(AGENT, &args).finish(BOUND);
        assert!(!output.status.success(), "expected a refusal\n{report}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(stderr.trim(), format!("agent: error: {expected}"), "\n{report}");
    }
    run.interrupt();
    let (status, report) = run.finish(BOUND);
    assert_eq!(status.status.code(), Some(130), "the run ends only on Ctrl-C\n{report}");
    let log = world_log(dir.path());
    for why in ["the scenario has no such route", "the route asked for is taken by another agent"] {
        assert!(log.contains(&format!("join refused: {why}")), "{why}:\n{log}");
    }
    assert_nothing_left(&id);
}

/// `agent --attach` to a run id that no world serves waits `--world-timeout-ms` for the
/// run's services, then exits with one line naming the run id and the flag. Before, it
/// waited a fixed 10 s whatever the flag said: a second timeout a second longer must make
/// the wait at least a second longer (no bound on how long either takes).
#[test]
fn attaching_to_a_run_that_is_not_running_waits_the_world_timeout() {
    let dir = scratch();
    let out = dir.path().display().to_string();
    let waited = |timeout: Duration| {
        let id = run_id("absent");
        let timeout_ms = timeout.as_millis().to_string();
        let args = ["--attach", &id, "--out", &out, "--world-timeout-ms", &timeout_ms];
        let started = Instant::now();
        let (output, report) = Spawned::start(AGENT, &args).finish(BOUND);
        let waited = started.elapsed();
        assert!(!output.status.success(), "expected a failure\n{report}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        let expected = format!(
            "agent: error: run `{id}`: not running: no world created its services \
             within {timeout:?} (--world-timeout-ms)"
        );
        assert_eq!(stderr.trim(), expected, "\n{report}");
        // At least the timeout it was given (`waited` also holds the process's start).
        assert!(waited >= timeout, "gave up after {waited:?}, before {timeout:?}\n{report}");
        assert_nothing_left(&id);
        waited
    };
    let (short, long) = (Duration::from_millis(300), Duration::from_millis(1300));
    let (short_wait, long_wait) = (waited(short), waited(long));
    assert!(
        long_wait.saturating_sub(short_wait) >= long - short - Duration::from_millis(100),
        "a {long:?} timeout waited {long_wait:?}, a {short:?} one {short_wait:?}"
    );
}

/// An attaching agent whose `--resume` names no directory, or whose `--bt` tree is bad,
/// exits saying so before it asks to join, and before it waits for a run that is not there:
/// before, it was admitted on the free route first and the run noted it as an agent that
/// attached and left (or, with no run, it said only that the run was not running, after
/// `--world-timeout-ms`).
#[test]
fn an_agent_with_bad_inputs_of_its_own_exits_before_it_joins() {
    let dir = scratch();
    let (id, out) = (run_id("bad-inputs"), dir.path().display().to_string());
    // s4 has three routes: the third is free for an attaching agent.
    let run = run_until_stopped(&id, &out, "s4");
    wait_for_agent(&id, 2);
    let missing = dir.path().join("no-such-run").display().to_string();
    let tree = dir.path().join("bad.bt");
    std::fs::write(&tree, "not a tree(").unwrap();
    let tree = tree.display().to_string();
    let absent = run_id("bad-inputs-absent");
    for (run_id, flag, value, error) in [
        (&id, "--resume", &missing, format!("--resume {missing}: no such directory")),
        (&id, "--bt", &tree, tree.clone()),
        (&absent, "--bt", &tree, tree.clone()),
    ] {
        let args = ["--attach", run_id, "--out", &out, flag, value, "--world-timeout-ms", "60000"];
        // Well within the minute it would wait for a run that is not there.
        let (output, report) = Spawned::start(AGENT, &args).finish(Duration::from_secs(30));
        assert!(!output.status.success(), "expected a refusal\n{report}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        let stderr = stderr.trim();
        assert!(stderr.starts_with("agent: error: ") && stderr.contains(&error), "{report}");
        assert_eq!(stderr.lines().count(), 1, "{report}");
    }
    run.interrupt();
    let (status, report) = run.finish(BOUND);
    assert_eq!(status.status.code(), Some(130), "the run ends only on Ctrl-C\n{report}");
    let s = crate::harness::summary(dir.path());
    assert_eq!(s["notes"], serde_json::json!([]), "{s:#}");
    assert_nothing_left(&id);
}
