//! Spawning the binaries under test. A failure prints the whole command, its exit status,
//! stdout and stderr, so a red test says what happened without a re-run.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::atomic::{AtomicU32, Ordering};

pub const SUPERVISOR: &str = env!("CARGO_BIN_EXE_supervisor");
pub const AGENT: &str = env!("CARGO_BIN_EXE_agent");

/// The words of `text`: long argument lists read better as one string.
pub fn words(text: &str) -> Vec<&str> {
    text.split_whitespace().collect()
}

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

/// Runs the supervisor expecting failure; returns its stderr, checked to be one error line
/// and exit status 1.
pub fn error_line(args: &[&str]) -> String {
    let (out, report) = run_fail(SUPERVISOR, args);
    let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
    assert_eq!(stderr.lines().count(), 1, "expected one error line\n{report}");
    assert!(stderr.starts_with("supervisor: error: "), "{report}");
    assert_eq!(out.status.code(), Some(1), "{report}");
    stderr
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

/// Where `a` and `b` first part, for a failure message (None if they are equal): the byte
/// offset and the line it falls in, from each side.
pub fn first_difference(a: &[u8], b: &[u8]) -> Option<String> {
    let at = a.iter().zip(b).position(|(x, y)| x != y).unwrap_or(a.len().min(b.len()));
    if a.len() == b.len() && at == a.len() {
        return None;
    }
    let line_of = |bytes: &[u8]| {
        let start =
            bytes[..at.min(bytes.len())].iter().rposition(|&c| c == b'\n').map_or(0, |i| i + 1);
        let end =
            bytes[start..].iter().position(|&c| c == b'\n').map_or(bytes.len(), |i| start + i);
        String::from_utf8_lossy(&bytes[start..end.min(start + 200)]).into_owned()
    };
    let line = a[..at].iter().filter(|&&c| c == b'\n').count() + 1;
    Some(format!(
        "they part at byte {at} (line {line}; {} and {} bytes in all):\n  {:?}\n  {:?}",
        a.len(),
        b.len(),
        line_of(a),
        line_of(b)
    ))
}

/// Fails unless the files at `a` and `b` hold the same bytes, naming both and where they
/// part.
pub fn assert_same_file(a: &Path, b: &Path) {
    if let Some(difference) = first_difference(&read(a), &read(b)) {
        panic!("{} and {} differ: {difference}", a.display(), b.display());
    }
}

/// The world's log of the run whose results are in `dir`.
pub fn world_log(dir: &Path) -> String {
    String::from_utf8(read(&dir.join("logs").join("world.log"))).expect("the world log is UTF-8")
}

pub fn repo_file(relative: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(relative)
}

/// Pids of the processes whose command line contains `needle` (e.g. a run id).
pub fn pids_with(needle: &str) -> Vec<u32> {
    let mut pids = Vec::new();
    for entry in std::fs::read_dir("/proc").expect("/proc is readable").flatten() {
        let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let Ok(cmdline) = std::fs::read(entry.path().join("cmdline")) else { continue };
        let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        if cmdline.contains(needle) && pid != std::process::id() {
            pids.push(pid);
        }
    }
    pids
}

/// Sends `signal` to `pid`.
pub fn signal(pid: u32, signal: libc::c_int) {
    // SAFETY: kill(2) with a pid we found; a process already gone is not an error here.
    unsafe {
        libc::kill(pid as libc::pid_t, signal);
    }
}

/// Polls `condition` every 10 ms for at most `timeout`; panics with `what` if it never holds.
pub fn wait_until(what: &str, timeout: std::time::Duration, mut condition: impl FnMut() -> bool) {
    let start = std::time::Instant::now();
    while !condition() {
        assert!(start.elapsed() < timeout, "gave up after {timeout:?} waiting for {what}");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// A spawned supervisor, waited for with a bound; killed (and the test failed) past it.
pub struct Supervised {
    pub cmd: Command,
    pub child: std::process::Child,
}

impl Supervised {
    pub fn start(args: &[&str]) -> Supervised {
        let mut cmd = Command::new(SUPERVISOR);
        cmd.args(args).stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped());
        let child = cmd.spawn().unwrap_or_else(|e| panic!("cannot start the supervisor: {e}"));
        Supervised { cmd, child }
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Waits for the exit, at most `timeout` (a deadlock fails the test with the output).
    pub fn finish(mut self, timeout: std::time::Duration) -> (Output, String) {
        let start = std::time::Instant::now();
        loop {
            if self.child.try_wait().expect("wait on the supervisor").is_some() {
                break;
            }
            if start.elapsed() > timeout {
                let _ = self.child.kill();
                let out = self.child.wait_with_output().expect("collect output");
                panic!(
                    "the supervisor did not finish within {timeout:?} (deadlock?)\n{}",
                    describe(&self.cmd, &out)
                );
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        let out = self.child.wait_with_output().expect("collect output");
        let report = describe(&self.cmd, &out);
        (out, report)
    }
}

/// Parsed `episodes.csv`: (trial, agent, episode, start_tick, length, truncated) rows.
pub fn episode_rows(out: &Path) -> Vec<[u64; 6]> {
    let text = String::from_utf8(read(&out.join("episodes.csv"))).expect("UTF-8 CSV");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("trial,agent,episode,start_tick,length,truncated"));
    lines
        .map(|line| {
            let fields: Vec<u64> = line
                .split(',')
                .map(|f| f.parse().unwrap_or_else(|e| panic!("`{line}`: {e}")))
                .collect();
            fields.try_into().unwrap_or_else(|f| panic!("`{line}` has {} fields", Vec::len(&f)))
        })
        .collect()
}

/// Asserts that nothing of run `id` is left: no process, no shared-memory file.
pub fn assert_nothing_left(id: &str) {
    wait_until(
        &format!("the processes of run {id} to exit"),
        std::time::Duration::from_secs(10),
        || pids_with(id).is_empty(),
    );
    let left = flockstep_proto::transport::leftover_files(id).expect("list the run's files");
    assert!(left.is_empty(), "run {id} left files behind: {left:?}");
}
