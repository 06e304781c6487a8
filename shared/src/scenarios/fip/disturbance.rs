//! The force disturbance b at the UAV (section 6): (i) none, (ii) a constant, (iii) the
//! Ornstein–Uhlenbeck process (71), ḃ = 1.5·diag(13, 15, 22)⁻¹(−b + 5·diag(6.5, 5, 4)·w_d),
//! written here per axis as ḃᵢ = (−bᵢ + gᵢwᵢ)/τᵢ.
//!
//! The paper does not give w_d's sample time. Here w_d is a seeded Gaussian
//! (standard deviation 0.1) drawn every `ou_noise_sample_s` and held, and b is integrated
//! exactly between draws: b(t + s) = gw + (b(t) − gw)·e^(−s/τ). The stationary spread is then
//! √(g²σ²T_s/(2τ)): (0.078, 0.056, 0.037) N at the default 0.01 s.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    None,
    Constant,
    OrnsteinUhlenbeck,
}

impl std::fmt::Display for Kind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Kind::None => "no disturbance",
            Kind::Constant => "constant disturbance",
            Kind::OrnsteinUhlenbeck => "stochastic disturbance",
        })
    }
}

/// `[disturbance]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceSection {
    /// none | constant | ornstein-uhlenbeck.
    pub kind: Kind,
    /// constant: b, N, inertial (NED).
    pub constant_n: [f64; 3],
    /// ornstein-uhlenbeck: b(0), N.
    pub ou_initial_n: [f64; 3],
    /// τᵢ, s (the paper: 13/1.5, 15/1.5, 22/1.5).
    pub ou_time_constants_s: [f64; 3],
    /// gᵢ, N (the paper: 5·6.5, 5·5, 5·4).
    pub ou_noise_gain_n: [f64; 3],
    /// w_d's standard deviation (the paper: 0.1).
    pub ou_noise_std: f64,
    /// How long each draw of w_d is held, s.
    pub ou_noise_sample_s: f64,
}

impl DisturbanceSection {
    /// b(0).
    pub fn initial(&self) -> [f64; 3] {
        match self.kind {
            Kind::None => [0.0; 3],
            Kind::Constant => self.constant_n,
            Kind::OrnsteinUhlenbeck => self.ou_initial_n,
        }
    }
}

/// b over time, as the plant integrates it.
pub struct Disturbance {
    section: DisturbanceSection,
    rng: ChaCha8Rng,
    /// The draw in effect and the noise slot it was drawn in.
    held: Option<(u64, [f64; 3])>,
}

impl Disturbance {
    pub fn new(section: DisturbanceSection, seed: u64) -> Self {
        let rng = ChaCha8Rng::seed_from_u64(seed ^ crate::config::seed::fnv1a("disturbance"));
        Self { section, rng, held: None }
    }

    /// The gᵢwᵢ b is pulled towards over the interval from t (a new draw at each noise slot).
    fn target(&mut self, t: f64) -> [f64; 3] {
        let s = &self.section;
        // A tiny margin so that a tick on a slot boundary in exact arithmetic is in the new slot.
        let slot = ((t + 1e-9) / s.ou_noise_sample_s).floor() as u64;
        match self.held {
            Some((drawn, w)) if drawn == slot => w,
            _ => {
                let w: [f64; 3] = std::array::from_fn(|i| {
                    let n: f64 = StandardNormal.sample(&mut self.rng);
                    s.ou_noise_gain_n[i] * s.ou_noise_std * n
                });
                self.held = Some((slot, w));
                w
            }
        }
    }

    /// b over the tick [t, t + dt] from b(t) = `b`.
    pub fn over_tick(&mut self, t: f64, b: [f64; 3]) -> OverTick {
        let (kind, tau) = (self.section.kind, self.section.ou_time_constants_s);
        let target = if kind == Kind::OrnsteinUhlenbeck { self.target(t) } else { b };
        OverTick { start: b, target, tau, drifts: kind == Kind::OrnsteinUhlenbeck }
    }
}

/// b within one tick.
#[derive(Debug, Clone, Copy)]
pub struct OverTick {
    start: [f64; 3],
    target: [f64; 3],
    tau: [f64; 3],
    drifts: bool,
}

impl OverTick {
    /// b at `s` seconds into the tick.
    pub fn at(&self, s: f64) -> [f64; 3] {
        if !self.drifts {
            return self.start;
        }
        std::array::from_fn(|i| self.target[i] + (self.start[i] - self.target[i]) * (-s / self.tau[i]).exp())
    }
}

#[cfg(test)]
pub mod tests {
    use super::*;

    /// The stationary standard deviation of each axis of the Ornstein–Uhlenbeck process with
    /// held noise, √(g²σ²T_s/(2τ)) (for T_s ≪ τ).
    fn ou_stationary_std(section: &DisturbanceSection) -> [f64; 3] {
        std::array::from_fn(|i| {
            let g = section.ou_noise_gain_n[i] * section.ou_noise_std;
            (g * g * section.ou_noise_sample_s / (2.0 * section.ou_time_constants_s[i])).sqrt()
        })
    }

    pub fn paper(kind: Kind) -> DisturbanceSection {
        DisturbanceSection {
            kind,
            constant_n: [-0.5, 0.5, -0.8],
            ou_initial_n: [0.2, -0.2, -0.3],
            ou_time_constants_s: [13.0 / 1.5, 10.0, 22.0 / 1.5],
            ou_noise_gain_n: [32.5, 25.0, 20.0],
            ou_noise_std: 0.1,
            ou_noise_sample_s: 0.01,
        }
    }

    /// The derived spread: (0.078, 0.056, 0.037) N at T_s = 0.01 s, and the simulated spread
    /// over a long run agrees with it.
    #[test]
    fn the_ou_spread_matches_the_formula() {
        let section = paper(Kind::OrnsteinUhlenbeck);
        let expected = ou_stationary_std(&section);
        for (got, note) in expected.iter().zip([0.078, 0.056, 0.037]) {
            assert!((got - note).abs() < 1e-3, "{got} vs {note}");
        }
        let mut d = Disturbance::new(section, 3);
        let mut b = [0.0; 3];
        let (dt, n) = (0.01, 400_000);
        let mut sum_sq = [0.0; 3];
        for k in 0..n {
            b = d.over_tick(k as f64 * dt, b).at(dt);
            for i in 0..3 {
                sum_sq[i] += b[i] * b[i];
            }
        }
        for i in 0..3 {
            let std = (sum_sq[i] / n as f64).sqrt();
            // 4000 s is about 300–450 time constants: the sample spread is within ~8 %.
            assert!((std / expected[i] - 1.0).abs() < 0.12, "axis {i}: {std} vs {}", expected[i]);
        }
    }
}
