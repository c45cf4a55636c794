//! `agent bt show` and `agent bt replay` (issue 2): the formats the README documents.
//! Nodes are named `kind@line`, the line in the tree file (comments count).

use crate::harness::{repo_file, run_fail, run_ok, AGENT};

fn stdout(args: &[&str]) -> String {
    String::from_utf8(run_ok(AGENT, args).stdout).expect("UTF-8 output")
}

#[test]
fn show_draws_the_fig5_tree() {
    let tree = repo_file("agents/trees/fig5.bt");
    let drawn = stdout(&["bt", "show", tree.to_str().expect("a UTF-8 path")]);
    let expected = " 1  OR\n 2  ├── AND\n 3  │   ├── C-seeTarget\n 4  │   └── A-endEpisode\n 5  └── LOR\n 6      ├── A-rotate\n 7      ├── A-elevate\n 8      ├── A-rotate\n 9      ├── A-deElevate\n10      └── A-waypointTranslation\n";
    assert_eq!(drawn, expected);
}

#[test]
fn replay_reports_root_status_ticked_and_halted_leaves() {
    let tree = repo_file("tests/data/show_replay.bt");
    let script = repo_file("tests/data/show_replay.script");
    let report =
        stdout(&["bt", "replay", tree.to_str().expect("path"), script.to_str().expect("path")]);
    let expected = "\
tick 1: RUNNING  ticked C-done@4=FAILURE A-climb@7=RUNNING  halted -
tick 2: RUNNING  ticked C-done@4=FAILURE A-climb@7=SUCCESS A-scan@8=RUNNING  halted -
tick 3: SUCCESS  ticked C-done@4=SUCCESS A-report@5=SUCCESS  halted A-scan@8
";
    assert_eq!(report, expected);
}

#[test]
fn replay_names_the_script_line_of_a_missing_result() {
    let dir = crate::harness::scratch();
    let script = dir.path().join("short.script");
    std::fs::write(&script, "done=F\n").expect("write the script");
    let tree = repo_file("tests/data/show_replay.bt");
    let (out, report) = run_fail(
        AGENT,
        &["bt", "replay", tree.to_str().expect("path"), script.to_str().expect("path")],
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("short.script:1:") && stderr.contains("A-climb was ticked"),
        "{report}"
    );
}

/// A replay commands no UAV, so the run's limit of 16 commands per tick does not apply: a
/// tree that ticks an action 20 times in one tick replays (a run refuses it). Before, the
/// replay refused it with the run's limit.
#[test]
fn replay_takes_a_tree_past_the_run_limit_of_commands_per_tick() {
    let dir = crate::harness::scratch();
    let (tree, script) = (dir.path().join("busy.bt"), dir.path().join("busy.script"));
    std::fs::write(&tree, "REPEAT 1 n=20\n- A-step 0\n").expect("write the tree");
    std::fs::write(&script, "step=S\n").expect("write the script");
    let report =
        stdout(&["bt", "replay", tree.to_str().expect("path"), script.to_str().expect("path")]);
    let steps = vec!["A-step@2=SUCCESS"; 20].join(" ");
    assert_eq!(report, format!("tick 1: SUCCESS  ticked {steps}  halted -\n"));
}

/// A tree past the run's limit of commands per tick is refused with the line of the node to
/// change: the deepest node past the limit on its own (here the `REPEAT` on line 7, under a
/// learning selector), and the whole tree's worst case beside it. Before, every such error
/// named line 1, the root.
#[test]
fn a_tree_past_the_command_limit_names_the_node_at_fault() {
    let dir = crate::harness::scratch();
    let tree = dir.path().join("deep.bt");
    let text = "OR 2\n- AND 2\n-- C-seeTarget 0\n-- A-endEpisode 0\n- LOR 2\n-- A-rotate 0\n-- REPEAT 1 n=20\n--- A-elevate 0\n";
    std::fs::write(&tree, text).expect("write the tree");
    let tree = tree.display().to_string();
    let out = dir.path().join("out").display().to_string();
    let line = crate::harness::error_line(&["--bt", &tree, "--out", &out, "--episodes", "1"]);
    let expected = format!("supervisor: error: {tree}:7: this REPEAT n=20 may issue up to 20 commands in one tick (the whole tree up to 22); the limit is 16");
    assert_eq!(line, expected);
}

/// A replay lists every leaf it ticks, so a tree that may tick more than a million in one
/// tick is refused up front (three nested `REPEAT n=1000`, a billion ticks, used to run
/// until memory ran out). The leaf is a condition, which issues no command: counting
/// commands alone let this tree through.
#[test]
fn replay_refuses_a_tree_that_could_tick_without_bound() {
    let dir = crate::harness::scratch();
    let (tree, script) = (dir.path().join("endless.bt"), dir.path().join("endless.script"));
    let nested = "REPEAT 1 n=1000\n- REPEAT 1 n=1000\n-- REPEAT 1 n=1000\n--- C-ready 0\n";
    std::fs::write(&tree, nested).expect("write the tree");
    std::fs::write(&script, "ready=S\n").expect("write the script");
    let args = ["bt", "replay", tree.to_str().expect("path"), script.to_str().expect("path")];
    let (out, report) = crate::harness::run_fail(crate::harness::AGENT, &args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains(":1: this REPEAT n=1000 may tick up to 1000000000 leaves in one tick; the limit is 1000000"),
        "{report}"
    );
}
