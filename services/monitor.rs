//! The monitor process: records latency, jitter and the trajectory (see `looplab_shared::monitor`).

fn main() -> std::process::ExitCode {
    use looplab_shared::{contract::role::Role, runtime};
    runtime::child::process_main(Role::Monitor, looplab_shared::monitor::run)
}
