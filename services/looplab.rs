//! `looplab`, the launcher: starts the loop's processes from a launch file, supervises them and
//! reports (see `looplab_shared::cli`).

fn main() -> std::process::ExitCode {
    looplab_shared::cli::main()
}
