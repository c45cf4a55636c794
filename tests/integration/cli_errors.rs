//! Bad input (issue 3, acceptance 6): an unknown scenario, an unreadable tree, `--uavs 0`,
//! more UAVs than routes, a results directory that cannot be written or that holds an
//! earlier run, settings that would make a run meaningless, bad test aids, a run flag typed
//! where its subcommand would ignore it or does not take it. Each gives one clear error line
//! naming the problem and a non-zero exit, for both transports, before any process of the
//! run starts.

use crate::harness::{
    assert_nothing_left, error_line, first_difference, read, repo_file, run_fail, run_id, run_ok,
    scratch, summary, supervise, words, Spawned, AGENT, SUPERVISOR,
};
use flockstep_supervisor::results::RUN_OUTPUTS;
use std::time::Duration;

/// Runs the supervisor with `args` on both transports (10 episodes unless `args` give
/// `--episodes`), results into `out`, a directory no run wrote to; `check` looks at the error
/// line. No process of the run may have started, and nothing of it may be left behind.
fn fails_on_both_transports(out: &str, args: &[&str], check: impl Fn(&str, &str)) {
    let id = run_id("bad-input");
    for transport in ["inproc", "shm"] {
        let mut all = args.to_vec();
        all.extend(["--transport", transport, "--out", out, "--quiet", "--run-id", &id]);
        if !args.contains(&"--episodes") {
            all.extend(["--episodes", "10"]);
        }
        let line = error_line(&all);
        check(&line, transport);
        // `out` would hold the processes' logs had any started.
        let logs = std::path::Path::new(out).join("logs");
        assert!(!logs.exists(), "a process of the run started ({transport}): {line}");
        assert_nothing_left(&id);
    }
}

/// The error line must mention every word of `expected`.
fn for_both_transports(args: &[&str], expected: &[&str]) {
    let dir = scratch();
    let out = dir.path().join("out").display().to_string();
    fails_on_both_transports(&out, args, |line, transport| {
        for word in expected {
            assert!(line.contains(word), "`{line}` should mention `{word}` ({transport})");
        }
    });
}

#[test]
fn unknown_scenario() {
    for_both_transports(&["--scenario", "s9"], &["unknown scenario `s9`", "s1, s2, s3, s4"]);
}

#[test]
fn unreadable_tree() {
    for_both_transports(
        &["--bt", "/nonexistent/tree.bt"],
        &["cannot read tree file", "/nonexistent/tree.bt"],
    );
}

#[test]
fn malformed_tree_names_file_line_and_column() {
    let dir = scratch();
    let tree = dir.path().join("bad.bt");
    std::fs::write(&tree, "OR 2\n- A-fly 0\n- A-rotate 0\n").expect("write the tree");
    let tree = tree.display().to_string();
    for_both_transports(&["--bt", &tree], &[&format!("{tree}:2:3:"), "unknown action `fly`"]);
}

#[test]
fn trees_past_the_engine_limits_name_file_and_line() {
    let dir = scratch();
    let wide = dir.path().join("wide.bt");
    // Conditions issue no commands, so only the width is past a limit.
    let children = "-- C-seeTarget 0\n".repeat(65);
    std::fs::write(&wide, format!("OR 1\n- LOR 65\n{children}")).expect("write the tree");
    let wide = wide.display().to_string();
    for_both_transports(
        &["--bt", &wide],
        &[&format!("{wide}:2:"), "learning selector has 65 children; the limit is 64"],
    );
    let busy = dir.path().join("busy.bt");
    std::fs::write(&busy, "REPEAT 1 n=17\n- A-rotate 0\n").expect("write the tree");
    let busy = busy.display().to_string();
    for_both_transports(
        &["--bt", &busy],
        &[&format!("{busy}:1:"), "up to 17 commands in one tick; the limit is 16"],
    );
}

#[test]
fn zero_uavs() {
    for_both_transports(&["--uavs", "0"], &["--uavs must be at least 1"]);
}

#[test]
fn more_uavs_than_routes() {
    for_both_transports(&["--uavs", "3", "--scenario", "s3"], &["--uavs 3", "2 route"]);
}

#[test]
fn more_uavs_than_supported() {
    for_both_transports(&["--uavs", "65"], &["--uavs 65", "64"]);
}

#[test]
fn results_directory_that_cannot_be_written() {
    let dir = scratch();
    let file = dir.path().join("a-file");
    std::fs::write(&file, b"").expect("write a file");
    let out = file.join("results").display().to_string();
    fails_on_both_transports(&out, &[], |line, transport| {
        assert!(line.contains("results directory") && line.contains(&out), "{line} ({transport})");
    });
    // A file given as the directory is named as such (it used to say "File exists").
    let file = file.display().to_string();
    fails_on_both_transports(&file, &[], |line, transport| {
        let expected = format!("results directory {file}: is a file, not a directory");
        assert!(line.contains(&expected), "{line} ({transport})");
    });
}

/// A results file that cannot be written fails the run, and the files after it are written
/// all the same: before, a `curve.csv` that could not be written left no `curve.svg` and no
/// `summary.json`, the one file with the run's timings and notes.
#[test]
fn the_summary_is_written_when_a_file_before_it_cannot_be() {
    for transport in ["inproc", "shm"] {
        let dir = scratch();
        std::fs::create_dir(dir.path().join("curve.csv"))
            .expect("a directory in curve.csv's place");
        let out = dir.path().display().to_string();
        let id = run_id("curve-unwritable");
        let args = words("--scenario s3 --uavs 2 --episodes 20 --trials 1 --quiet");
        let line = error_line(
            &[&args[..], &["--transport", transport, "--out", &out, "--run-id", &id]].concat(),
        );
        let expected = format!(
            "supervisor: error: cannot write {out}/curve.csv: Is a directory (os error 21)"
        );
        assert_eq!(line, expected, "{transport}");
        let summary = summary(dir.path());
        assert_eq!(summary["complete"], true, "{transport}: {summary:#}");
        for written in ["greedy_curve.csv", "curve.svg", "episodes.csv"] {
            assert!(dir.path().join(written).is_file(), "{transport}: no {written}");
        }
        assert_nothing_left(&id);
    }
}

/// A repeated command must not silently replace a finished run: `--out` holding one is
/// refused unless `--overwrite`, which removes exactly what a run writes (a run's own
/// listing is checked against that list) and never the snapshots `--resume` starts from.
#[test]
fn an_earlier_runs_results_are_kept_unless_overwrite_is_given() {
    let dir = scratch();
    let out = dir.path().join("run");
    let out_arg = out.display().to_string();
    let run = |extra: &[&str]| -> Vec<String> {
        let id = run_id("overwrite");
        let common = ["--transport", "shm", "--out", &out_arg, "--quiet", "--run-id", &id];
        words("--scenario s1 --uavs 1 --trials 1 --episodes 20 --eval-episodes 5")
            .into_iter()
            .chain(common)
            .chain(extra.iter().copied())
            .map(String::from)
            .collect()
    };
    run_ok(SUPERVISOR, &as_strs(&run(&[])));
    run_ok(SUPERVISOR, &["eval", "--qtables", &out_arg, "--episodes", "3"]);
    let written: Vec<String> = std::fs::read_dir(&out)
        .expect("the results directory")
        .map(|e| e.expect("an entry").file_name().to_string_lossy().into_owned())
        .collect();
    for name in &written {
        assert!(RUN_OUTPUTS.contains(&name.as_str()), "`{name}` is not in RUN_OUTPUTS");
    }
    let episodes = read(&out.join("episodes.csv"));
    let unchanged = |refused: &str| {
        if let Some(difference) = first_difference(&read(&out.join("episodes.csv")), &episodes) {
            panic!("the refused run ({refused}) changed the results: {difference}");
        }
    };

    let line = error_line(&as_strs(&run(&[])));
    assert!(
        line.contains(&format!("results directory {out_arg}: holds the results of an earlier run")),
        "{line}"
    );
    assert!(line.contains("--overwrite"), "{line}");
    unchanged("no --overwrite");
    let line = error_line(&as_strs(&run(&["--overwrite", "--resume", &out_arg])));
    assert!(line.contains("is the results directory it would replace"), "{line}");
    assert!(out.join("qtables").join("uav1_trial0.bin").exists(), "the snapshots were removed");
    // The copy of the tables `eval` wrote is removed with `eval/`: refused before anything
    // is removed (the earlier run and the tables used to go, and the run failed).
    let evaluated = out.join("eval").display().to_string();
    let line = error_line(&as_strs(&run(&["--overwrite", "--resume", &evaluated])));
    let expected = format!("--resume {evaluated} would be removed by --overwrite");
    assert!(line.contains(&expected) && line.contains("give another --out"), "{line}");
    let copied = out.join("eval").join("qtables").join("uav1_trial0.bin");
    assert!(copied.exists(), "the snapshots to resume from were removed");
    unchanged("--resume inside eval/");

    let stale = out.join("qtables").join("uav7_trial0.bin");
    std::fs::write(&stale, b"from another run").unwrap();
    std::fs::write(out.join("notes.txt"), b"the user's own").unwrap();
    run_ok(SUPERVISOR, &as_strs(&run(&["--overwrite", "--seed", "2"])));
    assert!(!stale.exists(), "an earlier run's snapshot was left beside the new ones");
    assert!(!out.join("eval").exists(), "the earlier run's evaluation was left");
    assert!(out.join("notes.txt").exists(), "a file no run writes was removed");
    assert_ne!(read(&out.join("episodes.csv")), episodes, "not replaced by the seed-2 run");
}

/// A second run given the `--out` of a run still writing there is refused, `--overwrite` or
/// not, and the first run's results are untouched: before, `--overwrite` removed them while
/// the first run went on, and the two runs' files ended up mixed (a user test).
#[test]
fn the_results_directory_of_a_live_run_is_refused() {
    let dir = scratch();
    let out = dir.path().display().to_string();
    let id = run_id("live-out");
    let args = ["--transport", "shm", "--run-id", &id, "--out", &out, "--quiet"];
    let rest = words("--scenario s3 --uavs 2 --episodes 10000000 --trials 1");
    let live = Spawned::start(SUPERVISOR, &[&args[..], &rest[..]].concat());
    let episodes = dir.path().join("episodes.csv");
    crate::harness::wait_for_records(&episodes, 10_000, Duration::from_secs(60));
    // Without --overwrite the second run was told to give it, as if the results were old.
    for (transport, overwrite) in [("shm", "--overwrite"), ("inproc", "--overwrite"), ("shm", "")] {
        let second = ["--transport", transport, "--out", &out, overwrite, "--episodes", "10"];
        let second: Vec<&str> = second.into_iter().filter(|arg| !arg.is_empty()).collect();
        let line = error_line(&[&second[..], &["--scenario", "s3", "--uavs", "2"]].concat());
        let expected = format!("--out {out}: another run is writing its results there");
        assert!(line.contains(&expected), "{transport} {overwrite}: {line}");
    }
    assert!(std::fs::metadata(&episodes).is_ok_and(|m| m.len() > 10_000), "removed");
    live.interrupt();
    let (status, report) = live.finish(Duration::from_secs(120));
    assert_eq!(status.status.code(), Some(130), "{report}");
    assert_eq!(summary(dir.path())["run_id"], id.as_str(), "{report}");
    assert_nothing_left(&id);
}

#[test]
fn settings_that_would_make_a_run_meaningless() {
    for_both_transports(&["--agent-timeout-ms", "0"], &["--agent-timeout-ms must be at least 1"]);
    for_both_transports(&["--smoothing", "0"], &["--smoothing must be at least 1"]);
    for_both_transports(
        &["--smoothing", "100000", "--episodes", "100"],
        &["--smoothing 100000 is more than the 100 training episodes of a trial"],
    );
    // A negative value is a value out of range, not an unknown flag `-1`.
    for_both_transports(&["--alpha", "-1"], &["--alpha -1 is out of range [0, 1]"]);
    for_both_transports(&["--epsilon", "1.5"], &["--epsilon 1.5 is out of range [0, 1]"]);
    for_both_transports(
        &["--eval-every", "5", "--eval-block", "0"],
        &["--eval-every 5 needs an --eval-block of at least 1"],
    );
    let dir = scratch();
    let line =
        error_line(&["eval", "--qtables", &dir.path().display().to_string(), "--episodes", "0"]);
    assert!(line.contains("eval --episodes must be at least 1"), "{line}");
}

/// Counts a run could not count or keep are refused by the flags that make them, before the
/// run: they used to overflow, or to allocate a total per periodic evaluation up front.
#[test]
fn episode_counts_past_what_a_run_can_count_or_keep() {
    let most = u64::MAX.to_string();
    for_both_transports(
        &["--episodes", &most, "--trials", "2"],
        &[&format!(
            "--episodes {most} with --trials 2: more training episodes in all than a run can count"
        )],
    );
    for_both_transports(
        &["--eval-every", "1", "--episodes", "10000000000"],
        &["--eval-every 1 with --episodes 10000000000: 9999999999 periodic greedy evaluations per trial, at most 100000 are supported"],
    );
    for_both_transports(
        &["--eval-every", "1000", "--episodes", "2001", "--eval-block", &most],
        &[&format!("--eval-block {most} with --eval-episodes 1000: 2 blocks and the final evaluation are more greedy episodes per trial than a run can count")],
    );
}

/// `eval` takes its settings from the run's `summary.json`: a value there that does not fit
/// is named with its file and field, not cut short, and not as the command-line flag it
/// stands for (`--trials 0 is out of range`, which the user never typed).
#[test]
fn eval_refuses_a_summary_value_out_of_range_naming_the_file_and_field() {
    let dir = scratch();
    for file in ["scenario.map", "tree.bt"] {
        std::fs::write(dir.path().join(file), b"").expect("write a file");
    }
    let qtables = dir.path().display().to_string();
    let summary_json = format!("{qtables}/summary.json");
    for (fields, expected) in [
        (
            r#""uavs": 1, "trials": 1, "tick_cap": 4294967296, "comm": "none""#,
            "`tick_cap` 4294967296 is out of range 1..=4294967295",
        ),
        (
            r#""uavs": 1, "trials": 0, "tick_cap": 100, "comm": "none""#,
            "`trials` 0 is out of range 1..=",
        ),
        (
            r#""uavs": 0, "trials": 1, "tick_cap": 100, "comm": "none""#,
            "`uavs` 0 is out of range 1..=",
        ),
        (
            r#""uavs": 1, "trials": 1, "tick_cap": 0, "comm": "none""#,
            "`tick_cap` 0 is out of range",
        ),
        (
            r#""uavs": 1, "trials": 1, "tick_cap": 100, "comm": "loud""#,
            "`comm` \"loud\" is none of none, flags, compact",
        ),
        (r#""trials": 1, "tick_cap": 100, "comm": "none""#, "no whole number `uavs`"),
    ] {
        let summary = format!(r#"{{"seed": 1, {fields}}}"#);
        std::fs::write(dir.path().join("summary.json"), summary).expect("write summary.json");
        let line = error_line(&["eval", "--qtables", &qtables]);
        assert!(line.contains(&format!("{summary_json}: {expected}")), "{line}");
    }
    // More agents than the run's map has routes: named in the summary, beside the map.
    let s1 = crate::harness::repo_file("world/maps/s1_one_uav_one_target.map");
    std::fs::copy(s1, dir.path().join("scenario.map")).expect("copy a map");
    let summary = r#"{"uavs": 2, "trials": 1, "seed": 1, "tick_cap": 100, "comm": "none"}"#;
    std::fs::write(dir.path().join("summary.json"), summary).expect("write summary.json");
    let line = error_line(&["eval", "--qtables", &qtables]);
    let expected = format!("{summary_json}: `uavs` 2, but its scenario.map has 1 route(s)");
    assert!(line.ends_with(&expected), "{line}");
}

/// Flags that watch or shape agent processes are refused by an in-process run, which has
/// none, as other ignored flags are (a bad value is named as such first: see
/// `settings_that_would_make_a_run_meaningless`).
#[test]
fn an_in_process_run_refuses_the_flags_of_agent_processes() {
    let dir = scratch();
    let out = dir.path().join("out");
    let (out_arg, traces) = (out.display().to_string(), dir.path().join("t").display().to_string());
    for (flag, value) in [
        ("--restart", "on-failure"),
        ("--snapshot-every", "100"),
        ("--agent-timeout-ms", "900"),
        ("--fault", "1=crash-at-round=5"),
        ("--trace-dir", &traces),
    ] {
        let args = [flag, value, "--transport", "inproc", "--out", &out_arg, "--episodes", "10"];
        let line = error_line(&args);
        assert!(
            line.contains(&format!("{flag} applies to agent processes"))
                && line.contains("(--transport inproc)"),
            "{line}"
        );
        assert!(!out.join("episodes.csv").exists(), "{flag}: the run started");
    }
}

/// `plot` draws SVG only: a file named for another format used to get SVG and exit 0.
#[test]
fn plot_refuses_a_file_name_for_another_format_than_svg() {
    let dir = scratch();
    let curve = dir.path().join("curve.csv");
    let text = "episode,agent,mean_length,smoothed_length\n0,1,40,40\n1,1,30,35\n";
    std::fs::write(&curve, text).expect("write curve.csv");
    let spec = format!("{}=a run", curve.display());
    for name in ["both.png", "both", "both.svg.pdf"] {
        let out = dir.path().join(name);
        let line = error_line(&["plot", "--curve", &spec, "--out", &out.display().to_string()]);
        assert!(line.contains("plots are written as SVG only") && line.contains(name), "{line}");
        assert!(!out.exists(), "{name} was written");
    }
    let out = dir.path().join("both.svg");
    let printed =
        run_ok(SUPERVISOR, &["plot", "--curve", &spec, "--out", &out.display().to_string()]);
    assert!(read(&out).starts_with(b"<svg"), "not an SVG");
    assert_eq!(String::from_utf8_lossy(&printed.stdout).trim(), out.display().to_string());
}

/// Output that cannot be written used to panic (status 101 and a backtrace): stdout closed by
/// its reader (`supervisor optimum | head -2`) ends quietly with the command's status, a
/// full stdout is one error line, and a stderr that cannot be written is ignored.
#[test]
fn output_that_cannot_be_written_never_panics() {
    let dir = scratch();
    let stderr_file = dir.path().join("stderr");
    let run = |args: &[&str], stdout: std::process::Stdio, stderr: std::process::Stdio| {
        let mut cmd = std::process::Command::new(SUPERVISOR);
        cmd.args(args).stdout(stdout).stderr(stderr);
        Spawned::spawn(cmd).finish(Duration::from_secs(60)).0.status
    };
    let stderr = || std::fs::File::create(&stderr_file).expect("a stderr file").into();
    let full = || std::fs::File::create("/dev/full").expect("/dev/full").into();
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let status = run(&["optimum", "--scenario", "s4"], writer.into(), stderr());
    let said = String::from_utf8_lossy(&read(&stderr_file)).into_owned();
    assert_eq!((status.code(), said.as_str()), (Some(0), ""), "stdout closed by its reader");
    let status = run(&["optimum", "--scenario", "s4"], full(), stderr());
    let said = String::from_utf8_lossy(&read(&stderr_file)).into_owned();
    assert_eq!(status.code(), Some(1), "stdout full: {said}");
    assert_eq!(
        said,
        "supervisor: error: cannot write to stdout: No space left on device (os error 28)\n"
    );
    let status = run(&["--uavs", "0"], std::process::Stdio::null(), full());
    assert_eq!(status.code(), Some(1), "stderr full, on an error");
}

/// `plot` reads `curve.csv` files it did not write: `inf`, `NaN` or `1e400` there used to
/// reach plotters, which never returned from an axis up to infinity.
#[test]
fn plot_refuses_a_curve_whose_length_is_not_finite() {
    let dir = scratch();
    let curve = dir.path().join("curve.csv");
    let out = dir.path().join("both.svg");
    for bad in ["inf", "NaN", "1e400", "-3"] {
        let text = format!("episode,agent,mean_length,smoothed_length\n0,1,40,40\n1,1,41,{bad}\n");
        std::fs::write(&curve, text).expect("write curve.csv");
        let spec = format!("{}=bad", curve.display());
        let line = error_line(&["plot", "--curve", &spec, "--out", &out.display().to_string()]);
        let expected =
            format!("{}:3: smoothed_length `{bad}` is not an episode length", curve.display());
        assert!(line.contains(&expected), "{line}");
        assert!(!out.exists(), "a plot was drawn from `{bad}`");
    }
}

/// The hidden test aids are input too: a bad one is refused before any agent runs, not
/// by an agent failing in the middle of the run.
#[test]
fn bad_test_aids_are_refused_before_the_run() {
    for_both_transports(
        &["--fault", "1=crash-at-round=soon"],
        &["--fault", "`soon` is not a round"],
    );
    let dir = scratch();
    let file = dir.path().join("a-file");
    std::fs::write(&file, b"").expect("write a file");
    let traces = file.join("traces").display().to_string();
    let out = dir.path().join("out").display().to_string();
    let id = run_id("bad-trace-dir");
    let args =
        ["--trace-dir", &traces, "--out", &out, "--episodes", "10", "--quiet", "--run-id", &id];
    let line = error_line(&args);
    assert!(line.contains("--trace-dir: cannot create") && line.contains(&traces), "{line}");
    assert!(!dir.path().join("out").join("logs").join("world.log").exists(), "the world started");
    assert_nothing_left(&id);
}

/// A run flag before a subcommand that would ignore it is refused, not dropped: before,
/// `--episodes 100 reproduce fig10` ran the 50 000 episodes of reproduce's own default.
#[test]
fn run_flags_a_subcommand_would_ignore_are_refused() {
    let dir = scratch();
    let out = dir.path().join("fig10").display().to_string();
    let line = error_line(&["--episodes", "100", "reproduce", "fig10", "--out", &out]);
    assert!(line.contains("--episodes before `reproduce` would be ignored"), "{line}");
    assert!(line.contains("give it after `reproduce`"), "{line}");
    let line = error_line(&["--uavs", "3", "optimum", "--scenario", "s1"]);
    assert!(line.contains("--uavs is a flag of a run, which `optimum` does not use"), "{line}");
    let line = error_line(&["--seed", "2", "eval", "--qtables", &out]);
    assert!(line.contains("--seed is a flag of a run, which `eval` does not use"), "{line}");
    assert!(!dir.path().join("fig10").exists(), "a refused command started a run");
    // What a subcommand does use is still taken from before it.
    let printed = run_ok(
        SUPERVISOR,
        &[
            "--quiet",
            "--tick-cap",
            "50",
            "reproduce",
            "fig10",
            "--episodes",
            "20",
            "--trials",
            "1",
            "--transport",
            "inproc",
            "--out",
            &out,
        ],
    );
    assert!(String::from_utf8_lossy(&printed.stdout).contains("fig10.svg"));
    let summary = crate::harness::summary(&dir.path().join("fig10").join("s1"));
    assert_eq!(summary["tick_cap"], 50, "{summary:#}");
}

#[test]
fn run_flags_typed_after_a_subcommand_say_where_they_belong() {
    let dir = scratch();
    let out = dir.path().join("fig10").display().to_string();
    let line = error_line(&["reproduce", "fig10", "--quiet", "--out", &out]);
    assert!(line.contains("--quiet after `reproduce` is a flag of the run"), "{line}");
    assert!(line.contains("give it before `reproduce`"), "{line}");
    // A value given with `=` or as the next argument, and a second misplaced flag.
    let line = error_line(&["reproduce", "fig10", "--alpha=0.2", "--out", &out]);
    assert!(line.contains("--alpha after `reproduce` is a flag of the run"), "{line}");
    let line = error_line(&["reproduce", "--tick-cap", "50", "fig10", "--quiet", "--out", &out]);
    assert!(line.contains("--tick-cap after `reproduce` is a flag of the run"), "{line}");
    let line = error_line(&["optimum", "--uavs", "3"]);
    assert!(line.contains("--uavs is a flag of a run, which `optimum` does not use"), "{line}");
    let line = error_line(&["eval", "--qtables", &out, "--tick-cap", "5"]);
    assert!(line.contains("--tick-cap is a flag of a run, which `eval` does not use"), "{line}");
    assert!(!dir.path().join("fig10").exists(), "a refused command started a run");
    // Anything else stays clap's own error (exit status 2).
    let (printed, report) = run_fail(SUPERVISOR, &["reproduce", "fig10", "--no-such-flag"]);
    assert_eq!(printed.status.code(), Some(2), "{report}");
    assert!(String::from_utf8_lossy(&printed.stderr).contains("'--no-such-flag'"), "{report}");
}

fn as_strs(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

/// `generate` writes a map that loads back as the scenario it generated, says where, and
/// refuses to replace an existing file (a map may have been edited by hand): it used to
/// overwrite it silently.
#[test]
fn generate_writes_a_new_map_and_refuses_an_existing_file() {
    let dir = scratch();
    let spec = "gen:uavs=2,targets=3,seed=2";
    let out = dir.path().join("n2.map");
    let path = out.display().to_string();
    let printed = run_ok(SUPERVISOR, &["generate", spec, "--out", &path]);
    assert_eq!(String::from_utf8_lossy(&printed.stdout).trim(), path);
    let generated = flockstep_world::Scenario::resolve(spec).expect("the scenario generates");
    let loaded = flockstep_world::Scenario::resolve(&path).expect("the map loads");
    assert_eq!(loaded.source_text(), generated.source_text());
    std::fs::write(&out, "edited by hand").unwrap();
    let line = error_line(&["generate", spec, "--out", &path]);
    assert!(line.contains(&format!("--out {path}: the file exists")), "{line}");
    assert_eq!(read(&out), b"edited by hand", "the file was replaced");
}

/// A route that cannot see some target has no optimum: `optimum` says why for that route,
/// once and naming it once, and still prints the other route's numbers.
#[test]
fn optimum_names_a_route_without_one_and_prints_the_others() {
    let spec = "gen:uavs=2,targets=3,cover=1,seed=2";
    let out = run_ok(SUPERVISOR, &["optimum", "--scenario", spec]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let header = |uav: &str| stdout.lines().filter(|l| l.contains(uav)).count();
    assert!(stdout.contains(" UAV1 sees T2 from no pose of its route"), "{stdout}");
    assert!(!stdout.contains("UAV1: UAV1"), "{stdout}");
    // UAV2's number, from the library on the same generated scenario.
    let scenario = flockstep_world::Scenario::resolve(spec).expect("the scenario generates");
    let optima = flockstep_world::optimum::route_optima(&scenario);
    assert!(optima[0].memoryless.is_err(), "UAV1 has an optimum after all: {:?}", optima[0]);
    let uav2 = optima[1].memoryless.as_ref().expect("UAV2's optimum").expected_ticks;
    let expected = format!(" UAV2: memoryless optimum {uav2:.4} ticks");
    assert!(stdout.contains(&expected), "`{expected}` expected:\n{stdout}");
    assert_eq!((header("UAV1"), header("UAV2")), (1, 1), "{stdout}");
}

/// A map path is handed on to attaching agents in a field of 512 bytes: one longer than
/// that is refused up front, naming `--scenario` (the world used to fail at start-up).
#[test]
fn a_scenario_path_too_long_to_hand_on_is_refused() {
    let dir = scratch();
    let deep = ["d", "e", "f", "g", "h"]
        .iter()
        .fold(dir.path().to_path_buf(), |path, name| path.join(name.repeat(100)));
    std::fs::create_dir_all(&deep).expect("create the directories");
    let map = deep.join("s3.map");
    let source = crate::harness::repo_file("world/maps/s3_two_uavs_two_targets.map");
    std::fs::copy(source, &map).expect("copy a map");
    let (map, out) = (map.display().to_string(), dir.path().join("out").display().to_string());
    let line = error_line(&["--scenario", &map, "--out", &out, "--episodes", "1"]);
    assert!(line.contains(&format!("--scenario {map}: its absolute path")), "{line}");
    assert!(line.contains("is longer than the 512 bytes"), "{line}");
}

/// A `curve.csv` field that is no number was read as nothing, and `plot` exited 0: every
/// field is checked, and the refusal names file, line and field.
#[test]
fn plot_refuses_a_curve_field_that_is_not_a_number_naming_it() {
    let dir = scratch();
    let curve = dir.path().join("curve.csv");
    let out = dir.path().join("plot.svg");
    for (row, field) in [("1,1,abc,35", "mean_length"), ("1,1,30,abc", "smoothed_length")] {
        let text = format!("episode,agent,mean_length,smoothed_length\n0,1,40,40\n{row}\n");
        std::fs::write(&curve, text).expect("write curve.csv");
        let spec = format!("{}=bad", curve.display());
        let line = error_line(&["plot", "--curve", &spec, "--out", &out.display().to_string()]);
        let expected = format!("{}:3: {field} `abc` is not an episode length", curve.display());
        assert!(line.contains(&expected), "{line}");
        assert!(!out.exists(), "a plot was drawn");
    }
}

/// A curve of one row drew an empty plot: its point is drawn as a dot.
#[test]
fn plot_of_a_one_row_curve_draws_its_point() {
    let dir = scratch();
    let curve = dir.path().join("curve.csv");
    std::fs::write(&curve, "episode,agent,mean_length,smoothed_length\n0,1,40,40\n")
        .expect("write curve.csv");
    let out = dir.path().join("one.svg");
    let spec = format!("{}=one row", curve.display());
    run_ok(SUPERVISOR, &["plot", "--curve", &spec, "--out", &out.display().to_string()]);
    let svg = String::from_utf8(read(&out)).expect("UTF-8");
    assert!(svg.contains("<circle"), "no dot for the one point:\n{svg}");
}

/// A plot that cannot be written said "backend error: Drawing backend error: ...": the
/// reason is given once.
#[test]
fn plot_that_cannot_be_written_says_why_once() {
    let dir = scratch();
    let curve = dir.path().join("curve.csv");
    std::fs::write(&curve, "episode,agent,mean_length,smoothed_length\n0,1,40,40\n1,1,30,35\n")
        .expect("write curve.csv");
    let spec = format!("{}=a run", curve.display());
    let out = dir.path().join("missing").join("plot.svg");
    let line = error_line(&["plot", "--curve", &spec, "--out", &out.display().to_string()]);
    assert_eq!(
        line,
        format!(
            "supervisor: error: cannot write {}: No such file or directory (os error 2)",
            out.display()
        )
    );
}

/// `agent bt replay` gave results to leaves the tree does not have (a typo), and let the
/// last of two results for a leaf win: both are refused with the script's line.
#[test]
fn replay_refuses_unknown_and_repeated_leaves() {
    let dir = scratch();
    let tree = repo_file("tests/data/show_replay.bt");
    let script = dir.path().join("bad.script");
    for (line, expected) in [
        ("C-nope=S", "bad.script:1: `C-nope=S`: the tree has no leaf C-nope (its leaves: A-report A-climb A-scan C-done)"),
        ("done=S done=F", "bad.script:1: `done=F`: leaf done is given twice on this line"),
    ] {
        std::fs::write(&script, format!("{line}\n")).expect("write the script");
        let (out, report) = run_fail(
            AGENT,
            &["bt", "replay", tree.to_str().expect("path"), script.to_str().expect("path")],
        );
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.lines().count(), 1, "{report}");
        assert!(stderr.trim_end().ends_with(expected), "{report}");
    }
}

/// Flags that would be ignored were accepted: `--eval-block` without `--eval-every`, and
/// an `--eval-every` no training reaches before its end. `--eval-episodes` past what a run
/// counts over its trials was accepted where the same count by `--eval-block` was refused.
#[test]
fn periodic_evaluation_flags_that_would_be_ignored_are_refused() {
    for_both_transports(
        &["--eval-block", "50"],
        &["--eval-block 50", "--eval-every, which is not given"],
    );
    for_both_transports(
        &["--eval-every", "100", "--episodes", "10"],
        &["--eval-every 100 with --episodes 10: no periodic greedy evaluation would run"],
    );
    let most = u64::MAX.to_string();
    for_both_transports(
        &["--eval-episodes", &most],
        &[&format!(
            "--eval-episodes {most} with --trials 4: more greedy episodes in all than a run can count"
        )],
    );
}

/// Input files were read whole: `--scenario /dev/zero` read until memory ran out. Every
/// file a user names is read up to 16 MiB, and refused past it with its name; a curve, read
/// a line at a time, at its first line.
#[test]
fn endless_input_files_are_refused_at_the_size_bound() {
    let limit = "larger than 16 MiB, the limit for an input file";
    for_both_transports(&["--scenario", "/dev/zero"], &["/dev/zero", limit]);
    for_both_transports(&["--bt", "/dev/urandom"], &["cannot read tree file /dev/urandom", limit]);
    let dir = scratch();
    let svg = dir.path().join("plot.svg").display().to_string();
    let line = error_line(&["plot", "--curve", "/dev/zero=zeros", "--out", &svg]);
    assert!(line.ends_with("/dev/zero:1: a line longer than 256 bytes, not a curve.csv"), "{line}");
    std::os::unix::fs::symlink("/dev/zero", dir.path().join("summary.json")).expect("a link");
    let qtables = dir.path().display().to_string();
    let line = error_line(&["eval", "--qtables", &qtables]);
    assert!(line.contains(&format!("summary.json: {limit}")), "{line}");
    for args in [&["bt", "show", "/dev/zero"][..], &["bt", "replay", "/dev/zero", "/dev/zero"]] {
        let (out, report) = run_fail(AGENT, args);
        assert!(String::from_utf8_lossy(&out.stderr).contains(limit), "{report}");
    }
}

/// summary.json lacked the periodic evaluation and agent-process settings, and stored the
/// tree file as given (relative) beside an absolute scenario.
#[test]
fn the_summary_records_the_whole_configuration() {
    let dir = scratch();
    let tree = dir.path().join("fig5.bt");
    std::fs::copy(repo_file("agents/trees/fig5.bt"), &tree).expect("copy the tree");
    // A relative path, as a user types it.
    let relative = tree.strip_prefix(std::env::current_dir().expect("a directory")).ok();
    let tree_arg = relative.unwrap_or(&tree).display().to_string();
    let inproc = supervise(
        &dir.path().join("inproc"),
        &words(&format!(
            "--uavs 1 --episodes 4 --trials 1 --eval-every 2 --eval-block 3 --eval-episodes 2 \
             --transport inproc --bt {tree_arg}"
        )),
    );
    assert_eq!(inproc["eval_every"], 2);
    assert_eq!(inproc["eval_block"], 3);
    // Every periodic and final greedy episode was flown.
    assert_eq!(inproc["every_agent_flew_every_episode"], true, "{inproc:#}");
    for key in ["restart", "snapshot_every", "agent_timeout_ms"] {
        assert!(inproc[key].is_null(), "{key} of an in-process run: {}", inproc[key]);
    }
    let canonical = tree.canonicalize().expect("the tree");
    assert_eq!(inproc["tree_file"], canonical.display().to_string());
    let shm = supervise(
        &dir.path().join("shm"),
        &words("--uavs 1 --episodes 2 --trials 1 --eval-episodes 2 --agent-timeout-ms 900"),
    );
    assert_eq!(
        (shm["eval_every"].clone(), shm["eval_block"].clone()),
        (0.into(), serde_json::Value::Null)
    );
    assert_eq!(shm["restart"], "never");
    assert_eq!(shm["snapshot_every"], 10_000);
    assert_eq!(shm["agent_timeout_ms"], 900);
    assert_eq!(shm["every_agent_flew_every_episode"], true, "{shm:#}");
    assert!(shm["tree_file"].is_null(), "the built-in tree has no file");
}

/// `eval` of a run an agent attached to evaluated the starting agents only, silently: it
/// says so on stderr and in its summary's notes. (The attached agent is written into the
/// run's summary.json as a run records one; `eval` reads nothing else of it.)
#[test]
fn eval_of_a_run_with_an_attached_agent_says_what_it_leaves_out() {
    let dir = scratch();
    let run = dir.path().join("run");
    let mut recorded = supervise(
        &run,
        &words(
            "--uavs 2 --scenario s4 --episodes 2 --trials 1 --eval-episodes 1 --transport inproc",
        ),
    );
    let attached = serde_json::json!({
        "uav": 3, "attached": true, "first_episode_per_trial": [1], "episodes_per_trial": [1]
    });
    recorded["agents"].as_array_mut().expect("agents").push(attached);
    std::fs::write(run.join("summary.json"), recorded.to_string()).expect("write summary.json");
    let out = run_ok(SUPERVISOR, &["--quiet", "eval", "--qtables", &run.display().to_string()]);
    let note = "eval evaluates only the agents the run started (UAV1, UAV2), not UAV3, which \
                attached to it";
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(&format!("supervisor: {note}")), "{stderr}");
    let notes = summary(&run.join("eval"))["notes"].clone();
    assert_eq!(notes, serde_json::json!([note]));
}

/// A results directory `eval` or `reproduce` chose (no --out given) that holds results was
/// refused as "--out DIR: ...", a flag the user never typed.
#[test]
fn a_chosen_results_directory_is_refused_without_naming_an_out_flag() {
    let dir = scratch();
    let run = dir.path().join("run");
    supervise(
        &run,
        &words("--uavs 1 --episodes 2 --trials 1 --eval-episodes 1 --transport inproc"),
    );
    let qtables = run.display().to_string();
    run_ok(SUPERVISOR, &["--quiet", "eval", "--qtables", &qtables, "--episodes", "1"]);
    let line = error_line(&["--quiet", "eval", "--qtables", &qtables, "--episodes", "1"]);
    let expected = format!("results directory {}: holds the results", run.join("eval").display());
    assert!(line.contains(&expected) && !line.contains("--out "), "{line}");
}

/// `eval --help` said nothing of `--out`; `--help` did not say that `--trials` is 1 to 16.
#[test]
fn help_describes_eval_out_and_the_trials_range() {
    let help = |args: &[&str]| String::from_utf8(run_ok(SUPERVISOR, args).stdout).expect("UTF-8");
    let eval = help(&["eval", "--help"]);
    assert!(eval.contains("Directory for the evaluation's results"), "{eval}");
    assert!(help(&["--help"]).contains("1 to 16"), "no range of --trials");
}
