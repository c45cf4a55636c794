//! Spawning the binaries under test. A failure prints the whole command, its exit status,
//! stdout and stderr, so a red test says what happened without a re-run.

use serde_json::Value;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

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

/// Runs `program args` to completion (at most `RUN_BOUND`); panics with the full report
/// unless it succeeded.
pub fn run_ok(program: &str, args: &[&str]) -> Output {
    let (out, report) = Spawned::start(program, args).finish(RUN_BOUND);
    assert!(out.status.success(), "expected success\n{report}");
    out
}

/// Runs `program args` to completion (at most `RUN_BOUND`); panics with the full report if
/// it succeeded.
pub fn run_fail(program: &str, args: &[&str]) -> (Output, String) {
    let (out, report) = Spawned::start(program, args).finish(RUN_BOUND);
    assert!(!out.status.success(), "expected failure\n{report}");
    (out, report)
}

/// The bound on any one run of a binary here: far beyond the longest even on a loaded
/// machine, so only a hang reaches it.
pub const RUN_BOUND: Duration = Duration::from_secs(600);

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

/// Whether process `pid` has a handler installed for `signal` (`SigCgt` in
/// `/proc/<pid>/status`): before that, the signal's default action would kill it.
pub fn catches(pid: u32, signal: libc::c_int) -> bool {
    let Ok(status) = std::fs::read_to_string(format!("/proc/{pid}/status")) else { return false };
    status
        .lines()
        .find_map(|line| line.strip_prefix("SigCgt:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| mask & (1 << (signal - 1)) != 0)
}

/// Polls `condition` every 10 ms for at most `timeout`; panics with `what` if it never holds.
pub fn wait_until(what: &str, timeout: Duration, mut condition: impl FnMut() -> bool) {
    let start = Instant::now();
    while !condition() {
        assert!(start.elapsed() < timeout, "gave up after {timeout:?} waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A spawned binary under test, waited for with a bound. Its stdout and stderr are read
/// as they come, so a chatty process never blocks on a full pipe while the test waits.
/// Dropped while still running (a test that failed before waiting for it), it is killed.
pub struct Spawned {
    pub cmd: Command,
    child: Child,
    /// The output readers, taken when the process has exited.
    readers: Option<[JoinHandle<Vec<u8>>; 2]>,
}

impl Spawned {
    pub fn start(program: &str, args: &[&str]) -> Spawned {
        let mut cmd = Command::new(program);
        cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
        let mut child = cmd.spawn().unwrap_or_else(|e| panic!("cannot start {program}: {e}"));
        let stdout = drain(child.stdout.take().expect("a piped stdout"));
        let stderr = drain(child.stderr.take().expect("a piped stderr"));
        Spawned { cmd, child, readers: Some([stdout, stderr]) }
    }

    pub fn supervisor(args: &[&str]) -> Spawned {
        Spawned::start(SUPERVISOR, args)
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Waits for the exit, at most `timeout`; fails the test past it (see [`Self::try_finish`]).
    pub fn finish(self, timeout: Duration) -> (Output, String) {
        self.try_finish(timeout).unwrap_or_else(|overdue| panic!("{overdue}"))
    }

    /// Waits for the exit, at most `timeout`. Past it the process is interrupted as by
    /// Ctrl-C (killed if that does not end it within `INTERRUPT_GRACE`) and the error holds
    /// its output, the episodes recorded and the world log's tail: a run that was merely
    /// slow (a loaded machine) then reads apart from one that was stuck.
    pub fn try_finish(mut self, timeout: Duration) -> Result<(Output, String), String> {
        if let Some(status) = self.exited_within(timeout) {
            return Ok(self.output(status));
        }
        signal(self.pid(), libc::SIGINT);
        let (status, then) = match self.exited_within(INTERRUPT_GRACE) {
            Some(status) => (status, "it stopped on SIGINT"),
            None => {
                let _ = self.child.kill();
                (self.child.wait().expect("wait on the killed process"), "SIGINT did not stop it")
            }
        };
        let progress = self.progress();
        let (_, report) = self.output(status);
        Err(format!(
            "the process did not finish within {timeout:?}; then {then}\n{report}\n{progress}"
        ))
    }

    /// Polls every 10 ms for the exit, at most `timeout`.
    fn exited_within(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().expect("wait on the process") {
                return Some(status);
            }
            if start.elapsed() > timeout {
                return None;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The exited process's output and its report (its pipes close with it, which ends the
    /// readers).
    fn output(&mut self, status: ExitStatus) -> (Output, String) {
        let [stdout, stderr] = self.readers.take().expect("the output is collected once");
        let read = |reader: JoinHandle<Vec<u8>>| reader.join().expect("an output reader");
        let out = Output { status, stdout: read(stdout), stderr: read(stderr) };
        let report = describe(&self.cmd, &out);
        (out, report)
    }

    /// How far a run got: the rows of its `episodes.csv` and the tail of its world log.
    fn progress(&self) -> String {
        let args: Vec<_> = self.cmd.get_args().collect();
        let Some(out) = args.iter().position(|a| *a == "--out").and_then(|i| args.get(i + 1))
        else {
            return "(no --out: no results to show)".to_string();
        };
        let out = Path::new(out);
        let rows = std::fs::read_to_string(out.join("episodes.csv"))
            .map(|csv| format!("{} episode rows", csv.lines().count().saturating_sub(1)))
            .unwrap_or_else(|e| format!("no episodes.csv ({e})"));
        let log = std::fs::read_to_string(out.join("logs").join("world.log")).unwrap_or_default();
        let lines: Vec<&str> = log.lines().collect();
        let tail = match lines.len() {
            0 => "(empty)".to_string(),
            n => lines[n.saturating_sub(WORLD_LOG_TAIL)..].join("\n"),
        };
        format!("--- results: {rows}; world log, last {WORLD_LOG_TAIL} lines ---\n{tail}")
    }
}

impl Drop for Spawned {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Reads `pipe` to its end on a thread of its own.
fn drain(mut pipe: impl Read + Send + 'static) -> JoinHandle<Vec<u8>> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        // A read error ends the output early; what was read is still shown.
        let _ = pipe.read_to_end(&mut bytes);
        bytes
    })
}

/// How long an overdue run gets to stop on SIGINT and write its partial results.
const INTERRUPT_GRACE: Duration = Duration::from_secs(20);

/// The world log lines an overdue run's report shows.
const WORLD_LOG_TAIL: usize = 20;

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
    wait_until(&format!("the processes of run {id} to exit"), Duration::from_secs(10), || {
        pids_with(id).is_empty()
    });
    let left = flockstep_proto::transport::leftover_files(id).expect("list the run's files");
    assert!(left.is_empty(), "run {id} left files behind: {left:?}");
}
