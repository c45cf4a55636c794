//! Spawning the binaries under test. A failure prints the whole command, its exit status,
//! stdout and stderr, so a red test says what happened without a re-run.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicU32, Ordering};

pub const SUPERVISOR: &str = env!("CARGO_BIN_EXE_supervisor");
pub const AGENT: &str = env!("CARGO_BIN_EXE_agent");

/// A run id unique to this test process and call (tests run in parallel).
pub fn run_id(tag: &str) -> String {
    static NEXT: AtomicU32 = AtomicU32::new(0);
    format!("t{}-{}-{}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed), tag)
}

/// A scratch directory removed when dropped.
pub fn scratch() -> tempfile::TempDir {
    tempfile::Builder::new().prefix("flockstep-test-").tempdir().expect("a temporary directory")
}

pub fn describe(cmd: &Command, out: &Output) -> String {
    format!(
        "command: {:?}\nstatus: {}\n--- stdout ---\n{}\n--- stderr ---\n{}",
        cmd,
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Runs `program args` to completion; panics with the full report unless it succeeded.
pub fn run_ok(program: &str, args: &[&str]) -> Output {
    let mut cmd = Command::new(program);
    cmd.args(args);
    let out = cmd.output().unwrap_or_else(|e| panic!("cannot start {program}: {e}"));
    assert!(out.status.success(), "expected success\n{}", describe(&cmd, &out));
    out
}

/// Runs `program args` to completion; panics with the full report if it succeeded.
pub fn run_fail(program: &str, args: &[&str]) -> (Output, String) {
    let mut cmd = Command::new(program);
    cmd.args(args);
    let out = cmd.output().unwrap_or_else(|e| panic!("cannot start {program}: {e}"));
    assert!(!out.status.success(), "expected failure\n{}", describe(&cmd, &out));
    let report = describe(&cmd, &out);
    (out, report)
}

/// Runs the supervisor with `args` plus `--out DIR --quiet`, returns DIR's summary.json.
pub fn supervise(out: &Path, args: &[&str]) -> Value {
    let out_arg = out.display().to_string();
    let mut all: Vec<&str> = args.to_vec();
    all.extend(["--out", &out_arg, "--quiet"]);
    run_ok(SUPERVISOR, &all);
    summary(out)
}

pub fn summary(out: &Path) -> Value {
    let path = out.join("summary.json");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{} is not JSON: {e}", path.display()))
}

/// `summary[key][index]` as f64.
pub fn number(summary: &Value, key: &str, index: usize) -> f64 {
    summary[key][index]
        .as_f64()
        .unwrap_or_else(|| panic!("summary has no number {key}[{index}]: {summary:#}"))
}

pub fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
}

pub fn repo_file(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(relative)
}
