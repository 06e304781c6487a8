//! The tethered robot's metrics (names are a contract, issue 15):
//!
//! - `etrack_mean`, `etrack_std`: e_track of section VI-B (from the true state) averaged over
//!   the run, and its spread; `etrack_mean_phase1/2/3`, `etrack_std_phase1/2/3` per phase
//!   (constant, transition, constant again); `etrack_max_phase3`;
//! - `observer_converged_s`: from when on both estimated angles stay within 1e-3 rad of the
//!   truth (the run's end if they never settle);
//! - `phi_hat_err_rms_phase3_rad`, `theta_hat_err_rms_phase3_rad` and their maxima: the
//!   estimated angles' errors over phase 3;
//! - `active_branch_switches`: how often the selector changed branch; `plus_branch_share`;
//! - `link_force_min_n`: the smallest true f_L (≤ 0: the observer lost observability there);
//! - `thrust_phase1_end_n`, `thrust_final_n`: the motors' mean thrust over the last second of
//!   phase 1 and of the run (the flatness maps' equilibria);
//! - `lost`: 1 if the vehicle reached the ground (ϕ ∉ (0, π)), with `lost_at_s`.

use std::collections::BTreeMap;
use std::f64::consts::PI;

use super::reference::TetheredReference;
use super::{layout, state};
use crate::model::mean::{Mean, max_keeping_nan};
use crate::model::poly::wrap;
use crate::model::reference::Reference;
use crate::model::scenario::{Metrics, Row};

/// The observer counts as converged within this of the true angles, rad (the bar).
pub const CONVERGED_RAD: f64 = 1e-3;

pub struct TetheredMetrics {
    reference: TetheredReference,
    /// Where phase 2 and phase 3 begin, and the run's end, s.
    phase2_s: f64,
    phase3_s: f64,
    end_s: f64,
    etrack: Mean,
    etrack_phase: [Mean; 3],
    etrack_max_phase3: f64,
    /// The last tick at which an estimated angle was off by the bar or more.
    last_unconverged_s: Option<f64>,
    phase3_error: [Mean; 2],
    phase3_error_max: [f64; 2],
    last_branch: Option<f64>,
    switches: u64,
    plus: u64,
    ticks: u64,
    link_force_min: f64,
    thrust_phase1_end: Mean,
    thrust_final: Mean,
    lost_at: Option<f64>,
    last_t: f64,
}

impl TetheredMetrics {
    pub fn new(reference: TetheredReference, phase1_s: f64, transition_s: f64, duration_s: f64) -> Self {
        Self {
            reference,
            phase2_s: phase1_s,
            phase3_s: phase1_s + transition_s,
            end_s: duration_s,
            etrack: Mean::default(),
            etrack_phase: [Mean::default(); 3],
            etrack_max_phase3: 0.0,
            last_unconverged_s: None,
            phase3_error: [Mean::default(); 2],
            phase3_error_max: [0.0; 2],
            last_branch: None,
            switches: 0,
            plus: 0,
            ticks: 0,
            link_force_min: f64::INFINITY,
            thrust_phase1_end: Mean::default(),
            thrust_final: Mean::default(),
            lost_at: None,
            last_t: 0.0,
        }
    }
}

impl Metrics for TetheredMetrics {
    frozen_fields!(
        etrack,
        etrack_phase,
        etrack_max_phase3,
        last_unconverged_s,
        phase3_error,
        phase3_error_max,
        last_branch,
        switches,
        plus,
        ticks,
        link_force_min,
        thrust_phase1_end,
        thrust_final,
        lost_at,
        last_t
    );

    fn observe(&mut self, row: &Row) {
        let (t, x, e) = (row.t, row.state, row.estimate);
        self.last_t = t;
        self.ticks += 1;
        let phase = if t < self.phase2_s {
            0
        } else if t < self.phase3_s {
            1
        } else {
            2
        };
        let etrack = self.reference.error(t, x);
        self.etrack.add(etrack);
        self.etrack_phase[phase].add(etrack);
        if phase == 2 {
            self.etrack_max_phase3 = max_keeping_nan(self.etrack_max_phase3, etrack);
        }

        let errors = [wrap(e[layout::PHI] - x[state::PHI]).abs(), wrap(e[layout::THETA] - x[state::THETA]).abs()];
        // NaN counts as off.
        if !errors.iter().all(|err| *err < CONVERGED_RAD) {
            self.last_unconverged_s = Some(t);
        }
        if phase == 2 {
            for ((mean, max), error) in self.phase3_error.iter_mut().zip(&mut self.phase3_error_max).zip(errors) {
                mean.add(error);
                *max = max_keeping_nan(*max, error);
            }
        }

        let branch = e[layout::ACTIVE_BRANCH];
        if self.last_branch.is_some_and(|last| last != branch) {
            self.switches += 1;
        }
        self.last_branch = Some(branch);
        if branch > 0.0 {
            self.plus += 1;
        }
        self.link_force_min = self.link_force_min.min(x[state::LINK_FORCE]);
        let thrust = x[state::THRUST];
        if t < self.phase2_s && t >= self.phase2_s - 1.0 {
            self.thrust_phase1_end.add(thrust);
        }
        if t >= self.end_s - 1.0 {
            self.thrust_final.add(thrust);
        }
        if self.lost_at.is_none() && !(x[state::PHI] > 0.0 && x[state::PHI] < PI) {
            self.lost_at = Some(t);
        }
    }

    fn finish(&self) -> BTreeMap<String, f64> {
        let mut m = BTreeMap::new();
        let mut put = |name: &str, value: Option<f64>| {
            if let Some(v) = value {
                m.insert(name.to_string(), v);
            }
        };
        put("etrack_mean", self.etrack.mean());
        put("etrack_std", self.etrack.std());
        for (i, phase) in self.etrack_phase.iter().enumerate() {
            put(&format!("etrack_mean_phase{}", i + 1), phase.mean());
            put(&format!("etrack_std_phase{}", i + 1), phase.std());
        }
        if self.etrack_phase[2].n > 0 {
            put("etrack_max_phase3", Some(self.etrack_max_phase3));
        }
        // The first tick of the stretch within the bar that lasts to the end.
        let converged = match self.last_unconverged_s {
            None => 0.0,
            Some(t) => t.min(self.last_t),
        };
        put("observer_converged_s", Some(converged));
        put("phi_hat_err_rms_phase3_rad", self.phase3_error[0].rms());
        put("theta_hat_err_rms_phase3_rad", self.phase3_error[1].rms());
        if self.phase3_error[0].n > 0 {
            put("phi_hat_err_max_phase3_rad", Some(self.phase3_error_max[0]));
            put("theta_hat_err_max_phase3_rad", Some(self.phase3_error_max[1]));
        }
        put("active_branch_switches", Some(self.switches as f64));
        if self.ticks > 0 {
            put("plus_branch_share", Some(self.plus as f64 / self.ticks as f64));
            put("link_force_min_n", Some(self.link_force_min));
        }
        put("thrust_phase1_end_n", self.thrust_phase1_end.mean());
        put("thrust_final_n", self.thrust_final.mean());
        put("lost", Some(if self.lost_at.is_some() { 1.0 } else { 0.0 }));
        put("lost_at_s", self.lost_at);
        m
    }

    fn notes(&self) -> Vec<String> {
        let mut notes = vec![];
        if let Some(t) = self.lost_at {
            notes.push(format!("the vehicle reached the ground (ϕ left (0, π)) at t = {t:.3} s"));
        }
        if self.last_unconverged_s.is_some_and(|t| t >= self.last_t) {
            notes.push(format!("the estimated angles never stayed within {CONVERGED_RAD} rad of the truth"));
        }
        notes
    }
}
