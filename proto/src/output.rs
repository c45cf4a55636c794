//! What every flockstep program prints, written without `println!`/`eprintln!`, which panic
//! when the stream cannot be written (`supervisor optimum | head -2`, `agent bt show T >
//! /dev/full`, `2>/dev/full`).
//!
//! Stdout carries what a command produces. Once its reader has gone (a broken pipe) nobody
//! wants the rest, so the rest is dropped quietly and the command ends with the status it
//! would have had: a run's results are in its directory whatever became of the line naming
//! them. Any other failure to write stdout (a full disk) loses output someone asked for, and
//! is an error naming stdout. Stderr carries messages about the command; when it cannot be
//! written there is nowhere left to report that, so its failures are ignored.

use std::io::{Error, ErrorKind, Write};

/// Writes `text` and a newline to stdout (see the module's doc for a reader that has gone).
pub fn line(line: &str) -> Result<(), Error> {
    text(&format!("{line}\n"))
}

/// Writes `text` as it is to stdout (see the module's doc for a reader that has gone).
pub fn text(text: &str) -> Result<(), Error> {
    let mut stdout = std::io::stdout().lock();
    match stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush()) {
        Err(e) if e.kind() != ErrorKind::BrokenPipe => {
            Err(Error::new(e.kind(), format!("cannot write to stdout: {e}")))
        }
        _ => Ok(()),
    }
}

/// Writes `text` and a newline to stderr; a failure is ignored (nowhere to report it).
pub fn message(text: &str) {
    let mut stderr = std::io::stderr().lock();
    let _ = stderr.write_all(text.as_bytes()).and_then(|()| stderr.write_all(b"\n"));
}
