//! The tilt-rotor's physical parameters (paper 004, Table 1, with our readings of the
//! misprinted entries), the seeded ±30 % draw of the plant's masses and inertias, and the
//! control-design model of assumption (A1).

use rand::SeedableRng;
use rand::distr::{Distribution, StandardUniform};
use rand_chacha::ChaCha8Rng;

/// Body 1 (the main body), 2 (right thruster group), 3 (left), 4 (the load).
pub const BODIES: usize = 4;

#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// m₁..m₄, kg.
    pub mass: [f64; BODIES],
    /// Each body's inertia tensor about its own centre of mass, in its own frame, kg·m².
    pub inertia: [[[f64; 3]; 3]; BODIES],
    /// d₁, d₂, d₃ in B, m (d₄ follows from the rod and γ).
    pub offset: [[f64; 3]; 3],
    /// The rotors' inward cant β, rad.
    pub beta: f64,
    /// Rod length l, m.
    pub rod_length: f64,
    pub g: f64,
    /// kτ/b, the propeller drag-torque to thrust ratio of (22), m (printed "k_d").
    pub drag_torque_per_thrust: f64,
    /// Viscous drag on γ̇₁ and γ̇₂ (printed "μ_y"), N·m·s/rad.
    pub load_drag: f64,
}

/// β = 5° [Table 1]. The known-force sensor reads it, so it is a constant of the scenario.
pub const BETA: f64 = 5.0 * std::f64::consts::PI / 180.0;

impl Params {
    /// Table 1. The products of inertia of body 1 are used as tensor entries;
    /// "k_d" is kτ/b and "μ_y" is the drag on γ̇.
    pub fn table1() -> Self {
        let diag = |x: f64, y: f64, z: f64| [[x, 0.0, 0.0], [0.0, y, 0.0], [0.0, 0.0, z]];
        let thruster = diag(0.00004223, 0.00004096, 0.00002658);
        Params {
            mass: [1.402, 0.1566, 0.1566, 0.05],
            inertia: [
                [
                    [0.01902947, 0.00002074, -0.00087669],
                    [0.00002074, 0.00881577, 0.00000808],
                    [-0.00087669, 0.00000808, 0.01747731],
                ],
                thruster,
                thruster,
                diag(0.00000264, 0.00000264, 0.00000264),
            ],
            offset: [[0.00672, 0.000342, -0.0789], [0.0, -0.247, 0.123], [0.0, 0.247, 0.123]],
            beta: BETA,
            rod_length: 0.5,
            g: 9.81,
            drag_torque_per_thrust: 0.0179,
            load_drag: 0.005,
        }
    }

    /// Σ mᵢ, kg.
    pub fn total_mass(&self) -> f64 {
        self.mass.iter().sum()
    }

    /// One seeded draw: every mass and every inertia tensor (as a whole) scaled by its own
    /// factor from U[1 − fraction, 1 + fraction]. The geometry is unchanged.
    pub fn perturbed(&self, fraction: f64, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut factor = || {
            let u: f64 = StandardUniform.sample(&mut rng);
            1.0 + fraction * (2.0 * u - 1.0)
        };
        let mut p = self.clone();
        for m in &mut p.mass {
            *m *= factor();
        }
        for tensor in &mut p.inertia {
            let k = factor();
            for row in tensor.iter_mut() {
                for v in row.iter_mut() {
                    *v *= k;
                }
            }
        }
        p
    }

    /// The control-design model (A1): the main body's centre of mass at B's origin, the rotors
    /// level with it (d_z = 0), and equal thruster masses (their mean), so that H = −S(m₄d₄).
    pub fn control_model(&self) -> Self {
        let mut p = self.clone();
        p.offset[0] = [0.0; 3];
        let dy = 0.5 * (p.offset[2][1] - p.offset[1][1]);
        p.offset[1] = [0.0, -dy, 0.0];
        p.offset[2] = [0.0, dy, 0.0];
        let m = 0.5 * (p.mass[1] + p.mass[2]);
        p.mass[1] = m;
        p.mass[2] = m;
        p
    }

    /// The per-rotor thrust that holds a level hover at α = 0: m·g/(2 cos β).
    pub fn hover_thrust(&self) -> f64 {
        self.total_mass() * self.g / (2.0 * self.beta.cos())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table1_totals_and_hover_thrust() {
        let p = Params::table1();
        assert!((p.total_mass() - 1.7652).abs() < 1e-12);
        // Derived by hand: 8.691 N per rotor.
        assert!((p.hover_thrust() - 8.691).abs() < 5e-4, "{}", p.hover_thrust());
    }

    #[test]
    fn the_draw_is_seeded_and_within_the_band() {
        let p = Params::table1();
        let a = p.perturbed(0.3, 7);
        assert_eq!(a, p.perturbed(0.3, 7));
        assert_ne!(a, p.perturbed(0.3, 8));
        for (drawn, nominal) in a.mass.iter().zip(&p.mass) {
            let k = drawn / nominal;
            assert!((0.7..=1.3).contains(&k) && k != 1.0, "{k}");
        }
        assert_eq!(a.offset, p.offset);
    }
}
