//! The progress bar as a user sees it: the supervisor's stderr on a pseudo-terminal, as in
//! a shell. The bar's content is unit-tested on a terminal in memory; this checks that the
//! real binary draws it on a terminal, with every field the issue names, through to the
//! last episode.

use crate::harness::{
    assert_nothing_left, kill_tree, run_id, scratch, words, RUN_BOUND, SUPERVISOR,
};
use std::io::Read;
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;

/// A pseudo-terminal of 200 columns, wider than any frame: its controller (read by the test)
/// and its device (the process's stderr). Both close on exec, so no other process this test
/// binary starts, on any thread, holds them; the supervisor gets the device as its stderr
/// alone (`dup2` clears the flag there).
fn open_terminal() -> (OwnedFd, OwnedFd) {
    let flags = libc::O_RDWR | libc::O_NOCTTY | libc::O_CLOEXEC;
    let failed = |what: &str| panic!("{what} failed: {}", std::io::Error::last_os_error());
    // SAFETY: opens a new pseudo-terminal controller; nothing else owns the descriptor.
    let controller = unsafe { libc::posix_openpt(flags) };
    if controller < 0 {
        failed("posix_openpt");
    }
    // SAFETY: a fresh, open descriptor owned from here on.
    let controller = unsafe { OwnedFd::from_raw_fd(controller) };
    let fd = controller.as_raw_fd();
    let mut name = [0 as libc::c_char; 128];
    // SAFETY: calls on the open controller; `name` is a writable buffer of the given length.
    unsafe {
        if libc::grantpt(fd) != 0 || libc::unlockpt(fd) != 0 {
            failed("grantpt/unlockpt");
        }
        if libc::ptsname_r(fd, name.as_mut_ptr(), name.len()) != 0 {
            failed("ptsname_r");
        }
    }
    // SAFETY: `name` is the NUL-terminated path ptsname_r wrote.
    let device = unsafe { libc::open(name.as_ptr(), flags) };
    if device < 0 {
        failed("opening the terminal device");
    }
    // SAFETY: a fresh, open descriptor owned from here on.
    let device = unsafe { OwnedFd::from_raw_fd(device) };
    let size = libc::winsize { ws_row: 40, ws_col: 200, ws_xpixel: 0, ws_ypixel: 0 };
    // SAFETY: sets the window size of the open device from a valid `winsize`.
    if unsafe { libc::ioctl(device.as_raw_fd(), libc::TIOCSWINSZ, &size) } != 0 {
        failed("setting the terminal's size");
    }
    (controller, device)
}

/// Kills the process and its descendants when dropped while it runs, so a failed test
/// leaves no run behind.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            kill_tree(&mut self.0);
        }
    }
}

/// Runs the supervisor with `args` and its stderr on a terminal; returns its exit status and
/// everything it wrote there. The terminal reads as ended once every process holding it has
/// exited; a run that has not ended within [`RUN_BOUND`] fails the test.
fn run_on_terminal(args: &[&str]) -> (std::process::ExitStatus, String) {
    let (controller, device) = open_terminal();
    let child = {
        let mut cmd = Command::new(SUPERVISOR);
        cmd.args(args).stdin(Stdio::null()).stdout(Stdio::null()).stderr(Stdio::from(device));
        // The command, and with it this process's copy of the device, goes at the block's
        // end: the supervisor's stderr is then the only copy (its children write theirs to
        // log files).
        cmd.spawn().unwrap_or_else(|e| panic!("cannot start {SUPERVISOR}: {e}"))
    };
    let mut child = KillOnDrop(child);
    let (sent, received) = mpsc::channel();
    std::thread::spawn(move || {
        let mut terminal = std::fs::File::from(controller);
        let mut seen = Vec::new();
        let mut chunk = [0u8; 4096];
        // Linux ends the reads with EIO once no process holds the device.
        loop {
            match terminal.read(&mut chunk) {
                Ok(0) => break,
                Ok(n) => seen.extend_from_slice(&chunk[..n]),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
        let _ = sent.send(seen);
    });
    let seen = received.recv_timeout(RUN_BOUND).unwrap_or_else(|_| {
        panic!("the supervisor's terminal did not end within {RUN_BOUND:?}: {args:?}")
    });
    let status = child.0.wait().expect("wait for the supervisor");
    (status, String::from_utf8_lossy(&seen).into_owned())
}

/// The frames the bar drew (`... [===> ] 12/40 episodes  ...`): of the text between carriage
/// returns and line ends, without the terminal's control sequences (cursor moves, line
/// clears), what is not a line the supervisor printed.
fn frames(screen: &str) -> Vec<String> {
    let mut frames = Vec::new();
    let mut text = String::new();
    let mut chars = screen.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            // A control sequence: ESC [ parameters, then one final letter.
            '\u{1b}' => {
                if chars.next_if_eq(&'[').is_some() {
                    while chars.next().is_some_and(|c| !c.is_ascii_alphabetic()) {}
                }
            }
            '\r' | '\n' => frames.push(std::mem::take(&mut text)),
            c => text.push(c),
        }
    }
    frames.push(text);
    frames.retain(|frame| frame.contains("] ") && frame.contains(" episodes  "));
    frames
}

#[test]
fn the_progress_bar_shows_every_field_on_a_terminal_to_the_last_episode() {
    let dir = scratch();
    let (id, out) = (run_id("terminal"), dir.path().display().to_string());
    let args = [
        &words("--transport shm --scenario s3 --uavs 2 --trials 2 --episodes 3000")[..],
        &words("--eval-episodes 100 --eval-every 0 --seed 5")[..],
        &["--run-id", &id, "--out", &out],
    ]
    .concat();
    let (status, screen) = run_on_terminal(&args);
    assert!(status.success(), "{status}; on the terminal:\n{screen}");
    let frames = frames(&screen);
    let shown = |what: &str| frames.iter().any(|frame| frame.contains(what));
    let total = (3000 + 100) * 2;
    for field in [
        "training [",
        "greedy   [",
        "mean length",
        " ticks/s",
        "2 live agents",
        &format!("{total}/{total} episodes"),
    ] {
        assert!(shown(field), "no frame shows `{field}`; frames:\n{}", frames.join("\n"));
    }
    let last = frames.last().expect("frames were shown");
    assert!(last.contains(&format!("{total}/{total} episodes")), "the last frame: {last}");
    assert!(last.contains("greedy mean length"), "the last frame: {last}");
    assert_nothing_left(&id);
}
