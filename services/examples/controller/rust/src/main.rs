//! The pendulum's built-in controller (shared/src/scenarios/pendulum/controller.rs) as a crate of
//! one's own: the same arithmetic in the same order, u = -(K·x) clamped to ±current_limit_a, with
//! x the estimate minus the upright reference, which is zero. Run it with
//! `cargo build --release -p looplab-example-controller` and
//! `looplab run services/examples/controller/rust/pendulum_rust.toml`.

use looplab_sdk::model::scenario::Controller;
use looplab_sdk::runtime::stage::user_stage::run_controller;

struct StateFeedback {
    gains: [f64; 3],
    limit: f64,
}

impl Controller for StateFeedback {
    fn update(&mut self, _t: f64, x: &[f64], u: &mut [f64]) {
        let current = -(self.gains[0] * x[0] + self.gains[1] * x[1] + self.gains[2] * x[2]);
        u[0] = current.clamp(-self.limit, self.limit);
    }
}

fn main() -> std::process::ExitCode {
    run_controller(|stage| {
        let gain = |i| stage.number(&format!("controller.gains.{i}"));
        Ok(Box::new(StateFeedback {
            gains: [gain(0)?, gain(1)?, gain(2)?],
            limit: stage.number("model.current_limit_a")?,
        }))
    })
}
