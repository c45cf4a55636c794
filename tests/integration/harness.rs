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
pub const WORLD: &str = env!("CARGO_BIN_EXE_world");

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

/// The `notes` of a `summary.json`, in order.
pub fn notes(summary: &Value) -> Vec<&str> {
    let notes = summary["notes"].as_array().unwrap_or_else(|| panic!("no notes: {summary:#}"));
    notes.iter().filter_map(Value::as_str).collect()
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

/// Pids of the processes of agent `uav` (1-based) of run `id`, as the supervisor starts
/// them (`agent run --run-id ID --uav N ...`; the trailing space keeps UAV1 from matching
/// UAV10).
pub fn agent_pids(id: &str, uav: usize) -> Vec<u32> {
    pids_with(&format!("--run-id {id} --uav {uav} "))
}

/// Waits (at most 30 s) until agent `uav` of run `id` has a process; returns its pids.
pub fn wait_for_agent(id: &str, uav: usize) -> Vec<u32> {
    let mut pids = Vec::new();
    wait_until(&format!("UAV{uav} of run {id} to start"), Duration::from_secs(30), || {
        pids = agent_pids(id, uav);
        !pids.is_empty()
    });
    pids
}

/// Pids of the world process of run `id` (`supervisor world --run-id ID ...`).
pub fn world_pids(id: &str) -> Vec<u32> {
    pids_with(&format!("world --run-id {id} "))
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

/// Pids of the descendants of `pid` (its children, theirs, and so on), from the parent pid
/// in each `/proc/<pid>/stat`.
fn descendants(pid: u32) -> Vec<u32> {
    let mut parent_of = Vec::new();
    for entry in std::fs::read_dir("/proc").expect("/proc is readable").flatten() {
        let Ok(child) = entry.file_name().to_string_lossy().parse::<u32>() else { continue };
        let Ok(stat) = std::fs::read_to_string(entry.path().join("stat")) else { continue };
        // `pid (comm) state ppid ...`: comm may hold spaces and parentheses, so the fields
        // are counted from its closing parenthesis.
        let ppid = stat
            .rfind(')')
            .and_then(|end| stat[end + 1..].split_whitespace().nth(1))
            .and_then(|ppid| ppid.parse::<u32>().ok());
        if let Some(ppid) = ppid {
            parent_of.push((child, ppid));
        }
    }
    let (mut found, mut parents) = (Vec::new(), vec![pid]);
    while let Some(parent) = parents.pop() {
        for &(child, _) in parent_of.iter().filter(|&&(_, ppid)| ppid == parent) {
            found.push(child);
            parents.push(child);
        }
    }
    found
}

/// SIGKILLs `child` and its descendants, and reaps it. The supervisor's children run in
/// process groups of their own and, when it dies, get only SIGTERM (their parent-death
/// signal): an agent that ignores SIGTERM (`--fault N=ignore-sigterm`) would outlive a failed
/// test. The process is stopped first, so that it starts no new child while its descendants
/// are listed, and they are listed while they are still its children (an orphan's parent is
/// init).
pub fn kill_tree(child: &mut Child) -> ExitStatus {
    let pid = child.id();
    signal(pid, libc::SIGSTOP);
    let descendants = descendants(pid);
    let _ = child.kill();
    for descendant in descendants {
        signal(descendant, libc::SIGKILL);
    }
    child.wait().expect("wait on the killed process")
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
    /// The output readers (of the piped outputs), taken when the process has exited.
    readers: Option<[Option<JoinHandle<Vec<u8>>>; 2]>,
}

impl Spawned {
    /// Starts `program args` with its stdout and stderr collected.
    pub fn start(program: &str, args: &[&str]) -> Spawned {
        let mut cmd = Command::new(program);
        cmd.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
        Spawned::spawn(cmd)
    }

    /// Starts `cmd` as it is set up: an output it pipes is collected, one it sends elsewhere
    /// (a file, `/dev/full`) reads as empty.
    pub fn spawn(mut cmd: Command) -> Spawned {
        let mut child = cmd.spawn().unwrap_or_else(|e| panic!("cannot start {cmd:?}: {e}"));
        let stdout = child.stdout.take().map(drain);
        let stderr = child.stderr.take().map(drain);
        Spawned { cmd, child, readers: Some([stdout, stderr]) }
    }

    pub fn supervisor(args: &[&str]) -> Spawned {
        Spawned::start(SUPERVISOR, args)
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Sends SIGINT, as Ctrl-C does, once the process has its handler for it (at most 30 s):
    /// before that, the signal's default action would kill it, which tests nothing.
    pub fn interrupt(&self) {
        self.interrupt_after(Duration::ZERO);
    }

    /// [`Self::interrupt`], `delay` after the process has its handler.
    pub fn interrupt_after(&self, delay: Duration) {
        let pid = self.pid();
        wait_until(&format!("process {pid} to handle SIGINT"), Duration::from_secs(30), || {
            catches(pid, libc::SIGINT)
        });
        std::thread::sleep(delay);
        signal(pid, libc::SIGINT);
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
            None => (self.kill_tree(), "SIGINT did not stop it"),
        };
        let progress = self.progress();
        let (_, report) = self.output(status);
        Err(format!(
            "the process did not finish within {timeout:?}; then {then}\n{report}\n{progress}"
        ))
    }

    /// SIGKILLs the running process and every process under it; returns its exit status.
    fn kill_tree(&mut self) -> ExitStatus {
        kill_tree(&mut self.child)
    }

    /// Whether the process has exited (its status is kept for [`Self::finish`]).
    pub fn has_exited(&mut self) -> bool {
        self.child.try_wait().expect("wait on the process").is_some()
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
        let read = |reader: Option<JoinHandle<Vec<u8>>>| {
            reader.map_or_else(Vec::new, |reader| reader.join().expect("an output reader"))
        };
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
            self.kill_tree();
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

/// Mean episode length (the `length` column) of `rows`, which must not be empty.
pub fn mean_length(rows: &[[u64; 6]]) -> f64 {
    assert!(!rows.is_empty(), "the mean episode length of no episodes");
    rows.iter().map(|r| r[4] as f64).sum::<f64>() / rows.len() as f64
}

/// Where one agent's rows (in episode order) first skip an episode: the index of the last
/// row before the gap, e.g. where a killed agent was down until its restart.
pub fn first_gap(rows: &[[u64; 6]]) -> Option<usize> {
    rows.windows(2).position(|w| w[1][2] != w[0][2] + 1)
}

/// One line of an agent's trace (`agent run --trace FILE`, agents/src/trace.rs), which is
/// written after the agent took in the round's relayed flags and chose its action.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TraceRow {
    pub round: u64,
    /// `tick`, or `stop` in the run's last round.
    pub stop: bool,
    pub trial: u64,
    pub episode: u64,
    pub episode_tick: u64,
    /// Whether the world counts the agent in the trial's episode this round.
    pub member: bool,
    /// The flags the agent sent this round: the waypoint (0-based) and whether it saw the
    /// target from there.
    pub sent_waypoint: usize,
    pub sent_sees: u64,
    /// Its communication words after taking in the flags relayed this round.
    pub comm: Vec<u64>,
}

/// The rows of the trace at `path`, in file order.
pub fn read_trace(path: &Path) -> Vec<TraceRow> {
    let text = String::from_utf8(read(path)).expect("UTF-8 trace");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("round,kind,trial,episode,episode_tick,member,sent_waypoint,sent_sees,comm"),
        "{} has another header",
        path.display()
    );
    lines
        .map(|line| {
            let f: Vec<&str> = line.split(',').collect();
            assert_eq!(f.len(), 9, "malformed trace line `{line}` in {}", path.display());
            let num = |i: usize| {
                f[i].parse::<u64>().unwrap_or_else(|e| panic!("`{line}` field {i}: {e}"))
            };
            let stop = match f[1] {
                "tick" => false,
                "stop" => true,
                kind => panic!("`{line}`: unknown kind `{kind}`"),
            };
            let comm = match f[8] {
                "" => vec![],
                words => words
                    .split('-')
                    .map(|w| u64::from_str_radix(w, 16).unwrap_or_else(|e| panic!("`{line}`: {e}")))
                    .collect(),
            };
            TraceRow {
                round: num(0),
                stop,
                trial: num(2),
                episode: num(3),
                episode_tick: num(4),
                member: num(5) == 1,
                sent_waypoint: num(6) as usize,
                sent_sees: num(7),
                comm,
            }
        })
        .collect()
}

/// Entry `k` of packed communication words (2 bits an entry: 0 unknown, 1 "0", 2 "1";
/// agents/src/comm.rs).
pub fn comm_entry(words: &[u64], k: usize) -> u64 {
    words.get(2 * k / 64).map_or(0, |w| (w >> (2 * k % 64)) & 3)
}

/// Waits, at most `timeout`, until the file at `path` (a run's `episodes.csv`, ...) holds
/// more than `bytes`: the run is under way and recording.
pub fn wait_for_records(path: &Path, bytes: u64, timeout: Duration) {
    let what = format!("more than {bytes} bytes in {}", path.display());
    wait_until(&what, timeout, || std::fs::metadata(path).is_ok_and(|m| m.len() > bytes));
}

/// Asserts that nothing of run `id` is left: no process, no shared-memory file.
pub fn assert_nothing_left(id: &str) {
    wait_until(&format!("the processes of run {id} to exit"), Duration::from_secs(10), || {
        pids_with(id).is_empty()
    });
    let left = flockstep_proto::transport::leftover_files(id).expect("list the run's files");
    assert!(left.is_empty(), "run {id} left files behind: {left:?}");
}

/// The harness's own promise: a run a failing test drops takes every process it started
/// down with it, even an agent that ignores SIGTERM (it used to outlive the test).
#[test]
fn a_dropped_run_takes_every_process_it_started_down() {
    let dir = scratch();
    let (id, out) = (run_id("dropped"), dir.path().display().to_string());
    let run = Spawned::supervisor(
        &[
            &words("--transport shm --quiet --scenario s3 --uavs 2 --trials 1 --episodes 10000000")
                [..],
            &["--fault", "2=ignore-sigterm", "--run-id", &id, "--out", &out],
        ]
        .concat(),
    );
    let stubborn = wait_for_agent(&id, 2);
    // Under way, not in the middle of setting up its shared memory.
    wait_for_records(&dir.path().join("episodes.csv"), 100, Duration::from_secs(30));
    drop(run);
    wait_until(
        &format!(
            "every process of run {id}, UAV2 (pids {stubborn:?}) that ignores SIGTERM too, to end"
        ),
        Duration::from_secs(10),
        || pids_with(&id).is_empty(),
    );
    remove_killed_run(&id);
}

/// Removes the files of run `id`, whose processes were SIGKILLed and could not: its dead
/// nodes as the supervisor removes a crashed run's, then what a concurrent sweep (every shm
/// run another test starts sweeps dead nodes) may have left half-removed, with the node
/// directory that held it once empty.
fn remove_killed_run(id: &str) {
    flockstep_proto::transport::cleanup_run(id).expect("remove the killed run's nodes");
    let left = flockstep_proto::transport::leftover_files(id).expect("list the run's files");
    for file in left {
        std::fs::remove_file(&file).unwrap_or_else(|e| panic!("remove {}: {e}", file.display()));
        let node_dir =
            file.parent().filter(|dir| dir.parent().is_some_and(|p| p.ends_with("nodes")));
        if let Some(dir) = node_dir {
            // Fails, as it should, while other files are in it.
            let _ = std::fs::remove_dir(dir);
        }
    }
    assert_nothing_left(id);
}
