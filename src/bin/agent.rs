fn main() -> std::process::ExitCode {
    flockstep_agents::cli::main()
}
