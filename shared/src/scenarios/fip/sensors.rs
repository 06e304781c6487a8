//! What the flying inverted pendulum's sensors can measure: the motion capture of the load and
//! the UAV (positions and attitude R) and the UAV's velocity v_Q (Remark 4). Rates and noise are
//! set per sensor in the launch file. ω and v_L are never measured (section 3.2): the
//! estimator forms q from the two positions and the filter estimates ω.

use super::{LOAD_POSITION, ROTATION, UAV_POSITION, UAV_VELOCITY, state};
use crate::model::vectors::{Read, Signal};

pub const SIGNALS: &[Signal] = &[
    Signal {
        name: "load_position",
        components: &LOAD_POSITION,
        read: Read::Computed(|_, x, _, out| out[..3].copy_from_slice(&x[state::LOAD_POSITION])),
    },
    Signal {
        name: "uav_position",
        components: &UAV_POSITION,
        read: Read::Computed(|_, x, _, out| out[..3].copy_from_slice(&x[state::UAV_POSITION])),
    },
    // R, row-major.
    Signal {
        name: "attitude",
        components: &ROTATION,
        read: Read::Computed(|_, x, _, out| out[..9].copy_from_slice(&x[state::ROTATION])),
    },
    Signal {
        name: "uav_velocity",
        components: &UAV_VELOCITY,
        read: Read::Computed(|_, x, _, out| out[..3].copy_from_slice(&x[state::UAV_VELOCITY])),
    },
];
