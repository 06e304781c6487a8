//! What the quadcopter's sensors can measure. Rates, noise and delay are set per sensor in the
//! launch file: the paper's simulations read every signal every tick (`launch/quadcopter.toml`);
//! the lab reads only the motion-capture pose at 120 Hz (`launch/quadcopter/7-hover-mass-step.toml`).

use crate::scenarios::Signal;

pub const SIGNALS: &[Signal] = &[
    // Motion capture: position in {I} and the rotation matrix, row-major.
    Signal {
        name: "pose",
        components: &["p_x", "p_y", "p_z", "R_11", "R_12", "R_13", "R_21", "R_22", "R_23", "R_31", "R_32", "R_33"],
        read: |x, out| out[..12].copy_from_slice(&x[..12]),
    },
    // Linear velocity in the body frame.
    Signal {
        name: "velocity",
        components: &["v_x", "v_y", "v_z"],
        read: |x, out| out[..3].copy_from_slice(&x[12..15]),
    },
    // Body angular velocity.
    Signal {
        name: "angular_rate",
        components: &["w_x", "w_y", "w_z"],
        read: |x, out| out[..3].copy_from_slice(&x[15..18]),
    },
];
