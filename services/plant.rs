//! The plant process of the loop (see `looplab_shared::stages`).

fn main() -> std::process::ExitCode {
    looplab_shared::stages::process_main("plant", looplab_shared::plant::run)
}
