//! `supervisor`: runs experiments and writes their results. It is also the world and the
//! agent program (`supervisor world ...`, `supervisor agent ...`), so building it alone
//! is enough to run.

fn main() -> std::process::ExitCode {
    flockstep_supervisor::main()
}
