//! The sensors process of the loop (see `looplab_shared::runtime::builtin`).

fn main() -> std::process::ExitCode {
    use looplab_shared::{contract::role::Role, runtime, scenarios};
    runtime::stage::child::process_main_with(Role::Sensors, runtime::builtin::sensors, &scenarios::builtin())
}
