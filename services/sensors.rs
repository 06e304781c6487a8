//! The sensors process of the loop (see `looplab_shared::stages`).

fn main() -> std::process::ExitCode {
    looplab_shared::stages::process_main("sensors", looplab_shared::stages::sensors)
}
