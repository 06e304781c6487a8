//! The IMU, the only sensor (section V): a two-axis accelerometer along x_B and z_B, which
//! measures the specific force (13) and so depends on the thrust the motors actually produce,
//! and a one-axis gyro about y_B (12). Rate, noise and delay are set per sensor in the launch
//! file; the paper's simulation is continuous-time and has no multi-rate structure.

use super::{ACCEL, GYRO, state};
use crate::model::vectors::{Read, Signal};

pub const SIGNALS: &[Signal] = &[
    Signal {
        name: "accelerometer",
        components: &ACCEL,
        read: Read::Computed(|_, x, _, out| out[..2].copy_from_slice(&x[state::ACCEL])),
    },
    Signal { name: "gyro", components: &GYRO, read: Read::Computed(|_, x, _, out| out[0] = x[state::THETA_DOT]) },
];
