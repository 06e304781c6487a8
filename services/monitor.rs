//! The monitor process: records latency, jitter and the trajectory (see `looplab_shared::monitor`).

use looplab_shared::contract::role::Role;

fn main() -> std::process::ExitCode {
    looplab_shared::runtime::stages::process_main(Role::Monitor.name(), looplab_shared::monitor::run)
}
