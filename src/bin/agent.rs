fn main() -> std::process::ExitCode {
    flockstep_agents::cli::main(std::env::args_os())
}
