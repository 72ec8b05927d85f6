//! `host-sim`: parses the command line and dispatches to a subcommand (see [`cli`]).

mod cli;

fn main() -> std::process::ExitCode {
    cli::main()
}
