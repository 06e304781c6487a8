//! The controller process of the loop (see `looplab_shared::stages`).

fn main() -> std::process::ExitCode {
    looplab_shared::stages::process_main("controller", looplab_shared::stages::controller)
}
