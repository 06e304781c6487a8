//! What the quadcopter's sensors can measure. Rates, noise and delay are set per sensor in the
//! launch file: the paper's simulations read every signal every tick (`launch/quadcopter.toml`);
//! the lab reads only the motion-capture pose at 120 Hz (`launch/quadcopter/7-hover-mass-step.toml`).

use super::{POSE, RATE, VELOCITY};
use crate::model::vectors::{Read, Signal};

pub const SIGNALS: &[Signal] = &[
    // Motion capture: position in {I} and the rotation matrix, row-major.
    Signal {
        name: "pose",
        components: &POSE,
        read: Read::Computed(|_, x, _, out| out[..12].copy_from_slice(&x[..12])),
    },
    // Linear velocity in the body frame.
    Signal {
        name: "velocity",
        components: &VELOCITY,
        read: Read::Computed(|_, x, _, out| out[..3].copy_from_slice(&x[12..15])),
    },
    // Body angular velocity.
    Signal {
        name: "angular_rate",
        components: &RATE,
        read: Read::Computed(|_, x, _, out| out[..3].copy_from_slice(&x[15..18])),
    },
];
