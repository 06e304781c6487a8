//! What the tilt-rotor's sensors can measure. Rates and noise are set per sensor in the launch
//! file: the paper's position and velocity fix at 10 Hz (σ 0.05 m, 0.04 m/s), the angles and
//! rates every tick without noise, and the known translational force every tick (σ 1/3 N).

use super::dynamics::{rotation, thrust_directions};
use super::params::BETA;
use super::{ATTITUDE_SIGNAL, FORCE, POSITION, VELOCITY, state};
use crate::model::autodiff::mat_vec;
use crate::model::vectors::{Read, Signal};

/// The thrusters' force in F, R_B^F (r_R f_R + r_L f_L) of (21), from the attitude, the tilt
/// angles and the thrusts. This is a simple form of the "known" force T^F:
/// the estimator subtracts the nominal weight and leaves the load's pull, drag and the mass
/// error to the unknown input d̂.
pub fn thrust_force(angles: &[f64], thrust: [f64; 2]) -> [f64; 3] {
    let [r_r, r_l] = thrust_directions(BETA, angles[3], angles[4]);
    let body = [0, 1, 2].map(|i| r_r[i] * thrust[0] + r_l[i] * thrust[1]);
    mat_vec(&rotation([angles[0], angles[1], angles[2]]), body)
}

pub const SIGNALS: &[Signal] = &[
    Signal {
        name: "position",
        components: &POSITION,
        read: Read::Computed(|_, x, _, out| out[..3].copy_from_slice(&x[state::POSITION])),
    },
    Signal {
        name: "velocity",
        components: &VELOCITY,
        read: Read::Computed(|_, x, _, out| out[..3].copy_from_slice(&x[state::VELOCITY])),
    },
    Signal {
        name: "attitude",
        components: &ATTITUDE_SIGNAL,
        read: Read::Computed(|_, x, _, out| {
            out[..7].copy_from_slice(&x[state::ANGLES]);
            out[7..14].copy_from_slice(&x[state::ANGLE_RATES]);
        }),
    },
    Signal {
        name: "thrust_force",
        components: &FORCE,
        read: Read::Computed(|_, x, u, out| out[..3].copy_from_slice(&thrust_force(&x[state::ANGLES], [u[0], u[1]]))),
    },
];
