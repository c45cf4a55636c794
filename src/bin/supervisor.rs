fn main() -> std::process::ExitCode {
    flockstep_supervisor::main()
}
