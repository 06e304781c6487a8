//! The reaction-wheel pendulum's model (paper 003 §2): its parameters, ẋ and the
//! linearisation. The plant integrates it; the estimator uses it as its nominal model.
//!
//!   J₀ θ̈ = m l g sin θ − τ
//!   φ̈   = τ (1/J_r + 1/J₀) − (m l g / J₀) sin θ

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Physical parameters [paper 003 §1], plus the actuator's torque constant and current limit
/// (our choices; see README.md).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// Pendulum mass, kg.
    pub m_p: f64,
    /// Pivot to pendulum centre of mass, m.
    pub l_p: f64,
    /// Pendulum inertia about its centre of mass, kg·m².
    pub j_p: f64,
    /// Rotor mass, kg.
    pub m_r: f64,
    /// Pivot to rotor centre of mass, m.
    pub l_r: f64,
    /// Rotor (wheel) inertia, kg·m².
    pub j_r: f64,
    /// Gravity, m/s².
    pub g: f64,
    /// Motor torque constant k, N·m/A.
    pub torque_constant: f64,
    /// The motor controller accepts currents in [−limit, +limit], A.
    pub current_limit_a: f64,
}

impl Model {
    /// Inertia of the pendulum with the rotor as a point mass, about the pivot: J₀.
    pub fn j0(&self) -> f64 {
        self.j_p + self.m_p * self.l_p * self.l_p + self.m_r * self.l_r * self.l_r
    }

    /// m·l = m_p l_p + m_r l_r.
    pub fn ml(&self) -> f64 {
        self.m_p * self.l_p + self.m_r * self.l_r
    }

    /// a = m l g / J₀ (paper (4.2)).
    pub fn a(&self) -> f64 {
        self.ml() * self.g / self.j0()
    }

    /// b = −k / J₀ (paper (4.2)).
    pub fn b(&self) -> f64 {
        -self.torque_constant / self.j0()
    }

    /// ẋ for state x and current I.
    pub fn derivative(&self, x: &Vector3<f64>, current: f64) -> Vector3<f64> {
        let j0 = self.j0();
        let tau = self.torque_constant * current;
        let gravity = self.ml() * self.g * x[0].sin();
        Vector3::new(x[1], (gravity - tau) / j0, tau * (1.0 / self.j_r + 1.0 / j0) - gravity / j0)
    }

    /// Total mechanical energy; constant when no torque acts (τ = 0).
    pub fn energy(&self, x: &Vector3<f64>) -> f64 {
        let wheel_abs = x[1] + x[2];
        0.5 * self.j0() * x[1] * x[1] + 0.5 * self.j_r * wheel_abs * wheel_abs + self.ml() * self.g * x[0].cos()
    }

    /// The linearisation at the upright equilibrium: ẋ = A x + B I.
    pub fn linearised(&self) -> (nalgebra::Matrix3<f64>, Vector3<f64>) {
        let a = self.a();
        let j0 = self.j0();
        let k = self.torque_constant;
        let a_mat = nalgebra::Matrix3::new(0.0, 1.0, 0.0, a, 0.0, 0.0, -a, 0.0, 0.0);
        let b_vec = Vector3::new(0.0, -k / j0, k * (1.0 / self.j_r + 1.0 / j0));
        (a_mat, b_vec)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub fn paper_model() -> Model {
        Model {
            m_p: 0.58,
            l_p: 0.10,
            j_p: 3.8e-3,
            m_r: 0.35,
            l_r: 0.22,
            j_r: 12.48e-4,
            g: 9.81,
            torque_constant: 0.0369,
            current_limit_a: 5.0,
        }
    }

    #[test]
    fn derived_constants_match_the_note() {
        let m = paper_model();
        assert!((m.j0() - 0.02654).abs() < 1e-5);
        assert!((m.ml() - 0.135).abs() < 1e-12);
        assert!((m.a() - 49.9).abs() < 0.01);
    }

    #[test]
    fn paper_gain_gives_the_notes_closed_loop_poles() {
        // I = −K X with K = (−378, −55, −1): poles −32.1 and −6.69 ± 1.10j.
        let m = paper_model();
        let (a, b) = m.linearised();
        let k = nalgebra::RowVector3::new(-378.0, -55.0, -1.0);
        let poles = (a - b * k).complex_eigenvalues();
        let mut re: Vec<f64> = poles.iter().map(|p| p.re).collect();
        re.sort_by(f64::total_cmp);
        assert!((re[0] + 32.14).abs() < 0.05, "{poles:?}");
        assert!((re[1] + 6.685).abs() < 0.01 && (re[2] + 6.685).abs() < 0.01, "{poles:?}");
        let im = poles.iter().map(|p| p.im.abs()).fold(0.0, f64::max);
        assert!((im - 1.100).abs() < 0.01, "{poles:?}");
    }
}
