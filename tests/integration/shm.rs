//! The multi-process path (issue 3): real `world` and `agent` processes over iceoryx2.
//! Equivalence with the in-process runner, lockstep seen from the agents' own traces,
//! isolation of two simultaneous runs, nothing left in shared memory afterwards, and each
//! process's own peak memory in the summary.

use crate::harness::{
    assert_same_file, read, run_id, scratch, supervise, words, Spawned, RUN_BOUND,
};
use flockstep_proto::transport::leftover_files;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Runs `args` with both transports; returns (shm dir, inproc dir).
fn both(args: &[&str], tag: &str) -> (tempfile::TempDir, tempfile::TempDir) {
    let (shm, inproc) = (scratch(), scratch());
    let id = run_id(tag);
    let mut shm_args = args.to_vec();
    shm_args.extend(["--transport", "shm", "--run-id", &id]);
    let summary = supervise(shm.path(), &shm_args);
    assert_eq!(summary["complete"], true, "{summary:#}");
    let left = leftover_files(&id).expect("list the run's files");
    assert!(left.is_empty(), "run {id} left shared-memory files behind: {left:?}");
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

/// One line of an agent's trace: (round, kind, trial) -> (episode, episode_tick, sent wp,
/// sent sees, comm words).
type Trace = BTreeMap<(u64, String, usize), (u64, u64, usize, u64, Vec<u64>)>;

fn read_trace(path: &Path) -> Trace {
    let text = String::from_utf8(read(path)).expect("UTF-8 trace");
    let mut trace = Trace::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 8, "malformed trace line `{line}` in {}", path.display());
        let num =
            |i: usize| f[i].parse::<u64>().unwrap_or_else(|e| panic!("`{line}` field {i}: {e}"));
        let comm = if f[7].is_empty() {
            vec![]
        } else {
            f[7].split('-').map(|w| u64::from_str_radix(w, 16).expect("hex")).collect()
        };
        trace.insert(
            (num(0), f[1].to_string(), num(2) as usize),
            (num(3), num(4), num(5) as usize, num(6), comm),
        );
    }
    trace
}

/// Entry `k` (2 bits: 0 unknown, 1 "0", 2 "1") of a packed communication vector.
fn entry(words: &[u64], k: usize) -> u64 {
    words.get(2 * k / 64).map_or(0, |w| (w >> (2 * k % 64)) & 3)
}

#[test]
fn lockstep_agents_tick_the_same_rounds_and_flags_arrive_the_next_tick() {
    let out = scratch();
    let traces = out.path().join("traces");
    std::fs::create_dir_all(&traces).expect("a trace directory");
    let id = run_id("lockstep");
    let trace_arg = traces.display().to_string();
    supervise(
        out.path(),
        &[
            "--scenario",
            "s3",
            "--uavs",
            "2",
            "--episodes",
            "300",
            "--trials",
            "2",
            "--seed",
            "21",
            "--transport",
            "shm",
            "--run-id",
            &id,
            "--trace-dir",
            &trace_arg,
        ],
    );
    let uav1 = read_trace(&traces.join("uav1.trace.csv"));
    let uav2 = read_trace(&traces.join("uav2.trace.csv"));
    let keys = |t: &Trace| t.keys().cloned().collect::<Vec<_>>();
    assert_eq!(keys(&uav1), keys(&uav2), "the two agents did not tick the same rounds");
    let rounds: BTreeSet<u64> = uav1.keys().map(|(r, _, _)| *r).collect();
    let last = *rounds.iter().max().expect("rounds");
    assert_eq!(rounds, (0..=last).collect(), "rounds are not consecutive from 0");
    assert!(
        uav1.keys().filter(|(_, kind, _)| kind == "stop").all(|(r, _, _)| *r == last),
        "the run did not stop for everyone at the last round"
    );
    // Every flag UAV2 sent at tick t is in UAV1's state at tick t+1 of the same episode
    // (UAV1's vector for UAV2 is entries 0..5), and vice versa (UAV2's vector for UAV1).
    let mut checked = 0;
    for (sender, receiver) in [(&uav2, &uav1), (&uav1, &uav2)] {
        for ((round, kind, trial), (episode, tick, wp, sees, _)) in sender.iter() {
            let next = (round + 1, "tick".to_string(), *trial);
            let Some((next_episode, next_tick, _, _, comm)) = receiver.get(&next) else { continue };
            if kind != "tick" || next_episode != episode || *next_tick != tick + 1 {
                continue;
            }
            assert!(entry(comm, *wp) > *sees, "round {round} trial {trial}: flag (wp{}, {sees}) is not in the receiver's state at the next tick", wp + 1);
            checked += 1;
        }
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
    for run in runs {
        let (out, report) = run.finish(RUN_BOUND);
        assert!(out.status.success(), "{report}");
    }
    for i in 0..2 {
        let twin = scratch();
        supervise(twin.path(), &[&run(i)[..], &["--transport", "inproc"]].concat());
        assert_same_results(dirs[i].path(), twin.path());
        assert!(leftover_files(&ids[i]).expect("list files").is_empty());
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
