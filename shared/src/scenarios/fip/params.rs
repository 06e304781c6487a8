//! The vehicle (section 7 for the simulation, section 8 for the experiment): the UAV's mass m_Q,
//! the load's m_L on a massless rod of length ℓ, gravity, and the actuator's accepted ranges.

use serde::Deserialize;

/// `[model]`. The plant, the filter and the controller share it: the paper's simulation has no
/// model mismatch.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// m_Q, kg.
    pub uav_mass_kg: f64,
    /// m_L, kg.
    pub load_mass_kg: f64,
    /// ℓ, m.
    pub rod_length_m: f64,
    pub g_m_s2: f64,
    /// The thrust the actuator accepts: 0 ≤ T ≤ this, N (the paper gives no limit).
    pub thrust_max_n: f64,
    /// |Ωᵢ| ≤ this, rad/s (the paper gives no limit).
    pub rate_max_rad_s: f64,
}

impl Model {
    /// m_T = m_Q + m_L.
    pub fn total_mass(&self) -> f64 {
        self.uav_mass_kg + self.load_mass_kg
    }

    /// m_Q ℓ, kg·m: the filter's disturbance state is b/(m_Q ℓ).
    pub fn uav_mass_times_rod(&self) -> f64 {
        self.uav_mass_kg * self.rod_length_m
    }

    /// m_T g: the hover thrust, N.
    pub fn hover_thrust(&self) -> f64 {
        self.total_mass() * self.g_m_s2
    }
}

#[cfg(test)]
pub mod tests {
    use super::*;

    /// Section 7.
    pub fn simulation() -> Model {
        Model {
            uav_mass_kg: 0.26,
            load_mass_kg: 0.03,
            rod_length_m: 0.7,
            g_m_s2: 9.81,
            thrust_max_n: 20.0,
            rate_max_rad_s: 20.0,
        }
    }

    /// Numbers derived by hand: m_T = 0.29 kg, m_Qℓ = 0.182 kg·m, m_T g = 2.8449 N.
    #[test]
    fn derived_masses_match_the_note() {
        let m = simulation();
        assert!((m.total_mass() - 0.29).abs() < 1e-15);
        assert!((m.uav_mass_times_rod() - 0.182).abs() < 1e-15);
        assert!((m.hover_thrust() - 2.8449).abs() < 1e-12);
    }
}
