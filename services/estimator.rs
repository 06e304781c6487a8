//! The estimator process of the loop (see `looplab_shared::runtime::relay`).

fn main() -> std::process::ExitCode {
    use looplab_shared::{contract::role::Role, runtime};
    runtime::child::process_main(Role::Estimator, runtime::relay::estimator)
}
