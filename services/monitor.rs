//! The monitor process: records latency, jitter and the trajectory (see `looplab_shared::monitor`).

fn main() -> std::process::ExitCode {
    looplab_shared::stages::process_main("monitor", looplab_shared::monitor::run)
}
