//! Q-table snapshots put to use (issue 5): `supervisor eval --qtables DIR` evaluates a
//! finished run greedily on the same setup, and `--resume DIR` continues learning from it.

use crate::harness::{
    episode_rows, error_line, number, run_ok, scratch, summary, supervise, words, SUPERVISOR,
};
use flockstep_agents::snapshot::{read_snapshot, snapshot_path};

#[test]
fn eval_reproduces_the_greedy_result_of_the_run_in_both_transports() {
    let dir = scratch();
    let run = supervise(
        dir.path(),
        &[
            "--transport",
            "inproc",
            "--scenario",
            "s1",
            "--uavs",
            "1",
            "--episodes",
            "3000",
            "--seed",
            "3",
        ],
    );
    let greedy = number(&run, "greedy_episode_length", 0);
    for transport in ["inproc", "shm"] {
        let out = dir.path().join(format!("eval-{transport}"));
        let out_arg = out.display().to_string();
        let qtables = dir.path().display().to_string();
        let printed = run_ok(
            SUPERVISOR,
            &[
                "eval",
                "--qtables",
                &qtables,
                "--episodes",
                "200",
                "--transport",
                transport,
                "--out",
                &out_arg,
            ],
        );
        let text = String::from_utf8_lossy(&printed.stdout);
        assert!(text.contains("UAV1 greedy episode length 13"), "{transport}: {text}");
        let evaluated = summary(&out);
        assert_eq!(number(&evaluated, "greedy_episode_length", 0), greedy, "{transport}");
        assert_eq!(evaluated["episodes"], 0, "an evaluation does not train");
        assert!(episode_rows(&out).is_empty(), "an evaluation has no training episodes");
    }
}

#[test]
fn resume_continues_from_the_learned_level() {
    let first = scratch();
    supervise(
        first.path(),
        &[
            "--transport",
            "inproc",
            "--scenario",
            "s2",
            "--uavs",
            "1",
            "--episodes",
            "3000",
            "--seed",
            "5",
        ],
    );
    let second = scratch();
    let resume = first.path().display().to_string();
    let continued = words("--transport inproc --scenario s2 --uavs 1 --episodes 200 --seed 6");
    supervise(second.path(), &[&continued[..], &["--resume", &resume]].concat());
    let fresh = scratch();
    supervise(fresh.path(), &continued);
    let mean = |dir: &std::path::Path| {
        let rows = episode_rows(dir);
        rows.iter().map(|r| r[4] as f64).sum::<f64>() / rows.len() as f64
    };
    let (resumed, scratch_mean) = (mean(second.path()), mean(fresh.path()));
    assert!(
        resumed < 20.0 && resumed < scratch_mean / 2.0,
        "resumed {resumed} vs from scratch {scratch_mean}"
    );
}

/// A snapshot is checked by the supervisor before any process starts: one error line that
/// names the file and what is wrong, on both transports (over shared memory it used to be an
/// agent dying mid-run and the world failing for want of agents).
#[test]
fn a_snapshot_that_does_not_fit_the_run_is_refused_in_one_line_before_it_starts() {
    let dir = scratch();
    supervise(
        dir.path(),
        &words("--transport inproc --scenario s1 --uavs 1 --trials 1 --episodes 50"),
    );
    let qtables = dir.path().display().to_string();
    // `out` would hold the processes' logs had any started.
    let refused = |args: &[&str], out: &str, expected: &[&str]| {
        let line = error_line(args);
        assert!(expected.iter().all(|e| line.contains(e)), "{line}");
        assert!(!std::path::Path::new(out).join("logs").exists(), "a process started: {line}");
    };
    for transport in ["inproc", "shm"] {
        let out = dir.path().join(format!("other-{transport}")).display().to_string();
        let args = ["--scenario", "s2", "--uavs", "1", "--trials", "1", "--episodes", "5"];
        let rest = ["--resume", &qtables, "--transport", transport, "--out", &out, "--quiet"];
        let expected = ["--resume", "uav1_trial0.bin", "learned with scenario"];
        refused(&[&args[..], &rest].concat(), &out, &expected);
    }
    let path = snapshot_path(dir.path(), 0, 0);
    let mut snapshot = read_snapshot(&path).expect("readable").expect("the run saved trial 0");
    snapshot.tables[0].step(0, 1, f64::NAN, 1.0);
    let bytes = bincode::serde::encode_to_vec(&snapshot, bincode::config::standard()).unwrap();
    std::fs::write(&path, bytes).unwrap();
    for transport in ["inproc", "shm"] {
        let out = dir.path().join(format!("eval-{transport}")).display().to_string();
        let args = ["eval", "--qtables", &qtables, "--transport", transport, "--out", &out];
        // Named by the eval's own flag: the user gave no --resume.
        let expected = ["error: eval --qtables", "uav1_trial0.bin", "Q(state 0, child 2) is NaN"];
        refused(&args, &out, &expected);
    }
    let out = dir.path().join("eval-missing").display().to_string();
    let args = ["eval", "--qtables", &qtables, "--out", &out];
    std::fs::remove_file(&path).unwrap();
    let expected = ["error: eval --qtables", "no snapshot", "uav1_trial0.bin (UAV1, trial 0)"];
    refused(&args, &out, &expected);
    std::fs::remove_file(dir.path().join("tree.bt")).unwrap();
    refused(&args, &out, &["error: eval --qtables", "no tree.bt"]);
}
