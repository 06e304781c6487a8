//! The nominal vehicle of section VI (m_R = 1 kg, J_R = 0.25 kg·m², l = 2 m), the model's
//! constants a₁, a₂, a₃ of (2), the equilibria of the flatness maps, and the actuator's
//! accepted ranges. The controller and the observer use these values; the plant uses them
//! changed by the deviations Δ of section VI-B.

use serde::Deserialize;

/// `[model]`: the nominal values.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// m_R, kg.
    pub robot_mass_kg: f64,
    /// J_R, kg·m².
    pub inertia_kg_m2: f64,
    /// l, m.
    pub link_length_m: f64,
    pub g_m_s2: f64,
    /// 0 ≤ f_R ≤ this, N (the paper gives no limit).
    pub thrust_max_n: f64,
    /// |τ_R| ≤ this, N·m.
    pub torque_max_n_m: f64,
    /// |ḟ_R| ≤ this, N/s: the compensator's rate, which the estimator needs.
    pub thrust_rate_max_n_s: f64,
}

impl Model {
    /// a₁ = −g/l, s⁻².
    pub fn a1(&self) -> f64 {
        -self.g_m_s2 / self.link_length_m
    }

    /// a₂ = 1/(m_R l).
    pub fn a2(&self) -> f64 {
        1.0 / (self.robot_mass_kg * self.link_length_m)
    }

    /// a₃ = 1/J_R.
    pub fn a3(&self) -> f64 {
        1.0 / self.inertia_kg_m2
    }

    /// At rest at elevation ϕ and attitude ϑ (the flatness map of Γa′ with all derivatives
    /// zero): f_R = m_R g cos ϕ / cos(ϕ + ϑ), and the link force f_L of (5).
    pub fn equilibrium_of_attitude(&self, phi: f64, theta: f64) -> Equilibrium {
        let thrust = -self.a1() * phi.cos() / (self.a2() * (phi + theta).cos());
        let link_force = (self.a1() / self.a2()) * phi.sin() + (phi + theta).sin() * thrust;
        Equilibrium { thrust, theta, link_force }
    }

    /// At rest at elevation ϕ with link force f_L (the flatness map of Γb): the thrust r has
    /// r cos ψ = m_R g cos ϕ and r sin ψ = f_L + m_R g sin ϕ, ψ = ϕ + ϑ, taking f_R > 0.
    pub fn equilibrium_of_link_force(&self, phi: f64, link_force: f64) -> Equilibrium {
        let weight = self.robot_mass_kg * self.g_m_s2;
        let (c, s) = (weight * phi.cos(), link_force + weight * phi.sin());
        Equilibrium { thrust: c.hypot(s), theta: s.atan2(c) - phi, link_force }
    }
}

/// A static point of the vehicle on its link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Equilibrium {
    pub thrust: f64,
    pub theta: f64,
    pub link_force: f64,
}

#[cfg(test)]
pub mod tests {
    use super::*;

    pub fn paper() -> Model {
        Model {
            robot_mass_kg: 1.0,
            inertia_kg_m2: 0.25,
            link_length_m: 2.0,
            g_m_s2: 9.81,
            thrust_max_n: 60.0,
            torque_max_n_m: 20.0,
            thrust_rate_max_n_s: 1000.0,
        }
    }

    /// The derived equilibria: Γa′ from (10°, 30°) to (50°, 5°), Γb from (45°, 3 N) to
    /// (135°, 5 N), with a₁ = −4.905 and a₂ = 0.5.
    #[test]
    fn the_equilibria_are_the_notes() {
        let m = paper();
        assert_eq!((m.a1(), m.a2(), m.a3()), (-4.905, 0.5, 4.0));
        let close = |got: f64, want: f64| assert!((got - want).abs() < 5e-5, "{got} vs {want}");
        let start = m.equilibrium_of_attitude(10f64.to_radians(), 30f64.to_radians());
        close(start.thrust, 12.6115);
        close(start.link_force, 6.4030);
        let end = m.equilibrium_of_attitude(50f64.to_radians(), 5f64.to_radians());
        close(end.thrust, 10.9937);
        close(end.link_force, 1.4906);
        let start = m.equilibrium_of_link_force(45f64.to_radians(), 3.0);
        close(start.thrust, 12.1184);
        close(start.theta.to_degrees(), 10.0815);
        let end = m.equilibrium_of_link_force(135f64.to_radians(), 5.0);
        close(end.thrust, 13.8059);
        close(end.theta.to_degrees(), -14.8381);
    }
}
