//! `agent`: one UAV's learner for a running world (`agent --attach RUN`), or the tree tools
//! (`agent bt ...`); the same program as `supervisor agent`.

fn main() -> std::process::ExitCode {
    flockstep_agents::cli::main(std::env::args_os())
}
