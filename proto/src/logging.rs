//! Logging set-up shared by every flockstep process: `tracing` to stderr, the level from
//! `FLOCKSTEP_LOG` (e.g. `debug`, `flockstep_world=info`), colours only on a terminal (the
//! supervisor sends its children's stderr to log files). A log line that cannot be written
//! (stderr closed or on a full disk) is dropped: reporting that on stderr would fail too.

/// Installs the subscriber; `default` applies when `FLOCKSTEP_LOG` is not set.
pub fn init(default: &str) {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("FLOCKSTEP_LOG")
                .unwrap_or_else(|_| default.into()),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .log_internal_errors(false)
        .init();
}
