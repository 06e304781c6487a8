//! The estimator process of the loop (see `looplab_shared::stages`).

fn main() -> std::process::ExitCode {
    looplab_shared::stages::process_main("estimator", looplab_shared::stages::estimator)
}
