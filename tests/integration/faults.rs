//! Membership and faults (issue 4) with real processes: attach, SIGKILLed agents, restart
//! from snapshots, Ctrl-C, a killed world, and a rogue publisher. Every wait is bounded; a
//! run that does not finish in time fails the test with how far it got.

use crate::harness::{
    agent_pids, assert_nothing_left, assert_same_file, catches, comm_entry, episode_rows,
    first_gap, mean_length, notes, read, read_trace, run_fail, run_id, scratch, signal, summary,
    supervise, wait_for_agent, wait_for_records, wait_until, words, world_log, world_pids, Spawned,
    AGENT, WORLD,
};
use flockstep_agents::node::EXIT_WORLD_GONE;
use flockstep_agents::snapshot::{snapshot_path, Snapshot};
use flockstep_proto::supervisor_to_world::Control;
use flockstep_proto::transport::{
    iceoryx_root, process_of_node, RunConfig, RunServices, SignalMode,
};
use flockstep_proto::{Action, JoinRequest, ANY_SLOT};
use flockstep_supervisor::interrupt::HURRY_AFTER;
use std::os::unix::process::ExitStatusExt;
use std::time::{Duration, Instant};

const DEADLOCK: Duration = Duration::from_secs(120);

/// A small deterministic generator for "random" kill times (the tests must be repeatable).
struct Lcg(u64);

impl Lcg {
    fn below(&mut self, bound: u64) -> u64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 33) % bound
    }
}

fn run_args<'a>(id: &'a str, out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["--transport", "shm", "--run-id", id, "--out", out, "--quiet"];
    args.extend_from_slice(extra);
    args
}

/// The run id is in no output of a run given `--out`: the supervisor says it at the start,
/// and how another agent joins if routes are free; at the end it says how the run went;
/// `--quiet` says nothing.
#[test]
fn a_run_names_its_id_and_how_to_attach_unless_quiet() {
    let stderr_of = |scenario: &str, quiet: bool| {
        let dir = scratch();
        let (id, out) = (run_id("announce"), dir.path().display().to_string());
        let mut args = run_args(&id, &out, &["--scenario", scenario, "--uavs", "2"]);
        args.extend(["--episodes", "300", "--trials", "1", "--eval-episodes", "0"]);
        args.retain(|&a| quiet || a != "--quiet");
        let output = crate::harness::run_ok(crate::harness::SUPERVISOR, &args);
        assert_nothing_left(&id);
        let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
        (id, out, stderr)
    };
    let (id, out, stderr) = stderr_of("s4", false);
    assert!(
        stderr.contains(&format!("supervisor: run {id}: a world and 2 agents, results in {out}")),
        "{stderr}"
    );
    assert!(stderr.contains("1 route free; another agent joins with: "), "{stderr}");
    assert!(stderr.contains(&format!(" agent --attach {id}\n")), "{stderr}");
    let (id, _, stderr) = stderr_of("s3", false);
    assert!(stderr.contains(&format!("supervisor: run {id}")), "{stderr}");
    assert!(!stderr.contains("--attach"), "s3 has no free route:\n{stderr}");
    // At its end it says how it went: `--eval-episodes 0` flies no greedy episode.
    assert!(stderr.contains("supervisor: finished in "), "{stderr}");
    for uav in ["UAV1", "UAV2"] {
        let line = format!("supervisor: {uav} flew no greedy episode; training mean ");
        assert!(stderr.contains(&line), "{stderr}");
    }
    let (_, _, stderr) = stderr_of("s4", true);
    assert!(!stderr.contains("supervisor:"), "--quiet:\n{stderr}");
}

#[test]
fn an_attached_agent_is_admitted_at_an_episode_boundary_learns_and_is_heard() {
    let dir = scratch();
    let traces = dir.path().join("traces");
    std::fs::create_dir_all(&traces).expect("trace dir");
    let (id, out, trace_dir) =
        (run_id("attach"), dir.path().display().to_string(), traces.display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &[
            "--scenario",
            "s4",
            "--uavs",
            "2",
            "--episodes",
            "6000",
            "--trials",
            "2",
            "--seed",
            "41",
            "--trace-dir",
            &trace_dir,
        ],
    ));
    // The run is under way once its last starting agent is.
    wait_for_agent(&id, 2);
    let attached_trace = traces.join("uav3.trace.csv");
    let (attached, attach_report) = Spawned::start(
        AGENT,
        &["--attach", &id, "--out", &out, "--trace", &attached_trace.display().to_string()],
    )
    .finish(DEADLOCK);
    assert!(attached.status.success(), "{attach_report}");
    // The one who started it is told that it is done, and where its tables are.
    let said = String::from_utf8_lossy(&attached.stderr);
    let expected = format!("agent: run `{id}` ended; the Q-tables of UAV3 are in {out}/qtables");
    assert!(said.lines().any(|line| line == expected), "{attach_report}");
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let rows = episode_rows(dir.path());
    let attached_rounds = read_trace(&attached_trace);
    for trial in 0..2 {
        let third: Vec<[u64; 6]> =
            rows.iter().filter(|r| r[0] == trial && r[1] == 3).copied().collect();
        assert!(
            third.len() > 200,
            "trial {trial}: UAV3 took part in only {} episodes",
            third.len()
        );
        let first = &third[0];
        assert!(first[2] > 0, "UAV3 was there from the start: it did not attach");
        // Admitted at an episode boundary: the world counts it in from the first tick of the
        // episode its first record is of, and not before.
        let joined = attached_rounds
            .iter()
            .find(|r| r.trial == trial && r.member)
            .unwrap_or_else(|| panic!("trial {trial}: UAV3's trace has no round as a member"));
        assert_eq!(
            (joined.episode, joined.episode_tick),
            (first[2], 0),
            "trial {trial}: UAV3 joined episode {} at its tick {} (round {}); its first \
             record is of episode {}",
            joined.episode,
            joined.episode_tick,
            joined.round,
            first[2]
        );
        // It learns: its last episodes are shorter than its first ones.
        let (head, tail) = (mean_length(&third[..100]), mean_length(&third[third.len() - 100..]));
        assert!(tail < head, "trial {trial}: UAV3 did not learn ({head} -> {tail})");
    }
    // Its curve is placed at the trials' episode numbers: from the first episode every
    // trial has for it (it used to start at 0), to the last.
    let first_in_every_trial = (0..2)
        .map(|trial| rows.iter().find(|r| r[0] == trial && r[1] == 3).expect("a UAV3 row")[2])
        .max()
        .expect("two trials");
    let curve = String::from_utf8(read(&dir.path().join("curve.csv"))).expect("UTF-8");
    let episodes: Vec<u64> = curve
        .lines()
        .skip(1)
        .filter(|l| l.split(',').nth(1) == Some("3"))
        .map(|l| l.split(',').next().and_then(|e| e.parse().ok()).expect("an episode number"))
        .collect();
    assert_eq!(episodes.first(), Some(&first_in_every_trial), "UAV3's curve starts elsewhere");
    assert_eq!(episodes.last(), Some(&5999), "UAV3's curve ends elsewhere");
    // The summary names the agent that attached.
    let agents = summary(dir.path())["agents"].clone();
    assert_eq!(agents[2]["uav"], 3, "{agents:#}");
    assert_eq!(agents[2]["attached"], true, "{agents:#}");
    assert_eq!(agents[0]["attached"], false, "{agents:#}");
    // Its peers hear it: UAV1's communication state gains entries for route 3, which sit
    // after UAV2's 5 entries (bits 10..20 of the first word).
    let trace = read_trace(&traces.join("uav1.trace.csv"));
    let heard = trace.iter().filter(|r| (5..10).any(|k| comm_entry(&r.comm, k) != 0)).count();
    assert!(heard > 100, "UAV1 heard UAV3 in only {heard} rounds");
    assert_nothing_left(&id);
}

#[test]
fn sigkilled_agents_never_deadlock_the_survivors() {
    let mut random = Lcg(7);
    for attempt in 0..20 {
        let dir = scratch();
        let (id, out) = (run_id(&format!("kill{attempt}")), dir.path().display().to_string());
        let run = Spawned::supervisor(&run_args(
            &id,
            &out,
            &words(
                "--scenario s3 --uavs 2 --episodes 2000 --trials 1 --seed 51 --eval-episodes 200",
            ),
        ));
        wait_for_agent(&id, 2);
        // At a random point of the training, which writes about 80 kB of records here (in
        // steps of the writer's 8 KiB buffer): between none and half of them, so in the
        // first few thousand rounds at the earliest (agents killed as they start:
        // `agents_killed_as_they_start_never_hang_the_run`).
        wait_for_records(&dir.path().join("episodes.csv"), random.below(40_000), DEADLOCK);
        let uav2 = agent_pids(&id, 2);
        assert!(!uav2.is_empty(), "attempt {attempt}: UAV2 had already left, half-way through");
        for pid in uav2 {
            signal(pid, libc::SIGKILL);
        }
        let (status, report) = run.finish(DEADLOCK);
        assert!(status.status.success(), "attempt {attempt}\n{report}");
        let s = summary(dir.path());
        assert_eq!(s["complete"], true, "attempt {attempt}: {s:#}");
        // It ran to its end, without UAV2 since it was killed.
        assert_eq!(s["every_agent_flew_every_episode"], false, "attempt {attempt}: {s:#}");
        let notes = s["notes"].to_string();
        assert!(
            notes.contains("UAV2 failed") && notes.contains("SIGKILL"),
            "attempt {attempt}: the loss is not reported: {notes}"
        );
        let uav1 = episode_rows(dir.path()).iter().filter(|r| r[1] == 1).count();
        assert_eq!(uav1, 2000, "attempt {attempt}: the survivor did not finish its budget");
        assert_nothing_left(&id);
    }
}

/// An agent killed as it starts, while iceoryx2 creates its node, ports and services, can
/// leave files iceoryx2 never removes, and one kind made the world, or the next run's
/// start-up sweep, wait for good (an empty segment: 4 of about 1 000 such runs hung). Every
/// run completes and leaves nothing. Before `cleanup_run` removed those files, 6 of 80 runs
/// left some.
#[test]
fn agents_killed_as_they_start_never_hang_the_run() {
    for attempt in 0..40 {
        let dir = scratch();
        let (id, out) = (run_id(&format!("startkill{attempt}")), dir.path().display().to_string());
        let mut run = Spawned::supervisor(&run_args(
            &id,
            &out,
            &words("--scenario s3 --uavs 2 --episodes 300 --trials 1 --seed 55 --eval-episodes 0"),
        ));
        // A run that ended first is reported below, with its output.
        wait_until(&format!("UAV2 of run {id} to start"), DEADLOCK, || {
            !agent_pids(&id, 2).is_empty() || run.has_exited()
        });
        std::thread::sleep(Duration::from_millis(attempt));
        let killed = agent_pids(&id, 2);
        for &pid in &killed {
            signal(pid, libc::SIGKILL);
        }
        let (status, report) = run.finish(DEADLOCK);
        assert!(status.status.success(), "attempt {attempt}\n{report}");
        assert_nothing_left(&id);
        // Nothing names the run in an empty node directory, but its id names the process.
        let nodes = std::fs::read_dir(iceoryx_root().join("nodes")).expect("the node directory");
        let of_killed: Vec<_> = nodes
            .flatten()
            .filter(|node| {
                let node_id = node.file_name().to_string_lossy().parse::<u128>();
                node_id.is_ok_and(|node_id| killed.contains(&process_of_node(node_id)))
            })
            .map(|node| node.path())
            .collect();
        assert!(of_killed.is_empty(), "attempt {attempt}: UAV2 left {of_killed:?}");
    }
}

/// Before it asks to join, only the supervisor can tell that an agent died: the world must
/// not wait for it until its start-up timeout (30 s) and then fail the run.
#[test]
fn an_agent_that_dies_before_joining_does_not_hold_up_the_run() {
    let dir = scratch();
    let (id, out) = (run_id("prejoin"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 500 --trials 1 --seed 52 --fault 2=crash-before-join"),
    ));
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let log = world_log(dir.path());
    assert!(log.contains("its process ended before it asked to join uav=2"), "{log}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], true, "{s:#}");
    assert!(s["notes"].to_string().contains("UAV2 failed"), "the loss is not reported: {s:#}");
    let rows = episode_rows(dir.path());
    assert_eq!(rows.iter().filter(|r| r[1] == 1).count(), 500, "UAV1 did not finish its budget");
    assert_eq!(rows.iter().filter(|r| r[1] == 2).count(), 0, "UAV2 never flew");
    assert_nothing_left(&id);
}

/// A restart of an agent that failed before it joined: no report ever showed the slot live
/// for the predecessor, so the supervisor must take the restart for admitted when the slot
/// turns live; with no snapshot yet it starts from empty tables, and the note says so.
#[test]
fn an_agent_that_dies_before_joining_is_restarted_from_empty_tables() {
    let dir = scratch();
    let (id, out) = (run_id("prejoin-restart"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 2000 --trials 2 --seed 54 --fault 2=crash-before-join --restart on-failure"),
    ));
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], true, "{s:#}");
    let notes = notes(&s);
    assert_eq!(notes.len(), 2, "one failure, one restart: {notes:?}");
    assert!(notes[0].starts_with("UAV2 failed") && notes[0].contains("SIGABRT"), "{notes:?}");
    assert_eq!(
        notes[1],
        "UAV2 restarted from its latest snapshot; trial(s) 0, 1 had none yet and start from \
         empty tables"
    );
    let rows = episode_rows(dir.path());
    for trial in 0..2 {
        let flown = |agent| rows.iter().filter(|r| r[0] == trial && r[1] == agent).count();
        assert_eq!(flown(1), 2000, "trial {trial}: UAV1 did not finish its budget");
        assert!(flown(2) > 1000, "trial {trial}: the restart flew {} episodes", flown(2));
    }
    for trial in 0..2 {
        snapshot(dir.path(), 2, trial);
    }
    assert_nothing_left(&id);
}

/// When every agent fails, the world's own error ("every agent is gone") says nothing of why:
/// the supervisor's error names the first agent to fail, and the results are still written.
#[test]
fn when_every_agent_fails_the_error_names_the_first_one_and_why() {
    for (fault, world_says) in [
        ("crash-before-join", "every starting agent ended before it asked to join"),
        ("crash-at-round=5", "every agent is gone"),
    ] {
        let dir = scratch();
        let (id, out) = (run_id("allfail"), dir.path().display().to_string());
        let faults = [format!("1={fault}"), format!("2={fault}")];
        let extra = words("--scenario s3 --uavs 2 --episodes 500 --trials 1 --seed 53");
        let extra = [&extra[..], &["--fault", &faults[0], "--fault", &faults[1]]].concat();
        let run = Spawned::supervisor(&run_args(&id, &out, &extra));
        let (status, report) = run.finish(DEADLOCK);
        assert_eq!(status.status.code(), Some(1), "{fault}: {report}");
        let stderr = String::from_utf8_lossy(&status.stderr);
        let last = stderr.lines().last().unwrap_or_default();
        assert!(last.starts_with("supervisor: error: the world process failed"), "{fault}: {last}");
        assert!(last.contains(world_says), "{fault}: {last}");
        assert!(
            last.contains("first to fail: UAV") && last.contains("SIGABRT"),
            "{fault}: the agents' failure is not named: {last}"
        );
        let s = summary(dir.path());
        assert_eq!(s["complete"], false, "{fault}: {s:#}");
        assert_nothing_left(&id);
    }
}

#[test]
fn a_restarted_agent_goes_on_from_its_snapshot() {
    let dir = scratch();
    let (id, out) = (run_id("restart"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 12000 --trials 1 --seed 61 --restart on-failure --snapshot-every 200"),
    ));
    wait_until("UAV1's snapshot after 3000 episodes", Duration::from_secs(60), || {
        saved(dir.path(), 1, 0).is_some_and(|s| s.episodes >= 3000)
    });
    for pid in agent_pids(&id, 1) {
        signal(pid, libc::SIGKILL);
    }
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let notes = summary(dir.path())["notes"].to_string();
    assert!(notes.contains("UAV1 restarted"), "{notes}");
    let uav1: Vec<[u64; 6]> = episode_rows(dir.path()).into_iter().filter(|r| r[1] == 1).collect();
    let gap = first_gap(&uav1).expect("a gap where UAV1 was down");
    let (start, before, after) = (
        mean_length(&uav1[..200]),
        mean_length(&uav1[gap - 200..gap]),
        mean_length(&uav1[gap + 1..gap + 201]),
    );
    assert!(
        after < 2.0 * before && after < start / 2.0,
        "restarted from scratch? first {start}, before the kill {before}, after {after}"
    );
    assert_nothing_left(&id);
}

#[test]
fn ctrl_c_stops_cleanly_with_partial_results() {
    let mut random = Lcg(11);
    // Attempts stopped once rounds had run, whose final Q-tables are checked.
    let mut with_tables = 0;
    for attempt in 0..10 {
        let dir = scratch();
        let (id, out) = (run_id(&format!("int{attempt}")), dir.path().display().to_string());
        let run = Spawned::supervisor(&run_args(
            &id,
            &out,
            &words("--scenario s3 --uavs 2 --episodes 50000 --trials 2 --seed 71"),
        ));
        // Anywhere from start-up (the world not yet up) to well into training.
        std::thread::sleep(Duration::from_millis(random.below(1500)));
        run.interrupt();
        let (status, report) = run.finish(DEADLOCK);
        assert_eq!(
            status.status.code(),
            Some(130),
            "attempt {attempt}: Ctrl-C exits with 130\n{report}"
        );
        let s = summary(dir.path());
        assert_eq!(s["complete"], false, "attempt {attempt}");
        let rows = episode_rows(dir.path());
        assert!(rows.len() < 200_000, "attempt {attempt}: the run was not stopped");
        // Its curve is smoothed over a hundredth of what it trained, not of the 50 000
        // episodes it planned.
        let trained = rows.iter().map(|row| row[2] + 1).max().unwrap_or(0);
        assert_eq!(s["smoothing_window"], (trained / 100).max(1), "attempt {attempt}: {s:#}");
        // No agent was lost: each flew every episode the run flew before it stopped.
        assert_eq!(s["every_agent_flew_every_episode"], true, "attempt {attempt}: {s:#}");
        let rounds = s["rounds"].as_u64().unwrap_or_else(|| panic!("no rounds in {s:#}"));
        if rounds > 0 {
            with_tables += 1;
            for (uav, trial) in [(1, 0), (2, 1)] {
                snapshot(dir.path(), uav, trial);
            }
        }
        assert_nothing_left(&id);
    }
    assert!(with_tables > 0, "no attempt was stopped after a round: no final tables checked");
}

#[test]
fn a_killed_world_ends_the_run_at_once_and_keeps_the_results() {
    let dir = scratch();
    let (id, out) = (run_id("worldkill"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 50000 --trials 2 --seed 81"),
    ));
    let mut world = Vec::new();
    wait_until("episodes to be recorded by a running world", Duration::from_secs(30), || {
        world = world_pids(&id);
        std::fs::metadata(dir.path().join("episodes.csv")).is_ok_and(|m| m.len() > 100)
            && !world.is_empty()
    });
    for &pid in &world {
        signal(pid, libc::SIGKILL);
    }
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(1), "{report}");
    // Killed, it said nothing about why: its last log line is not offered as the reason.
    let stderr = String::from_utf8_lossy(&status.stderr);
    let said = "the world process failed (signal: 9 (SIGKILL)): killed, with no error in its log";
    assert!(stderr.contains(said), "{report}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], false);
    assert!(!episode_rows(dir.path()).is_empty(), "the results collected so far are lost");
    // The agents, stopped with the world gone, saved what they had learned (long before
    // their first periodic snapshot, due after 10 000 episodes).
    for uav in 1..=2 {
        for trial in 0..2 {
            snapshot(dir.path(), uav, trial);
        }
        let log = agent_log(dir.path(), uav);
        assert!(log.contains("its Q-tables are saved in"), "UAV{uav}: {log}");
    }
    assert_nothing_left(&id);
}

/// A world started by hand, with no supervisor to sweep after it, that is SIGKILLed leaves
/// its services behind. A world started again with its run id removes them and goes on
/// (here to wait for agents that never come), instead of refusing the run id as a live
/// run's (it did: "service ... already exists: another live run uses this run id").
#[test]
fn a_world_started_after_a_killed_one_of_its_run_removes_what_it_left() {
    let id = run_id("reworld");
    let args = |startup_ms: &'static str| {
        let mut args = words(
            "--scenario s1 --uavs 1 --trials 1 --seed 1 --episodes 10 --eval-episodes 0 \
             --tick-cap 100 --comm none --alpha 0.1 --gamma 0.9 --epsilon 0.1",
        );
        args.extend(["--run-id", &id, "--startup-timeout-ms", startup_ms]);
        args
    };
    let first = Spawned::start(WORLD, &args("60000"));
    wait_until("the first world to create its services", Duration::from_secs(30), || {
        RunServices::is_served(&id).expect("look for the run's services")
    });
    signal(first.pid(), libc::SIGKILL);
    let (killed, _) = first.finish(Duration::from_secs(10));
    assert_eq!(killed.status.signal(), Some(libc::SIGKILL));

    let (_, report) = run_fail(WORLD, &args("200"));
    // Past creating the services: it waited for its peers, who never came.
    assert!(report.contains("peers did not connect within"), "{report}");
    assert_nothing_left(&id);
}

/// An attached agent is no child of the supervisor, which cannot bring it down when the
/// world dies: it notices by itself that the world's process is gone, long before its
/// `--world-timeout-ms` (it used to wait that out, 30 s by default), and leaves with its
/// tables saved.
#[test]
fn an_attached_agent_notices_a_killed_world_at_once_and_keeps_its_tables() {
    let dir = scratch();
    let (id, out) = (run_id("attachkill"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s4 --uavs 2 --episodes 1000000 --trials 2 --seed 43"),
    ));
    wait_for_agent(&id, 2);
    let world = world_pids(&id);
    let &[world] = &world[..] else { panic!("run {id} has world processes {world:?}, not one") };
    let attached =
        Spawned::start(AGENT, &["--attach", &id, "--out", &out, "--world-timeout-ms", "600000"]);
    wait_until("UAV3 to fly episodes", Duration::from_secs(30), || rows_of(dir.path(), 3) > 0);
    signal(world, libc::SIGKILL);
    let (left, report) = attached.finish(DEADLOCK);
    assert_eq!(left.status.code(), Some(EXIT_WORLD_GONE.into()), "{report}");
    let said = String::from_utf8_lossy(&left.stderr);
    let gone = format!("the world (process {world}) is gone");
    assert!(said.contains(&gone) && said.contains("its Q-tables are saved in"), "{report}");
    for trial in 0..2 {
        let saved = snapshot(dir.path(), 3, trial);
        assert_eq!((saved.slot, saved.trial), (2, trial as u32));
    }
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(1), "{report}");
    assert_nothing_left(&id);
}

/// Agents that left because the world was gone are not what failed the run, even when the
/// supervisor sees them gone before it sees the world (here it is stopped meanwhile, as a
/// busy or paused supervisor would be late): the error names the world alone, no agent
/// failure is noted and none is restarted. Before, the run's error said "first to fail:
/// UAV1 ... the world is gone", and `--restart on-failure` could restart it.
#[test]
fn agents_that_leave_a_killed_world_are_not_blamed_or_restarted() {
    let dir = scratch();
    let (id, out) = (run_id("worldgone"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 1000000 --trials 2 --restart on-failure"),
    ));
    let agents: Vec<u32> = (1..=2).flat_map(|uav| wait_for_agent(&id, uav)).collect();
    wait_for_records(&dir.path().join("episodes.csv"), 1000, DEADLOCK);
    signal(run.pid(), libc::SIGSTOP);
    for pid in world_pids(&id) {
        signal(pid, libc::SIGKILL);
    }
    // Both agents leave by themselves; their parent, stopped, has not reaped them.
    wait_until("both agents to leave the killed world", Duration::from_secs(30), || {
        agents.iter().all(|&pid| process_state(pid).is_none_or(|state| state == 'Z'))
    });
    signal(run.pid(), libc::SIGCONT);
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(1), "{report}");
    let stderr = String::from_utf8_lossy(&status.stderr);
    let error = stderr.lines().last().unwrap_or_default();
    assert!(error.contains("the world process failed"), "{report}");
    assert!(!error.contains("first to fail"), "an agent is blamed:\n{report}");
    let s = summary(dir.path());
    let notes = notes(&s);
    let blamed = |note: &&str| note.starts_with("UAV") || note.contains("restarted");
    assert!(!notes.iter().any(blamed), "{notes:?}");
    for uav in 1..=2 {
        let log = agent_log(dir.path(), uav);
        assert!(log.contains("is gone") && log.contains("its Q-tables are saved in"), "{log}");
    }
    assert_nothing_left(&id);
}

/// The rows of `episodes.csv` in `dir` flown by UAV`uav` so far: as far as the supervisor's
/// buffered writes have put them on disk.
fn rows_of(dir: &std::path::Path, uav: u64) -> usize {
    let csv = std::fs::read_to_string(dir.join("episodes.csv")).unwrap_or_default();
    csv.lines().filter(|line| line.split(',').nth(1) == Some(&uav.to_string())).count()
}

/// An agent in a pid namespace of its own (a container that shares `/dev/shm` with the run)
/// sees the world's process id as nothing or as another process: whether the world is gone
/// is asked of iceoryx2, whose node locks hold across namespaces. It used to look the pid up
/// in `/proc` and, at the first round slower than 20 ms, leave saying the world was gone.
/// Skipped where `unshare --pid` is not allowed (it needs privileges).
#[test]
fn an_agent_in_another_pid_namespace_outlasts_a_slow_round() {
    let unshare = ["--pid", "--fork", "--mount-proc"];
    let allowed = std::process::Command::new("unshare")
        .args(unshare)
        .arg("true")
        .output()
        .is_ok_and(|output| output.status.success());
    if !allowed {
        eprintln!("skipped: `unshare --pid --fork --mount-proc true` failed here");
        return;
    }
    let dir = scratch();
    let (id, out) = (run_id("pidns"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s4 --uavs 2 --episodes 1000000 --trials 1 --seed 44"),
    ));
    let uav1 = wait_for_agent(&id, 1);
    let attached = Spawned::start(
        "unshare",
        &[&unshare[..], &[AGENT, "--attach", &id, "--out", &out, "--world-timeout-ms", "60000"]]
            .concat(),
    );
    wait_until("UAV3 to fly episodes", Duration::from_secs(30), || rows_of(dir.path(), 3) > 0);
    // A round of 300 ms: UAV1 stopped, well within its 500 ms deadline.
    for signal_to_send in [libc::SIGSTOP, libc::SIGCONT] {
        for &pid in &uav1 {
            signal(pid, signal_to_send);
        }
        std::thread::sleep(Duration::from_millis(300));
    }
    let flown = rows_of(dir.path(), 3);
    wait_until("UAV3 to fly on after the slow round", Duration::from_secs(30), || {
        rows_of(dir.path(), 3) > flown + 100
    });
    run.interrupt();
    let (left, report) = attached.finish(DEADLOCK);
    assert!(left.status.success(), "{report}");
    let said = String::from_utf8_lossy(&left.stderr);
    assert!(said.contains(&format!("agent: run `{id}` ended")), "{report}");
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(130), "{report}");
    assert_nothing_left(&id);
}

/// The snapshot of agent `uav` (1-based) in `trial` under results directory `dir`.
fn snapshot(dir: &std::path::Path, uav: usize, trial: usize) -> Snapshot {
    let path = snapshot_path(dir, uav - 1, trial);
    Snapshot::decode(&read(&path)).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// What agent `uav` (1-based) wrote to its log (its stderr) under results directory `dir`.
fn agent_log(dir: &std::path::Path, uav: usize) -> String {
    String::from_utf8_lossy(&read(&dir.join("logs").join(format!("uav{uav}.log")))).into_owned()
}

/// That snapshot if it is there and complete yet, for a wait.
fn saved(dir: &std::path::Path, uav: usize, trial: usize) -> Option<Snapshot> {
    let bytes = std::fs::read(snapshot_path(dir, uav - 1, trial)).ok()?;
    Snapshot::decode(&bytes).ok()
}

/// An agent killed in the final greedy evaluation goes on, restarted, from the tables it
/// trained: each trial saved them as its evaluation began. It used to restart from empty
/// tables (no periodic snapshot was due yet), evaluate those, and write them as the final
/// ones of a run that said it was complete.
#[test]
fn an_agent_killed_in_the_final_evaluation_is_restarted_with_its_trained_tables() {
    let dir = scratch();
    let (id, out) = (run_id("evalkill"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 1000 --trials 2 --seed 82 --eval-episodes 4000 --tick-cap 100 --restart on-failure"),
    ));
    wait_until("UAV1's tables saved as each trial's evaluation began", DEADLOCK, || {
        (0..2).all(|trial| saved(dir.path(), 1, trial).is_some_and(|s| s.episodes == 1000))
    });
    for pid in agent_pids(&id, 1) {
        signal(pid, libc::SIGKILL);
    }
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let s = summary(dir.path());
    let notes = notes(&s);
    assert_eq!(notes.len(), 2, "one failure, one restart: {notes:?}");
    assert_eq!(notes[1], "UAV1 restarted from its latest snapshot", "{notes:?}");
    for trial in 0..2 {
        assert_eq!(snapshot(dir.path(), 1, trial).episodes, 1000, "trial {trial}: {notes:?}");
    }
    assert_nothing_left(&id);
}

/// An attached agent leaves on Ctrl-C: it saves its tables, says so and exits 0; the world
/// drops it and the run goes on; the supervisor notes that it left.
#[test]
fn an_attached_agent_leaves_on_ctrl_c_with_its_tables_saved() {
    let (dir, own) = (scratch(), scratch());
    let (id, out) = (run_id("leave"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s4 --uavs 2 --episodes 50000 --trials 2 --seed 42"),
    ));
    wait_for_agent(&id, 2);
    let own_out = own.path().display().to_string();
    let attached = Spawned::start(AGENT, &["--attach", &id, "--out", &own_out]);
    wait_until("UAV3 to fly episodes", DEADLOCK, || rows_of(dir.path(), 3) > 100);
    let pid = attached.pid();
    attached.interrupt();
    let (left, leave_report) = attached.finish(DEADLOCK);
    assert!(left.status.success(), "{leave_report}");
    let said = String::from_utf8_lossy(&left.stderr);
    assert!(
        said.contains(&format!(
            "agent: UAV3 left run `{id}`; its Q-tables are in {own_out}/qtables"
        )),
        "{leave_report}"
    );
    for trial in 0..2 {
        assert!(snapshot(own.path(), 3, trial).episodes > 0, "trial {trial}: {leave_report}");
    }
    // The run goes on without it, then is stopped.
    let flown = rows_of(dir.path(), 1);
    wait_until("the run to go on", DEADLOCK, || rows_of(dir.path(), 1) > flown + 1000);
    run.interrupt();
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(130), "{report}");
    let notes = summary(dir.path())["notes"].to_string();
    assert!(notes.contains(&format!("UAV3 (attached, process {pid}) left")), "{notes}");
    assert_nothing_left(&id);
}

/// A second run with a live run's `--run-id` is refused before it writes or starts
/// anything; the live run is not disturbed. It used to open the live run's records and fail
/// with "episode records lost or out of order".
#[test]
fn a_run_id_a_live_run_uses_is_refused_at_once() {
    let (dir, second) = (scratch(), scratch());
    let (id, out) = (run_id("twice"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 50000 --trials 1 --seed 43"),
    ));
    wait_for_agent(&id, 2);
    let second_out = second.path().join("b");
    let (refused, report) = run_fail(
        crate::harness::SUPERVISOR,
        &[&["--run-id", &id, "--episodes", "10", "--out"][..], &[&*second_out.to_string_lossy()]]
            .concat(),
    );
    assert_eq!(refused.status.code(), Some(1), "{report}");
    let error = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(
        error.trim_end(),
        format!("supervisor: error: --run-id {id}: a live run uses this id; choose another"),
        "{report}"
    );
    assert!(!second_out.exists(), "the refused run wrote {}", second_out.display());
    run.interrupt();
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(130), "{report}");
    assert_eq!(summary(dir.path())["notes"], serde_json::json!([]), "{report}");
    assert_nothing_left(&id);
}

#[test]
fn a_rogue_publisher_is_rejected_and_changes_nothing() {
    let (shm, inproc) = (scratch(), scratch());
    let (id, out) = (run_id("rogue"), shm.path().display().to_string());
    let args =
        ["--scenario", "s3", "--uavs", "2", "--episodes", "2000", "--trials", "2", "--seed", "91"];
    let run = Spawned::supervisor(&run_args(&id, &out, &args));
    let rogue_id = id.clone();
    let rogue = std::thread::spawn(move || {
        let ports = RunServices::open(&RunConfig::new(&rogue_id, SignalMode::Untouched))
            .and_then(RunServices::into_agent)
            .expect("the rogue opens the run");
        // A second supervisor's ports, for orders only the supervisor may give. They live as
        // long as the rogue (a sample of a publisher gone before the world connected to it is
        // lost: iceoryx2 issue #39), and it reads the records they receive, or the world would
        // wait for it (docs/MEMBERSHIP.md, known limits).
        let control = RunServices::open(&RunConfig::new(&rogue_id, SignalMode::Untouched))
            .and_then(RunServices::into_supervisor)
            .expect("the rogue opens the run's control");
        let mut sent = 0;
        let start = Instant::now();
        while sent < 300 && start.elapsed() < Duration::from_secs(60) {
            while let Ok(Some(_)) = control.try_next() {}
            // The newest round: a forged answer to an older one would only be stale.
            let mut newest = None;
            while let Ok(Some(observation)) = ports.try_observation() {
                newest = Some(observation);
            }
            let Some(observation) = newest else {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            };
            if sent == 0 {
                // Joins while the run is under way (the world's ports surely exist by now).
                ports.send_join(&JoinRequest::new(0, 7)).expect("send a join");
                ports.send_join(&JoinRequest::new(99, ANY_SLOT)).expect("send a join");
                // Stop, and every agent gone.
                let stop = Control { stop: 1, gone: u64::MAX, ..Control::default() };
                control.send_control(&stop).expect("send a control command");
            }
            let mut bad = Action::new(0);
            bad.round = observation.round;
            bad.n_trials = observation.n_trials;
            match sent % 6 {
                0 => bad.agent = 99,
                1 => bad.n_trials = 999,
                2 => bad.trials[0].flags.waypoint = 5000,
                3 => {
                    bad.trials[1].n_commands = 1;
                    bad.trials[1].commands[0] = 77;
                }
                // Well-formed answers for UAV1 (hover, no flags) to this round and the next,
                // which the world has not published yet: only the sender gives them away.
                4 => {}
                _ => bad.round += 1,
            }
            ports.publish_action(&bad).expect("publish a rogue action");
            sent += 1;
        }
        sent
    });
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let sent = rogue.join().expect("the rogue thread");
    assert!(sent >= 50, "the rogue sent only {sent} messages");
    let log = world_log(shm.path());
    // Its malformed actions for UAV1 are refused by sender before their fields are read
    // (world/src/sim.rs tests the field checks); the one for slot 99 answers no slot.
    assert!(
        log.lines().any(|line| {
            line.contains("dropped an action that does not answer this round")
                && line.contains("action.agent=99")
        }),
        "the action for slot 99 was not refused:\n{log}"
    );
    assert!(
        log.contains("join refused") || log.contains("ignored a join request"),
        "rogue joins not logged:\n{log}"
    );
    assert!(
        log.contains("dropped an action sent for this agent by another process"),
        "no well-formed copy of UAV1's answer was refused:\n{log}"
    );
    assert!(
        log.contains("ignored a control command from a process not the supervisor"),
        "the rogue's stop was not refused:\n{log}"
    );
    assert_eq!(summary(shm.path())["complete"], true, "the rogue stopped the run");
    // Nothing the rogue sent changed the run: it equals the in-process twin byte for byte.
    supervise(inproc.path(), &[&args[..], &words("--transport inproc")].concat());
    assert_same_file(&shm.path().join("episodes.csv"), &inproc.path().join("episodes.csv"));
    assert_nothing_left(&id);
}

/// The starting slots belong to the agents the supervisor starts. A stray process that asks
/// for one before its agent does (here UAV1 waits for the test's go) is answered as an
/// attaching agent would be, once the run is under way (s3 has no free route: refused), and
/// the run equals the in-process one byte for byte. Before, the stray process took the slot.
#[test]
fn a_stray_join_for_a_starting_slot_does_not_take_it() {
    let (shm, inproc, gate_dir) = (scratch(), scratch(), scratch());
    let gate = gate_dir.path().join("uav1-may-join");
    let (id, out) = (run_id("stray"), shm.path().display().to_string());
    let args =
        ["--scenario", "s3", "--uavs", "2", "--episodes", "1000", "--trials", "2", "--seed", "97"];
    let fault = format!("1=join-after-file={}", gate.display());
    let run =
        Spawned::supervisor(&run_args(&id, &out, &[&args[..], &["--fault", &fault]].concat()));
    let log_file = shm.path().join("logs").join("world.log");
    let noticed = "came from a process it did not start";
    let start = Instant::now();
    let mut stray = None;
    let mut sent = 0;
    // Until the world says it saw the stray request (bounded; the gate opens either way, so
    // a failure leaves no process behind).
    while start.elapsed() < Duration::from_secs(30) {
        if std::fs::read_to_string(&log_file).unwrap_or_default().contains(noticed) {
            break;
        }
        if stray.is_none() {
            // The world creates the run's services as it starts.
            stray = RunServices::open(&RunConfig::new(&id, SignalMode::Untouched))
                .and_then(RunServices::into_agent)
                .ok();
        }
        if let Some(ports) = &stray {
            ports.send_join(&JoinRequest::new(0x5eed, 0)).expect("send a join");
            sent += 1;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    drop(stray);
    std::fs::write(&gate, "").expect("open the gate");
    let (status, report) = run.finish(DEADLOCK);
    let log = world_log(shm.path());
    assert!(log.contains(noticed), "the stray request ({sent} sent) was not noticed:\n{log}");
    assert!(status.status.success(), "{report}");
    assert!(log.contains("join refused"), "the stray request was not answered:\n{log}");
    supervise(inproc.path(), &[&args[..], &words("--transport inproc")].concat());
    assert_same_file(&shm.path().join("episodes.csv"), &inproc.path().join("episodes.csv"));
    assert_nothing_left(&id);
}

/// A hung agent (its process runs, it answers nothing) is dropped by the world at the
/// deadline; the supervisor sees it leave the barrier while its process runs, brings it down
/// at once (this one ignores SIGTERM: SIGKILL after 2 s) and reports it as failed.
#[test]
fn a_hung_agent_is_dropped_at_the_deadline_and_brought_down_by_the_supervisor() {
    let dir = scratch();
    let (id, out) = (run_id("hang"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 2000 --trials 1 --seed 95 --fault 2=hang-at-round=3000,ignore-sigterm"),
    ));
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let log = world_log(dir.path());
    assert!(log.contains("silent past the deadline") && log.contains("uav=2"), "{log}");
    let s = summary(dir.path());
    let notes = s["notes"].to_string();
    assert!(
        notes.contains("UAV2 was dropped by the world: silent past the deadline")
            && notes.contains("SIGKILL")
            && notes.contains("not restarted"),
        "the hung agent is not reported as brought down: {notes}"
    );
    assert!(!notes.contains("had to signal"), "left to the ladder at the end: {notes}");
    assert_eq!(s["complete"], true, "{s:#}");
    assert_eq!(episode_rows(dir.path()).iter().filter(|r| r[1] == 1).count(), 2000);
    assert_nothing_left(&id);
}

/// SPEC 4: an agent silent past the bound is presumed dead, reported and, if asked,
/// restarted. Before, the supervisor said nothing of the hung agent the world had dropped,
/// never restarted it, and only the ladder ended it after the run.
#[test]
fn a_hung_agent_is_reported_and_restarted() {
    let dir = scratch();
    let (id, out) = (run_id("hang-restart"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 3000 --trials 2 --seed 96 --fault 2=hang-at-round=5000 --restart on-failure --snapshot-every 20"),
    ));
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], true, "{s:#}");
    // UAV2 missed the episodes flown while it was down.
    assert_eq!(s["every_agent_flew_every_episode"], false, "{s:#}");
    let notes = notes(&s);
    assert_eq!(notes.len(), 2, "one drop, one restart: {notes:?}");
    assert!(
        notes[0].starts_with("UAV2 was dropped by the world: silent past the deadline"),
        "{notes:?}"
    );
    assert!(notes[1].starts_with("UAV2 restarted from its latest snapshot"), "{notes:?}");
    // Reported once, as it happened (it used to be printed twice).
    let stderr = String::from_utf8_lossy(&status.stderr);
    assert_eq!(stderr.matches("UAV2 was dropped by the world").count(), 1, "{report}");
    // The restarted agent flew again after the gap where UAV2 was down.
    let uav2: Vec<[u64; 6]> =
        episode_rows(dir.path()).into_iter().filter(|r| r[0] == 0 && r[1] == 2).collect();
    let gap = first_gap(&uav2).expect("a gap where UAV2 was down");
    assert!(
        uav2.len() - gap > 100,
        "UAV2 flew only {} episodes after its restart",
        uav2.len() - gap
    );
    assert_nothing_left(&id);
}

/// An agent stopped by someone (SIGSTOP: it looks hung) is dropped, and brought down with a
/// SIGCONT beside its SIGTERM: it saves its tables as it leaves, and its restart goes on
/// from them. Before, the SIGTERM waited behind the stop until the SIGKILL, and the restart
/// started from empty tables, losing everything learned since the last snapshot (here, with
/// `--snapshot-every 0`, everything).
#[test]
fn a_stopped_agent_saves_its_tables_before_it_is_restarted() {
    let dir = scratch();
    let (id, out) = (run_id("stopped"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 60000 --trials 2 --seed 97 --restart on-failure --snapshot-every 0 --eval-episodes 10"),
    ));
    let uav2 = wait_for_agent(&id, 2);
    wait_for_records(&dir.path().join("episodes.csv"), 10_000, DEADLOCK);
    for &pid in &uav2 {
        signal(pid, libc::SIGSTOP);
    }
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let s = summary(dir.path());
    let notes = notes(&s);
    let restart = notes.iter().find(|note| note.starts_with("UAV2 restarted"));
    let restart = restart.unwrap_or_else(|| panic!("UAV2 was not restarted: {notes:?}"));
    assert_eq!(*restart, "UAV2 restarted from its latest snapshot", "{notes:?}");
    assert_nothing_left(&id);
}

/// A world that cannot end the stop round (here stopped with SIGSTOP: it looks hung) does not
/// keep a stopped run waiting: a single Ctrl-C or SIGTERM ends the run once the world has
/// had the time the stop round may take (about 50 s here), as a second one would at once.
/// Before, the supervisor waited for the world for good (a user test: still waiting after
/// 12 minutes).
#[test]
fn a_hung_world_does_not_keep_a_stopped_run_waiting() {
    let dir = scratch();
    let (id, out) = (run_id("hung-world"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 10000000 --trials 1"),
    ));
    wait_for_records(&dir.path().join("episodes.csv"), 10_000, DEADLOCK);
    for pid in world_pids(&id) {
        signal(pid, libc::SIGSTOP);
    }
    run.interrupt();
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(130), "{report}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], false, "{s:#}");
    let notes = notes(&s);
    let overdue = "stopped at once: the world had not ended the stop round in time";
    assert!(notes.iter().any(|note| note.starts_with(overdue)), "{notes:?}");
    assert_nothing_left(&id);
}

/// A known limit (docs/MEMBERSHIP.md): no episode record may be lost, so a process that
/// subscribes to them and never reads stalls the world. The run must then fail in bounded
/// time with the service named, keep what was collected, and leave nothing behind.
#[test]
fn a_subscriber_that_never_reads_the_records_fails_the_run_cleanly() {
    let dir = scratch();
    let (id, out) = (run_id("idle"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 50000 --trials 4 --seed 3"),
    ));
    let (subscribed_tx, subscribed) = std::sync::mpsc::channel();
    let (release, released) = std::sync::mpsc::channel::<()>();
    let idle_id = id.clone();
    let idle = std::thread::spawn(move || {
        let start = Instant::now();
        let ports = loop {
            let config = RunConfig::new(&idle_id, SignalMode::Untouched);
            match RunServices::open(&config).and_then(RunServices::into_supervisor) {
                Ok(ports) => break ports,
                Err(e) if start.elapsed() > Duration::from_secs(30) => {
                    panic!("the idle reader could not open the run: {e}")
                }
                Err(_) => std::thread::sleep(Duration::from_millis(5)),
            }
        };
        // Connected to the world's publisher (`into_supervisor` waits for it), so the world
        // cannot skip this reader: it must wait for it once its buffer is full.
        subscribed_tx.send(()).expect("the test waits for the idle reader");
        // Holds its subscriber, unread, until the run is over.
        let _ = released.recv_timeout(DEADLOCK);
        drop(ports);
    });
    subscribed.recv_timeout(Duration::from_secs(40)).expect("the idle reader subscribed");
    let (status, report) = run.finish(DEADLOCK);
    release.send(()).expect("the idle reader holds on");
    idle.join().expect("the idle reader");
    assert_eq!(status.status.code(), Some(1), "{report}");
    assert!(report.contains("`episodes` not drained for 10s"), "{report}");
    assert_eq!(summary(dir.path())["complete"], false);
    assert!(!episode_rows(dir.path()).is_empty(), "the records collected before are lost");
    assert_nothing_left(&id);
}

/// A run past its bound is interrupted, not just killed: the failure shows how far it got,
/// which tells a machine too loaded for the bound from a deadlock.
#[test]
fn an_overdue_run_is_interrupted_and_reported_with_its_progress() {
    let dir = scratch();
    let (id, out) = (run_id("overdue"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 50000 --trials 2 --seed 73"),
    ));
    // Overdue as soon as it is under way: its world log exists.
    wait_until("the world log", DEADLOCK, || dir.path().join("logs/world.log").exists());
    let message = run.try_finish(Duration::from_millis(300)).expect_err("the run is overdue");
    assert!(message.contains("it stopped on SIGINT"), "{message}");
    assert!(message.contains("episode rows; world log, last 20 lines"), "{message}");
    assert_eq!(summary(dir.path())["complete"], false, "{message}");
    assert_nothing_left(&id);
}

/// An agent that hangs in the stop round never writes its final Q-tables: the world waits
/// its stop timeout (30 s), names the agent and fails, and the run fails with it, the
/// results so far written. Before, the world ended the run as complete and only the ladder
/// noticed the agent.
#[test]
fn an_agent_that_hangs_in_the_stop_round_fails_the_run() {
    let dir = scratch();
    let (id, out) = (run_id("hang-stop"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 300 --trials 1 --seed 97 --eval-episodes 20 --fault 2=hang-at-stop"),
    ));
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(1), "{report}");
    let stderr = String::from_utf8_lossy(&status.stderr);
    assert!(
        stderr.contains("final Q-tables may not be saved: UAV2 did not answer the stop round"),
        "{report}"
    );
    let s = summary(dir.path());
    assert_eq!(s["complete"], false, "{s:#}");
    assert_eq!(episode_rows(dir.path()).len(), 2 * 300, "episodes lost: {s:#}");
    assert_nothing_left(&id);
}

/// An agent that hangs after Ctrl-C asked the run to stop: the world stops at the end of the
/// round, which waits for the hung agent's deadline; it then drops it and stops the others.
/// The supervisor brings the dropped process down itself (it ignores SIGTERM here) and
/// reports it, not restarted since the run is stopping; the run ends as stopped (130), its
/// results written, nothing left to the shutdown ladder.
#[test]
fn an_agent_that_hangs_as_the_run_stops_is_dropped_and_brought_down() {
    let dir = scratch();
    let (id, out) = (run_id("hang-ctrlc"), dir.path().display().to_string());
    let run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 50000 --trials 1 --seed 98 --agent-timeout-ms 2000 --restart on-failure --fault 2=hang-at-round=3000,ignore-sigterm"),
    ));
    wait_for_hang(dir.path(), 2);
    run.interrupt();
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(130), "Ctrl-C exits with 130\n{report}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], false, "{s:#}");
    let notes = notes(&s);
    assert_eq!(notes.len(), 1, "one drop, not restarted: {notes:?}");
    assert!(
        notes[0].starts_with("UAV2 was dropped by the world: silent past the deadline")
            && notes[0].contains("SIGKILL")
            // Which depends on whether the world has exited by the time it is down.
            && (notes[0].ends_with("not restarted (the run is stopping)")
                || notes[0].ends_with("not restarted (the run has ended)")),
        "{notes:?}"
    );
    snapshot(dir.path(), 1, 0);
    assert_nothing_left(&id);
}

/// A second Ctrl-C stops at once: an agent that hangs in the stop round no longer holds the
/// run for the world's stop-round deadline (30 s) and then fails it. The world and the hung
/// agent are brought down, the run ends as stopped (130) with every result written, and the
/// notes say how it ended; the other agent had saved its final tables in the stop round.
#[test]
fn a_second_ctrl_c_stops_at_once_without_waiting_for_a_hung_agent() {
    let dir = scratch();
    let (id, out) = (run_id("hurry"), dir.path().display().to_string());
    let mut run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words(
            "--scenario s3 --uavs 2 --episodes 50000 --trials 1 --seed 99 --fault 2=hang-at-stop",
        ),
    ));
    wait_for_agent(&id, 2);
    run.interrupt();
    let first = Instant::now();
    wait_for_hang(dir.path(), 2);
    interrupt_until_it_ends(&mut run, first);
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(130), "stopped, not failed\n{report}");
    let world = world_log(dir.path());
    assert!(!world.contains("did not answer the stop round"), "the world waited it out: {world}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], false, "{s:#}");
    let notes = notes(&s);
    assert!(notes.iter().any(|n| n.starts_with("stopped at once by a second Ctrl-C")), "{notes:?}");
    assert!(notes.iter().any(|n| n.starts_with("UAV2 left (exit status: 1)")), "{notes:?}");
    assert!(!notes.iter().any(|n| n.starts_with("UAV1")), "UAV1 left in order: {notes:?}");
    snapshot(dir.path(), 1, 0);
    assert_nothing_left(&id);
}

/// Waits until agent `uav`'s log says it hangs (`--fault hang-at-...`).
fn wait_for_hang(dir: &std::path::Path, uav: usize) {
    let log = dir.join("logs").join(format!("uav{uav}.log"));
    wait_until(&format!("UAV{uav} to hang"), DEADLOCK, || {
        std::fs::read_to_string(&log).is_ok_and(|text| text.contains("hanging here"))
    });
}

/// Presses Ctrl-C again, as a user does after reading "stopping", and again every
/// 2 x [`HURRY_AFTER`] until the run has ended (at most [`DEADLOCK`]). The first press, sent
/// at `first`, counts from when the supervisor's handler took it, which a loaded machine can
/// delay; a press within [`HURRY_AFTER`] of that is taken for the same signal delivered
/// twice, and presses after the second change nothing.
fn interrupt_until_it_ends(run: &mut Spawned, first: Instant) {
    let mut due = first + HURRY_AFTER * 2;
    let started = Instant::now();
    while !run.has_exited() {
        assert!(started.elapsed() < DEADLOCK, "the run did not end within {DEADLOCK:?} of Ctrl-C");
        if Instant::now() >= due {
            run.interrupt();
            due = Instant::now() + HURRY_AFTER * 2;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A second Ctrl-C while an agent hangs in training, the world waiting for its answer (the
/// first Ctrl-C cannot start the stop round then): every process leaves at once, and the
/// agent that was waiting for the world saves its tables as it leaves, and says where.
#[test]
fn a_second_ctrl_c_in_training_saves_the_tables_of_every_agent_that_can() {
    let dir = scratch();
    let (id, out) = (run_id("hurry-train"), dir.path().display().to_string());
    let mut run = Spawned::supervisor(&run_args(
        &id,
        &out,
        &words("--scenario s3 --uavs 2 --episodes 50000 --trials 1 --seed 98 --agent-timeout-ms 60000 --fault 2=hang-at-round=3000"),
    ));
    wait_for_hang(dir.path(), 2);
    run.interrupt();
    interrupt_until_it_ends(&mut run, Instant::now());
    let (status, report) = run.finish(DEADLOCK);
    assert_eq!(status.status.code(), Some(130), "stopped, not failed\n{report}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], false, "{s:#}");
    let notes = notes(&s);
    assert!(notes.iter().any(|n| n.starts_with("stopped at once by a second Ctrl-C")), "{notes:?}");
    assert!(
        notes.iter().any(|n| n.starts_with("UAV1 left (exit status: 1)")
            && n.contains("its Q-tables are saved in")),
        "{notes:?}"
    );
    assert!(notes.iter().any(|n| n.starts_with("UAV2 left (exit status: 1)")), "{notes:?}");
    assert!(!notes.iter().any(|n| n.contains("world process failed")), "{notes:?}");
    assert!(snapshot(dir.path(), 1, 0).episodes > 0, "UAV1's tables as it left");
    assert_nothing_left(&id);
}

/// The one-letter state of process `pid` (`R`, `S`, `T` for stopped, ...), or None once it
/// is gone.
fn process_state(pid: u32) -> Option<char> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The state follows the parenthesised command name, which may hold spaces.
    stat.rsplit_once(") ").and_then(|(_, rest)| rest.chars().next())
}

/// Ctrl-Z pauses the whole run: the supervisor stops its world and agents, then itself, and
/// once continued it continues them. The pause outlasts the agents' deadline
/// (`--agent-timeout-ms 100`) many times, yet no agent is presumed dead: the run resumes
/// where it was and learns exactly what an unpaused run learns (the in-process run of the
/// same seed), and the pause is noted.
#[test]
fn ctrl_z_pauses_the_whole_run_and_it_resumes_where_it_was() {
    let (dir, inproc) = (scratch(), scratch());
    let (id, out) = (run_id("ctrl-z"), dir.path().display().to_string());
    let args = words("--scenario s3 --uavs 2 --episodes 50000 --trials 1 --seed 61");
    let timeout = words("--agent-timeout-ms 100");
    let run = Spawned::supervisor(&run_args(&id, &out, &[&args[..], &timeout[..]].concat()));
    let mut pids = vec![run.pid()];
    pids.extend(wait_for_agent(&id, 1));
    pids.extend(wait_for_agent(&id, 2));
    pids.extend(world_pids(&id));
    wait_until("the supervisor to catch Ctrl-Z", DEADLOCK, || catches(run.pid(), libc::SIGTSTP));
    signal(run.pid(), libc::SIGTSTP);
    wait_until("every process of the run to stop", DEADLOCK, || {
        pids.iter().all(|&pid| process_state(pid) == Some('T'))
    });
    // The pause itself, held past the waits' allowance for a stopped process (PAUSE_GAP).
    std::thread::sleep(Duration::from_millis(1500));
    signal(run.pid(), libc::SIGCONT);
    let (status, report) = run.finish(DEADLOCK);
    assert!(status.status.success(), "{report}");
    let s = summary(dir.path());
    assert_eq!(s["complete"], true, "{s:#}");
    assert_eq!(s["every_agent_flew_every_episode"], true, "{s:#}");
    let notes = notes(&s);
    assert!(
        notes.len() == 1 && notes[0].starts_with("paused for ") && notes[0].contains("Ctrl-Z"),
        "only the pause is noted: {notes:?}"
    );
    supervise(inproc.path(), &[&args[..], &words("--transport inproc")].concat());
    assert_same_file(&dir.path().join("episodes.csv"), &inproc.path().join("episodes.csv"));
    assert_nothing_left(&id);
}

/// Ctrl-C in the first milliseconds of a run (0 to 38 ms after the supervisor can take
/// SIGINT: as it starts the world, opens the run's services, starts the agents) stops the
/// run: status 130, no error. A user test saw such a signal cut short iceoryx2's wait for a
/// service the world was still creating, which failed the run with
/// `EventOpenError::Interrupt` (3 of 9 tries, on a loaded machine); the open now retries
/// it. This test did not reproduce that here (0 of 270 tries with the retry taken out): it
/// guards the early stop as a whole.
#[test]
fn ctrl_c_as_the_run_starts_stops_it() {
    for attempt in 0..20 {
        let (_dir, id, run) = long_run(&format!("start-stop{attempt}"));
        run.interrupt_after(Duration::from_millis(2 * attempt));
        let (status, report) = run.finish(DEADLOCK);
        assert_eq!(status.status.code(), Some(130), "attempt {attempt}\n{report}");
        let stderr = String::from_utf8_lossy(&status.stderr);
        assert!(!stderr.contains("error"), "attempt {attempt}\n{report}");
        assert_nothing_left(&id);
    }
}

/// A run of s3 long enough to be stopped (50 000 episodes, 1 trial), results in the scratch
/// directory returned, under a run id made of `tag`.
fn long_run(tag: &str) -> (tempfile::TempDir, String, Spawned) {
    let dir = scratch();
    let (id, out) = (run_id(tag), dir.path().display().to_string());
    let args = words("--scenario s3 --uavs 2 --episodes 50000 --trials 1");
    let run = Spawned::supervisor(&run_args(&id, &out, &args));
    (dir, id, run)
}

/// Ctrl-C as soon as the agents start: the world's first round is then the stop round, which
/// each agent answers once its tables are saved. An agent used to leave right after sending
/// that answer, and about one such run in seven failed with the world waiting for the answer
/// of an agent already gone ("UAV1 did not answer the stop round"); each now leaves after
/// the world. Ten runs: the old code got through all ten about one time in five.
#[test]
fn ctrl_c_as_the_agents_start_stops_every_run_in_order() {
    for attempt in 0..10 {
        let (dir, id, run) = long_run(&format!("early-stop{attempt}"));
        wait_for_agent(&id, 2);
        run.interrupt();
        let (status, report) = run.finish(DEADLOCK);
        assert_eq!(status.status.code(), Some(130), "attempt {attempt}\n{report}");
        for uav in [1, 2] {
            snapshot(dir.path(), uav, 0);
        }
        assert_nothing_left(&id);
    }
}
