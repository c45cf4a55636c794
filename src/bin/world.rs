fn main() -> std::process::ExitCode {
    flockstep_world::node::main()
}
