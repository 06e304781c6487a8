//! The monitor process: records latency, jitter and the trajectory (see `looplab_shared::monitor`).

fn main() -> std::process::ExitCode {
    use looplab_shared::{contract::role::Role, runtime, scenarios};
    runtime::stage::child::process_main_with(Role::Monitor, looplab_shared::monitor::run, &scenarios::builtin())
}
