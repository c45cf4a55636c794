//! The supervisor's child processes: spawned with explicit arguments in their own process
//! group (a terminal's Ctrl-C reaches only the supervisor, which stops the run in order),
//! with their stderr in a log file, and shut down by a ladder: wait, SIGTERM, SIGKILL.

use anyhow::{Context, Result};
use std::fs::File;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// One child process.
pub struct Process {
    pub name: String,
    child: Child,
    log: PathBuf,
    status: Option<ExitStatus>,
    /// Peak resident set size in KiB, known once the process has exited. It is `wait4`'s,
    /// so at least the supervisor's own peak at the time it spawned the process (Linux
    /// carries a peak over `exec`); in the runs measured that was below what a world or an
    /// agent uses itself.
    pub peak_rss_kib: Option<u64>,
    /// When [`Process::bring_down`] sent it SIGTERM.
    terminated_at: Option<Instant>,
}

/// How long a process has to leave after SIGTERM before it gets SIGKILL.
pub const TERM_GRACE: Duration = Duration::from_secs(2);

impl Process {
    /// Spawns `command` as `name`, its stdout and stderr going to `log`.
    pub fn spawn(name: &str, mut command: Command, log: &Path) -> Result<Process> {
        let file =
            File::create(log).with_context(|| format!("cannot create log {}", log.display()))?;
        command
            .stdin(Stdio::null())
            .stdout(
                file.try_clone().with_context(|| format!("cannot share log {}", log.display()))?,
            )
            .stderr(file)
            .process_group(0);
        let child = command
            .spawn()
            .with_context(|| format!("cannot start {name} ({:?})", command.get_program()))?;
        Ok(Process {
            name: name.to_string(),
            child,
            log: log.to_path_buf(),
            status: None,
            peak_rss_kib: None,
            terminated_at: None,
        })
    }

    /// Its process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The exit status, once the process has exited. Reaps it with `wait4`, which also
    /// reports the process's peak memory.
    pub fn status(&mut self) -> Result<Option<ExitStatus>> {
        if self.status.is_none() {
            let mut raw = 0;
            // SAFETY: wait4 on our own child's pid with valid out-pointers.
            let (reaped, usage) = unsafe {
                let mut usage: libc::rusage = std::mem::zeroed();
                (
                    libc::wait4(
                        self.child.id() as libc::pid_t,
                        &mut raw,
                        libc::WNOHANG,
                        &mut usage,
                    ),
                    usage,
                )
            };
            if reaped < 0 {
                return Err(std::io::Error::last_os_error())
                    .with_context(|| format!("cannot watch {}", self.name));
            }
            if reaped > 0 {
                self.status = Some(std::os::unix::process::ExitStatusExt::from_raw(raw));
                self.peak_rss_kib = Some(usage.ru_maxrss as u64);
            }
        }
        Ok(self.status)
    }

    /// Whether the process is known to have exited (as of the last [`Process::status`]).
    pub fn exited(&self) -> bool {
        self.status.is_some()
    }

    /// The shutdown ladder for this one process, a step at a time so that the caller goes on
    /// with its work meanwhile: SIGTERM at the first call, SIGKILL at a call once
    /// [`TERM_GRACE`] has passed since. The caller calls again until the process has exited.
    pub fn bring_down(&mut self) {
        match self.terminated_at {
            None => {
                self.signal(libc::SIGTERM);
                self.terminated_at = Some(Instant::now());
            }
            Some(at) if at.elapsed() >= TERM_GRACE => self.signal(libc::SIGKILL),
            Some(_) => {}
        }
    }

    /// Whether [`Process::bring_down`] has begun to bring it down.
    pub fn brought_down(&self) -> bool {
        self.terminated_at.is_some()
    }

    /// The last error line the process logged (or its last line), for error messages.
    pub fn last_words(&self) -> String {
        let text = std::fs::read_to_string(&self.log).unwrap_or_default();
        let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
        lines.iter().rev().find(|l| l.contains("error")).or(lines.last()).map_or_else(
            || format!("no output; see {}", self.log.display()),
            |l| l.trim().to_string(),
        )
    }

    fn signal(&self, signal: libc::c_int) {
        if self.status.is_none() {
            // SAFETY: kill(2) on our own child's pid; a failure (already gone) is harmless.
            unsafe {
                libc::kill(self.child.id() as libc::pid_t, signal);
            }
        }
    }
}

/// Waits until every process has exited, for at most `grace`. True if all did.
fn wait_all(processes: &mut [&mut Process], grace: Duration) -> Result<bool> {
    let deadline = Instant::now() + grace;
    loop {
        let mut running = 0;
        for p in processes.iter_mut() {
            if p.status()?.is_none() {
                running += 1;
            }
        }
        if running == 0 {
            return Ok(true);
        }
        if Instant::now() >= deadline {
            return Ok(false);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The shutdown ladder: let them leave for `grace`, then SIGTERM and wait [`TERM_GRACE`],
/// then SIGKILL and wait until they are gone. Returns the names of those that had to be
/// signalled.
pub fn shut_down(processes: &mut [&mut Process], grace: Duration) -> Result<Vec<String>> {
    let mut forced = Vec::new();
    if wait_all(processes, grace)? {
        return Ok(forced);
    }
    for p in processes.iter_mut() {
        if p.status()?.is_none() {
            forced.push(p.name.clone());
            p.signal(libc::SIGTERM);
        }
    }
    if wait_all(processes, TERM_GRACE)? {
        return Ok(forced);
    }
    for p in processes.iter_mut() {
        p.signal(libc::SIGKILL);
    }
    wait_all(processes, Duration::from_secs(10))?;
    Ok(forced)
}
