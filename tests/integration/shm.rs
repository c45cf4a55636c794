//! The multi-process path (issue 3): real `world` and `agent` processes over iceoryx2.
//! Equivalence with the in-process runner, lockstep seen from the agents' own traces,
//! isolation of two simultaneous runs, nothing left in shared memory afterwards, and each
//! process's own peak memory in the summary.

use crate::harness::{
    assert_nothing_left, assert_same_file, comm_entry, read, read_trace, run_id, scratch,
    supervise, wait_until, words, world_pids, Spawned, TraceRow, RUN_BOUND,
};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::Duration;

/// Runs `args` with both transports; returns (shm dir, inproc dir).
fn both(args: &[&str], tag: &str) -> (tempfile::TempDir, tempfile::TempDir) {
    let (shm, inproc) = (scratch(), scratch());
    let id = run_id(tag);
    let mut shm_args = args.to_vec();
    shm_args.extend(["--transport", "shm", "--run-id", &id]);
    let summary = supervise(shm.path(), &shm_args);
    assert_eq!(summary["complete"], true, "{summary:#}");
    assert_nothing_left(&id);
    let mut inproc_args = args.to_vec();
    inproc_args.extend(["--transport", "inproc"]);
    supervise(inproc.path(), &inproc_args);
    (shm, inproc)
}

fn assert_same_results(shm: &Path, inproc: &Path) {
    assert!(read(&shm.join("episodes.csv")).len() > 1000, "episodes.csv is suspiciously short");
    for file in ["episodes.csv", "greedy_episodes.csv"] {
        assert_same_file(&shm.join(file), &inproc.join(file));
    }
    let tables = |dir: &Path| -> BTreeSet<String> {
        std::fs::read_dir(dir.join("qtables"))
            .expect("a qtables directory")
            .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
            .collect()
    };
    let names = tables(shm);
    assert_eq!(names, tables(inproc));
    for name in names {
        assert_same_file(&shm.join("qtables").join(&name), &inproc.join("qtables").join(&name));
    }
}

/// Both transports give the same bytes for `scenario` with `uavs` UAVs (2 trials, 2000
/// episodes).
fn assert_transports_agree(scenario: &str, uavs: &str, seed: &str) {
    let args = [
        "--scenario",
        scenario,
        "--uavs",
        uavs,
        "--episodes",
        "2000",
        "--trials",
        "2",
        "--seed",
        seed,
    ];
    let (shm, inproc) = both(&args, &format!("eq-{scenario}"));
    assert_same_results(shm.path(), inproc.path());
}

#[test]
fn s1_shm_and_inproc_are_byte_identical() {
    assert_transports_agree("s1", "1", "11");
}

#[test]
fn s2_shm_and_inproc_are_byte_identical() {
    assert_transports_agree("s2", "1", "12");
}

#[test]
fn s3_shm_and_inproc_are_byte_identical() {
    assert_transports_agree("s3", "2", "13");
}

/// What the lockstep test runs: 2 trials.
const LOCKSTEP_TRIALS: u64 = 2;

#[test]
fn lockstep_agents_tick_the_same_rounds_and_flags_arrive_the_next_tick() {
    let out = scratch();
    let traces = out.path().join("traces");
    std::fs::create_dir_all(&traces).expect("a trace directory");
    let id = run_id("lockstep");
    let (trace_arg, trials) = (traces.display().to_string(), LOCKSTEP_TRIALS.to_string());
    supervise(
        out.path(),
        &[
            &words("--scenario s3 --uavs 2 --episodes 300 --seed 21 --transport shm")[..],
            &["--trials", &trials, "--run-id", &id, "--trace-dir", &trace_arg],
        ]
        .concat(),
    );
    assert_nothing_left(&id);
    let uav1 = read_trace(&traces.join("uav1.trace.csv"));
    let uav2 = read_trace(&traces.join("uav2.trace.csv"));
    let keys = |t: &[TraceRow]| t.iter().map(|r| (r.round, r.stop, r.trial)).collect::<Vec<_>>();
    assert_eq!(keys(&uav1), keys(&uav2), "the two agents did not tick the same rounds");
    let rounds: BTreeSet<u64> = uav1.iter().map(|r| r.round).collect();
    let last = *rounds.last().expect("rounds");
    assert_eq!(rounds, (0..=last).collect(), "rounds are not consecutive from 0");
    // The run ended for everyone at once: one stop row per trial and UAV, all in the last
    // round.
    for (name, trace) in [("UAV1", &uav1), ("UAV2", &uav2)] {
        for trial in 0..LOCKSTEP_TRIALS {
            let stops: Vec<u64> =
                trace.iter().filter(|r| r.stop && r.trial == trial).map(|r| r.round).collect();
            assert_eq!(stops, [last], "{name} trial {trial}: stop rounds (the last is {last})");
        }
        let trials: BTreeSet<u64> = trace.iter().map(|r| r.trial).collect();
        assert_eq!(trials, (0..LOCKSTEP_TRIALS).collect(), "{name}: trials in the trace");
    }
    // A flag sent in round t is in the receiver's state in round t+1, never later and never
    // earlier. Each agent's vector holds the other's entries alone (from entry 0).
    let mut checked = 0;
    for (sender, receiver, name) in [(&uav2, &uav1, "UAV2 -> UAV1"), (&uav1, &uav2, "UAV1 -> UAV2")]
    {
        let ticks = |trace: &[TraceRow]| -> BTreeMap<(u64, u64), TraceRow> {
            let rows = trace.iter().filter(|r| !r.stop).map(|r| ((r.round, r.trial), r.clone()));
            rows.collect()
        };
        let (sent, heard) = (ticks(sender), ticks(receiver));
        let mut arrived_here = 0;
        for (&(round, trial), flag) in &sent {
            let at = |round| heard.get(&(round, trial));
            let (Some(before), Some(after)) = (at(round), at(round + 1)) else { continue };
            assert_eq!(
                (before.episode, before.episode_tick),
                (flag.episode, flag.episode_tick),
                "{name} round {round} trial {trial}: the agents are in different ticks"
            );
            if after.episode != flag.episode || after.episode_tick != flag.episode_tick + 1 {
                continue; // the episode ended: the next one starts knowing nothing
            }
            let (wp, value) = (flag.sent_waypoint, flag.sent_sees + 1);
            let (was, is) = (comm_entry(&before.comm, wp), comm_entry(&after.comm, wp));
            let context = format!(
                "{name} round {round} trial {trial}: flag (wp{}, sees {}); the entry was {was}, \
                 next round {is}",
                wp + 1,
                flag.sent_sees
            );
            // By t+1: entries only rise within an episode, to the highest value heard.
            assert!(is >= value, "{context}: not in the receiver's state the next round");
            // Not later than t+1 either: whatever rose from t to t+1 is this flag.
            for k in 0..32 * after.comm.len() {
                let (from, to) = (comm_entry(&before.comm, k), comm_entry(&after.comm, k));
                assert!(
                    to <= from || (k, to) == (wp, value),
                    "{context}: entry {k} rose from {from} to {to}, which round {round} did \
                     not send"
                );
            }
            checked += 1;
            if was < value {
                arrived_here += 1;
            }
        }
        // The flags that told the receiver something new are what shows the timing.
        assert!(arrived_here > 0, "{name}: no flag told the receiver anything new");
    }
    assert!(checked > 1000, "only {checked} flags checked");
}

#[test]
fn two_simultaneous_runs_stay_independent() {
    let dirs = [scratch(), scratch()];
    let ids = [run_id("iso-a"), run_id("iso-b")];
    let seeds = ["31", "32"];
    let run = |i: usize| {
        [&words("--scenario s3 --uavs 2 --episodes 1000 --trials 2 --seed")[..], &[seeds[i]]]
            .concat()
    };
    let runs: Vec<Spawned> = (0..2)
        .map(|i| {
            let out = dirs[i].path().display().to_string();
            let mut args = run(i);
            args.extend(["--transport", "shm", "--run-id", &ids[i], "--quiet", "--out", &out]);
            Spawned::supervisor(&args)
        })
        .collect();
    // Simultaneous: at one moment both worlds run (each run takes seconds; 60 s is a hang).
    wait_until("both runs' worlds to run at once", Duration::from_secs(60), || {
        ids.iter().all(|id| !world_pids(id).is_empty())
    });
    for run in runs {
        let (out, report) = run.finish(RUN_BOUND);
        assert!(out.status.success(), "{report}");
    }
    for i in 0..2 {
        assert_nothing_left(&ids[i]);
        let twin = scratch();
        supervise(twin.path(), &[&run(i)[..], &["--transport", "inproc"]].concat());
        assert_same_results(dirs[i].path(), twin.path());
    }
    assert_ne!(
        read(&dirs[0].path().join("episodes.csv")),
        read(&dirs[1].path().join("episodes.csv"))
    );
}

#[test]
fn each_process_reports_its_own_peak_memory_not_its_launchers() {
    // A launcher with a large resident set, as `cargo run` is: Linux carries a program's
    // peak over `exec` into the next one's `getrusage`, so the supervisor must not use it.
    let ballast = std::hint::black_box(vec![1u8; 256 << 20]);
    let dir = scratch();
    let id = run_id("rss");
    let summary = supervise(
        dir.path(),
        &[
            "--uavs",
            "2",
            "--episodes",
            "20",
            "--trials",
            "1",
            "--eval-episodes",
            "0",
            "--run-id",
            &id,
        ],
    );
    drop(ballast);
    assert_nothing_left(&id);
    let peaks: BTreeMap<String, u64> = summary["peak_rss_kib"]
        .as_array()
        .expect("peak_rss_kib is a list")
        .iter()
        .map(|p| (p["process"].as_str().unwrap().to_string(), p["kib"].as_u64().unwrap()))
        .collect();
    let names: Vec<&str> = peaks.keys().map(String::as_str).collect();
    assert_eq!(names, ["UAV1", "UAV2", "supervisor", "world"], "{summary:#}");
    for (name, kib) in &peaks {
        assert!((1_000..128 << 10).contains(kib), "{name} peaked at {kib} KiB\n{summary:#}");
    }
}
