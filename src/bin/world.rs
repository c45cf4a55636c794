//! `world`: the simulation's ground truth and barrier, the same program as `supervisor
//! world`, for running a world by hand (agents then attach to it with `agent --attach`).

fn main() -> std::process::ExitCode {
    flockstep_world::node::main(std::env::args_os())
}
