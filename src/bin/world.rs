fn main() -> std::process::ExitCode {
    flockstep_world::node::main(std::env::args_os())
}
