//! What the pendulum's sensors can measure. Rates, noise, bias and quantisation are set per
//! sensor in the launch file (`launch/pendulum.toml`); the emulator is `crate::model::sensors`.

use crate::model::vectors::{Component, Read, Signal};

pub const SIGNALS: &[Signal] = &[
    // The incremental encoder on the pivot: the pendulum angle.
    Signal {
        name: "theta",
        components: &[Component::new("theta", "rad")],
        read: Read::Computed(|_, x, _, out| out[0] = x[0]),
    },
    // The motor controller's speed measurement: wheel speed relative to the pendulum.
    Signal {
        name: "wheel_speed",
        components: &[Component::new("wheel_speed", "rad/s")],
        read: Read::Computed(|_, x, _, out| out[0] = x[2]),
    },
];
