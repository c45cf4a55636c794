//! Q-table snapshots put to use (issue 5): `supervisor eval --qtables DIR` evaluates a
//! finished run greedily on the same setup, and `--resume DIR` continues learning from it.

use crate::harness::{
    assert_nothing_left, episode_rows, error_line, first_gap, mean_length, notes, number, read,
    repo_file, run_fail, run_id, run_ok, scratch, summary, supervise, wait_for_records, words,
    Spawned, SUPERVISOR,
};
use flockstep_agents::snapshot::{read_snapshot, snapshot_path};
use std::time::Duration;

/// On s2, whose two targets are drawn at random, `eval` of as many episodes as the run's
/// own final evaluation (1000, both by default) flies the same episodes, so its greedy
/// length is the run's to the last digit: a different draw of targets, seed or tables
/// would show.
#[test]
fn eval_reproduces_the_greedy_result_of_the_run_in_both_transports() {
    let dir = scratch();
    let run = supervise(
        dir.path(),
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
                "1000",
                "--transport",
                transport,
                "--out",
                &out_arg,
            ],
        );
        // The run's own greedy length, as `eval` prints it (two decimals, then the count of
        // truncated episodes).
        let expected = format!("UAV1 greedy episode length {greedy:.2} (");
        let text = String::from_utf8_lossy(&printed.stdout);
        assert!(text.starts_with(&expected), "{transport}: `{expected}` expected:\n{text}");
        let evaluated = summary(&out);
        // `eval` takes no --run-id: its run id (of pid and time) is in its summary.
        let id = evaluated["run_id"].as_str().expect("the evaluation's run id");
        assert_nothing_left(id);
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
    let resumed_run = supervise(second.path(), &[&continued[..], &["--resume", &resume]].concat());
    // The summary records what the run resumed from, as the absolute directory.
    let absolute = first.path().canonicalize().expect("the first run's directory");
    assert_eq!(resumed_run["resume"], absolute.display().to_string(), "{resumed_run:#}");
    let fresh = scratch();
    assert_eq!(supervise(fresh.path(), &continued)["resume"], serde_json::Value::Null);
    let (resumed, scratch_mean) =
        (mean_length(&episode_rows(second.path())), mean_length(&episode_rows(fresh.path())));
    // Where the first run left off: its last 200 episodes (of every trial).
    let learned: Vec<[u64; 6]> =
        episode_rows(first.path()).into_iter().filter(|row| row[2] >= 2800).collect();
    let learned = mean_length(&learned);
    assert!(
        resumed < learned * 1.25 && resumed < scratch_mean / 2.0,
        "resumed {resumed} vs where the first run left off {learned} and from scratch \
         {scratch_mean}"
    );
}

/// A resumed run's agent that fails before its first periodic snapshot (`--snapshot-every`,
/// 10 000 episodes) is restarted from the tables the run resumed from, which the run copied
/// into its own `qtables/`: it used to be pointed at `--out`, which held none yet, and
/// started from empty tables while the summary said "from its latest snapshot".
#[test]
fn an_agent_restarted_before_its_first_snapshot_goes_on_from_the_resumed_tables() {
    let first = scratch();
    let setup = words("--scenario s3 --uavs 2 --trials 1 --seed 5");
    supervise(first.path(), &[&setup[..], &words("--transport inproc --episodes 3000")].concat());
    let second = scratch();
    let (id, resume) = (run_id("resume-restart"), first.path().display().to_string());
    let resumed = words("--transport shm --episodes 600 --eval-episodes 0 --restart on-failure");
    let fault = ["--fault", "1=crash-at-round=300", "--resume", &resume, "--run-id", &id];
    let s = supervise(second.path(), &[&setup[..], &resumed, &fault].concat());
    assert_nothing_left(&id);
    let notes = s["notes"].to_string();
    assert!(notes.contains("UAV1 restarted from its latest snapshot"), "{notes}");
    assert!(!notes.contains("empty tables"), "{notes}");
    let log = std::fs::read_to_string(second.path().join("logs").join("uav1.restart1.log"))
        .expect("the restarted agent's log");
    assert!(!log.contains("starts from scratch"), "{log}");
    let uav1 = |dir: &std::path::Path| -> Vec<[u64; 6]> {
        episode_rows(dir).into_iter().filter(|r| r[1] == 1).collect()
    };
    let rows = uav1(second.path());
    let gap = first_gap(&rows).expect("a gap where UAV1 was down");
    let (untrained, after) =
        (mean_length(&uav1(first.path())[..200]), mean_length(&rows[gap + 1..]));
    assert!(
        after < untrained / 2.0,
        "restarted from empty tables? untrained {untrained}, after the restart {after}"
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
    // A copy of s1 edited but for its name is another map (its name alone used to pass).
    let edited = dir.path().join("s1-edited.map");
    let s1 = String::from_utf8(read(&repo_file("world/maps/s1_one_uav_one_target.map"))).unwrap();
    std::fs::write(&edited, s1.replacen("grid:\n.  ", "grid:\nX  ", 1)).unwrap();
    let out = dir.path().join("edited").display().to_string();
    let args = ["--scenario", &edited.display().to_string(), "--uavs", "1", "--trials", "1"];
    let rest = ["--episodes", "5", "--resume", &qtables, "--out", &out, "--quiet"];
    let expected = ["learned on another map named `s1_one_uav_one_target`: line 5 ", "`X  . "];
    refused(&[&args[..], &rest].concat(), &out, &expected);
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

/// Agents that cannot write their final Q-tables lose results: the run ends with an error
/// naming the file and status 1 on both transports, everything else written (over shared
/// memory it used to exit 0 with `"complete": true`, in-process 1). Here `qtables` is a file.
#[test]
fn a_run_whose_final_q_tables_cannot_be_written_fails_naming_the_file() {
    for transport in ["inproc", "shm"] {
        let dir = scratch();
        std::fs::write(dir.path().join("qtables"), b"not a directory").expect("write a file");
        let (out, id) = (dir.path().display().to_string(), run_id("unsaved"));
        let args = words("--scenario s3 --uavs 2 --trials 2 --episodes 300 --quiet");
        let rest = ["--transport", transport, "--out", &out, "--run-id", &id];
        let (printed, report) = run_fail(SUPERVISOR, &[&args[..], &rest].concat());
        assert_eq!(printed.status.code(), Some(1), "{transport}: {report}");
        let stderr = String::from_utf8_lossy(&printed.stderr);
        let error = stderr.lines().last().unwrap_or_default();
        // Over shared memory the agents fail in the stop round, which they answer once their
        // tables are written: the world names them and fails, and the run with it. Either
        // agent may be the first to fail, and named.
        let named = |uav: usize| {
            let file = dir.path().join("qtables").join(format!("uav{uav}_trial0.bin"));
            error.contains(&format!("cannot write {}", file.display()))
        };
        assert!(
            error.starts_with("supervisor: error: ")
                && error.contains("final Q-tables")
                && (named(1) || named(2)),
            "{transport}: {report}"
        );
        let s = summary(dir.path());
        assert_eq!(s["complete"], false, "{transport}: {s:#}");
        let notes = s["notes"].as_array().expect("notes");
        let last = notes.last().and_then(|n| n.as_str()).unwrap_or_default();
        assert!(error.ends_with(last), "{transport}: the error is not the last note: {s:#}");
        assert_eq!(episode_rows(dir.path()).len(), 2 * 2 * 300, "{transport}: episodes lost");
        assert!(dir.path().join("curve.csv").exists(), "{transport}: no curve.csv");
        assert_nothing_left(&id);
    }
}

/// Ctrl-C during `eval` stops it as it stops a run: what was evaluated is printed and
/// written, flagged `"complete": false`, and the status is 130 (it used to be 1).
#[test]
fn an_evaluation_stopped_by_ctrl_c_exits_130_with_partial_results() {
    let dir = scratch();
    supervise(
        dir.path(),
        &words("--transport inproc --scenario s1 --uavs 1 --trials 1 --episodes 200"),
    );
    let qtables = dir.path().display().to_string();
    let eval = Spawned::supervisor(&["eval", "--qtables", &qtables, "--episodes", "100000000"]);
    let greedy = dir.path().join("eval").join("greedy_episodes.csv");
    wait_for_records(&greedy, 1000, Duration::from_secs(60));
    eval.interrupt();
    let (printed, report) = eval.finish(Duration::from_secs(120));
    assert_eq!(printed.status.code(), Some(130), "{report}");
    let stdout = String::from_utf8_lossy(&printed.stdout);
    assert!(stdout.starts_with("UAV1 greedy episode length "), "{report}");
    assert!(String::from_utf8_lossy(&printed.stderr).contains("stopped early"), "{report}");
    assert_eq!(summary(&dir.path().join("eval"))["complete"], false);
}

/// `eval` of a run stopped by Ctrl-C evaluated what it had learned by then and said nothing
/// of it: `"complete": true` and no notes. It says so on stderr and in its notes.
#[test]
fn eval_of_a_run_that_did_not_complete_says_so() {
    let dir = scratch();
    let out = dir.path().display().to_string();
    let setup = words("--transport inproc --scenario s1 --uavs 1 --trials 1 --episodes 100000000");
    let run = Spawned::supervisor(&[&setup[..], &["--quiet", "--out", &out]].concat());
    let episodes = dir.path().join("episodes.csv");
    wait_for_records(&episodes, 1000, Duration::from_secs(60));
    run.interrupt();
    let (stopped, report) = run.finish(Duration::from_secs(120));
    assert_eq!(stopped.status.code(), Some(130), "{report}");
    let printed = run_ok(SUPERVISOR, &["eval", "--qtables", &out, "--episodes", "5"]);
    let note = format!(
        "eval evaluates the Q-tables of a run that did not complete ({} says \"complete\": \
         false): what it had learned when it stopped",
        dir.path().join("summary.json").display()
    );
    let stderr = String::from_utf8_lossy(&printed.stderr);
    assert!(stderr.contains(&format!("supervisor: {note}")), "{stderr}");
    let evaluated = summary(&dir.path().join("eval"));
    assert_eq!(evaluated["complete"], true, "the evaluation itself ran to its end");
    assert_eq!(notes(&evaluated), [note.as_str()]);
}
