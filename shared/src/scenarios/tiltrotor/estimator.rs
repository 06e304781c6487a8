//! The LKFUI, the linear Kalman filter with unknown inputs of paper 004 §4, eqs (58)–(71)
//! It estimates the translational position and velocity and the unknown force d.
//! It predicts every tick τ and corrects when a new 10 Hz position and velocity fix arrives.
//!
//! What comes from the paper and what was chosen here:
//! - Paper: the model (58)/(60) x⁺ = A x + B T^F + G d with B = G at the nominal mass; the
//!   prediction (64) every tick with d̂ held; the lifted model (59)/(61)/(62) on the fix grid,
//!   with Ḡ = Σ A^j G; the gain (69) under the constraint L E = F, E = F = Ḡ (C = I); the
//!   covariance (68); Q = B_Ts B_Tsᵀ (71), which carries the launch file's `q_scale`
//!   (1 is the literal (71), 1/9 is the 3σ = 1 N reading).
//! - Ω = E (Eᵀ (P^yy)⁻¹ E)⁻¹ Eᵀ (P^yy)⁻¹, the form for which L E = F holds.
//! - The simple form: the known input is the `thrust_force` reading (the
//!   thrusters' force in F) minus the nominal weight m·g·k. The load's pull, drag and the mass
//!   error are left to d̂.
//! - Our choice: R = diag(σ_p² I₃, σ_v² I₃); d̂₀ = 0.
//! - Our choice, `initial`: x̂₀|₀ is the launch file's start (at rest) with
//!   P₀ = diag(p0_p² I₃, p0_v² I₃) (`start`, the paper's Fig. 4, whose error starts at 0), or the
//!   first fix with P₀ = R (`first-fix`). A filter that starts after the first tick (a restarted
//!   estimator) always starts from the fix.
//! - Our choice: the covariance lives only on the fix grid. A_Ts, Ḡ and Q are built
//!   for the ticks that actually passed since the last correction. Normally that is h =
//!   T_s/τ_s.
//! - The d̂ update, see [`Lkfui::correct`]: this is (67) rewritten so that d̂ is consistent
//!   with a prediction that already contains G d̂.
//! - A fix is treated as a measurement of the state at the tick it is assimilated (the paper's
//!   zero-delay sensor). In real time, a fix that arrives late is not moved back.
//!   The exception is the first fix: x̂₀ is placed at its sample time and predicted to now. That
//!   way an estimator restarted while a fix is held does not start up to T_s behind.

use nalgebra::{SMatrix, SVector, Vector3};
use serde::Deserialize;

use super::layout;
use crate::contract::msg::SensorReading;
use crate::model::scenario::Estimator;

type Vector6 = SVector<f64, 6>;
type Matrix6 = SMatrix<f64, 6, 6>;
type Matrix6x3 = SMatrix<f64, 6, 3>;
type Matrix3x6 = SMatrix<f64, 3, 6>;

/// The `[estimator]` launch section. All values must be positive (`q_scale` may be 0).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EstimatorSection {
    /// Q = q_scale · B_Ts B_Tsᵀ. 1 is the paper's literal (71), unit force variance per tick.
    /// 1/9 is σ_T² for the stated 3σ = 1 N.
    pub q_scale: f64,
    /// σ of the position fix in R, m (default 0.05).
    pub r_position_m: f64,
    /// σ of the velocity fix in R, m/s (default 0.04).
    pub r_velocity_m_s: f64,
    /// What x̂₀|₀ is: the launch's start or the first fix.
    pub initial: Initial,
    /// σ of the start's position in P₀|₀, m (`initial = "start"`; a fix start uses R).
    pub p0_position_m: f64,
    /// σ of the start's velocity in P₀|₀, m/s.
    pub p0_velocity_m_s: f64,
}

/// Where the filter starts.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Initial {
    /// x̂₀|₀ = the launch's start position, at rest, with P₀ from `p0_*`.
    Start,
    /// x̂₀|₀ = the first fix, with P₀ = R.
    FirstFix,
}

impl EstimatorSection {
    /// The defaults: literal Q (71), R from the sensors' σ, the start known to 1 mm.
    pub fn paper() -> Self {
        EstimatorSection {
            q_scale: 1.0,
            r_position_m: 0.05,
            r_velocity_m_s: 0.04,
            initial: Initial::Start,
            p0_position_m: 0.001,
            p0_velocity_m_s: 0.001,
        }
    }
}

/// Which sensor (an index into the readings) carries each signal.
#[derive(Debug, Clone, Copy)]
pub struct Inputs {
    pub position: usize,
    pub velocity: usize,
    pub attitude: usize,
    pub force: usize,
}

/// A = [[I, τI], [0, I]] of (58) for a step τ. Over h steps this is A^h = the same matrix with hτ.
fn transition(step: f64) -> Matrix6 {
    let mut a = Matrix6::identity();
    for i in 0..3 {
        a[(i, i + 3)] = step;
    }
    a
}

/// B = G = [[τ²/(2m) I], [τ/m I]] of (60) for a step τ. With τ = T_s this is also Ḡ = Σ A^j G
/// of (62), because Σ_{j<h} (2j+1) = h².
fn force_map(step: f64, mass: f64) -> Matrix6x3 {
    let mut b = Matrix6x3::zeros();
    for i in 0..3 {
        b[(i, i)] = step * step / (2.0 * mass);
        b[(i + 3, i)] = step / mass;
    }
    b
}

/// B_Ts B_Tsᵀ = Σ_{j<h} (A^j B)(A^j B)ᵀ of (71) in closed form, per axis:
/// Q_pp = (τ²/2m)² h(4h²−1)/3, Q_pv = (τ²/2m)(τ/m) h², Q_vv = h (τ/m)².
fn lifted_force_covariance(tick: f64, mass: f64, ticks: u32) -> Matrix6 {
    let h = f64::from(ticks);
    let (bp, bv) = (tick * tick / (2.0 * mass), tick / mass);
    let (pp, pv, vv) = (bp * bp * h * (4.0 * h * h - 1.0) / 3.0, bp * bv * h * h, bv * bv * h);
    let mut q = Matrix6::zeros();
    for i in 0..3 {
        q[(i, i)] = pp;
        q[(i, i + 3)] = pv;
        q[(i + 3, i)] = pv;
        q[(i + 3, i + 3)] = vv;
    }
    q
}

/// The model lifted over h ticks: A_Ts, Ḡ, Q and Ḡ's left inverse (ḠᵀḠ)⁻¹Ḡᵀ.
#[derive(Debug, Clone)]
struct Lifted {
    ticks: u32,
    a: Matrix6,
    g_bar: Matrix6x3,
    q: Matrix6,
    g_bar_left_inverse: Matrix3x6,
}

impl Lifted {
    fn new(tick: f64, mass: f64, ticks: u32, q_scale: f64) -> Self {
        // No ticks between two fixes cannot happen in a loop that advances; one tick keeps Ḡ
        // of full rank if it ever does.
        let ticks = ticks.max(1);
        let period = f64::from(ticks) * tick;
        let g_bar = force_map(period, mass);
        let gram = (g_bar.transpose() * g_bar).try_inverse().expect("Ḡ has full column rank");
        Lifted {
            ticks,
            a: transition(period),
            g_bar,
            q: q_scale * lifted_force_covariance(tick, mass, ticks),
            g_bar_left_inverse: gram * g_bar.transpose(),
        }
    }
}

/// The filter once it has started (from the launch's start or a fix).
#[derive(Debug, Clone)]
struct Filter {
    /// x̂ = [x y z ẋ ẏ ż].
    x: Vector6,
    /// d̂, N, held between corrections.
    d: Vector3<f64>,
    /// P^xx_{k|k}, on the fix grid only.
    p: Matrix6,
    /// The seq of the last fix assimilated (none yet: a filter started from the launch's start).
    fix_seq: Option<u64>,
    /// The time of the last update, s.
    t: f64,
    ticks_since_fix: u32,
}

/// The LKFUI. It keeps the nominal mass; the plant's mass is drawn ±30 %.
#[derive(Debug, Clone)]
pub struct Lkfui {
    mass: f64,
    g: f64,
    tick_s: f64,
    inputs: Inputs,
    q_scale: f64,
    /// A and B = G of (58)/(60) at τ.
    a: Matrix6,
    b: Matrix6x3,
    r: Matrix6,
    p0: Matrix6,
    /// x̂₀|₀ for a filter that starts at the first tick, if `initial = "start"`.
    start: Option<Vector6>,
    /// The lifted model at the nominal T_s/τ_s. Other spacings are built when they happen.
    nominal: Lifted,
    filter: Option<Filter>,
}

fn diagonal(first: f64, second: f64) -> Matrix6 {
    Matrix6::from_diagonal(&Vector6::from_fn(|i, _| if i < 3 { first } else { second }))
}

impl Lkfui {
    pub fn new(
        section: &EstimatorSection,
        nominal_mass: f64,
        g: f64,
        tick_s: f64,
        fix_period_ticks: u32,
        inputs: Inputs,
        start_position: [f64; 3],
    ) -> Self {
        let start = (section.initial == Initial::Start)
            .then(|| Vector6::from_fn(|i, _| if i < 3 { start_position[i] } else { 0.0 }));
        Lkfui {
            mass: nominal_mass,
            g,
            tick_s,
            inputs,
            q_scale: section.q_scale,
            a: transition(tick_s),
            b: force_map(tick_s, nominal_mass),
            r: diagonal(section.r_position_m.powi(2), section.r_velocity_m_s.powi(2)),
            p0: diagonal(section.p0_position_m.powi(2), section.p0_velocity_m_s.powi(2)),
            start,
            nominal: Lifted::new(tick_s, nominal_mass, fix_period_ticks, section.q_scale),
            filter: None,
        }
    }

    /// The known input T^F: the thrusters' force minus the nominal weight (the simple
    /// form). Before the force sensor's first sample, 0 (hover).
    fn known_force(&self, reading: &SensorReading) -> Vector3<f64> {
        if reading.valid == 0 {
            return Vector3::zeros();
        }
        let v = &reading.value;
        Vector3::new(v[0], v[1], v[2] - self.mass * self.g)
    }

    /// The correction (65)–(69) over the ticks since the last one.
    ///
    /// The d̂ update is (67) rewritten for a prediction that contains G d̂. The prediction (64)
    /// adds G d̂_prev every tick, Ḡ d̂_prev in all. So the innovation ν = y − ŷ measures the
    /// part of d that d̂_prev did not explain. Applied to ν, the literal (67) estimates d − d̂_prev,
    /// not d. For a constant d it would then alternate between d and 0. Because L Ḡ = Ḡ (the
    /// constraint with E = F = Ḡ), the state update is the same with or without d̂ in the
    /// prediction. So the consistent estimate is d̂_new = d̂_prev + (ḠᵀḠ)⁻¹Ḡᵀ L ν. This equals
    /// (67) applied to the innovation of the prediction without d̂.
    fn correct(&self, filter: &mut Filter, y: &Vector6) {
        let lifted = if filter.ticks_since_fix == self.nominal.ticks {
            self.nominal.clone()
        } else {
            Lifted::new(self.tick_s, self.mass, filter.ticks_since_fix, self.q_scale)
        };
        let (l, p) = self.gain(&filter.p, &lifted);
        let innovation = y - filter.x;
        let step = l * innovation;
        filter.x += step;
        filter.d += lifted.g_bar_left_inverse * step;
        filter.p = p;
        filter.ticks_since_fix = 0;
    }

    /// The gain L (69) and P^xx_{k|k} (68) from P^xx_{k-1|k-1} over one lifted interval.
    fn gain(&self, p_post: &Matrix6, lifted: &Lifted) -> (Matrix6, Matrix6) {
        let p_prior = lifted.a * p_post * lifted.a.transpose() + lifted.q;
        // C = I: P^xy = P^xx, P^yy = P^xx + R (positive definite because R is).
        let p_yy = p_prior + self.r;
        let p_yy_inv = p_yy.cholesky().expect("R is positive definite").inverse();
        let k = p_prior * p_yy_inv;
        let e = lifted.g_bar;
        let constrained = (e.transpose() * p_yy_inv * e).try_inverse().expect("Ḡ has full column rank");
        // (69) in an equivalent form: L = K + (F − K E)(Eᵀ (P^yy)⁻¹ E)⁻¹ Eᵀ (P^yy)⁻¹.
        let l = k + (e - k * e) * constrained * e.transpose() * p_yy_inv;
        // (68), valid for any gain.
        let p = p_prior - l * p_prior.transpose() - p_prior * l.transpose() + l * p_yy * l.transpose();
        (l, (p + p.transpose()) * 0.5)
    }
}

impl Estimator for Lkfui {
    fn update(&mut self, t: f64, readings: &[SensorReading], _u_applied: &[f64], estimate: &mut [f64]) {
        estimate[..layout::LEN].fill(0.0);
        let attitude = &readings[self.inputs.attitude];
        if attitude.valid != 0 {
            estimate[layout::ANGLES.start..layout::ANGLE_RATES.end].copy_from_slice(&attitude.value[..14]);
        }
        let (position, velocity) = (&readings[self.inputs.position], &readings[self.inputs.velocity]);
        let fix_valid = position.valid != 0 && velocity.valid != 0;
        let fix = || Vector6::from_fn(|i, _| if i < 3 { position.value[i] } else { velocity.value[i - 3] });
        let u = self.known_force(&readings[self.inputs.force]);

        // x̂₀|₀ = the launch's start at the first tick (the fix held then counts as assimilated:
        // the first correction is the next fix, as in the paper's k = 1). Otherwise the first fix,
        // placed at its sample time: an estimator started (or restarted) while a fix is held
        // predicts it forward to now like any other.
        let initialising = self.filter.is_none();
        let first_tick = t < 0.5 * self.tick_s;
        let mut filter = match (self.filter.take(), self.start) {
            (Some(filter), _) => filter,
            (None, Some(start)) if first_tick => Filter {
                x: start,
                d: Vector3::zeros(),
                p: self.p0,
                fix_seq: fix_valid.then_some(position.seq),
                t,
                ticks_since_fix: 0,
            },
            (None, _) if fix_valid => Filter {
                x: fix(),
                d: Vector3::zeros(),
                p: self.r,
                fix_seq: Some(position.seq),
                t: position.sample_time,
                ticks_since_fix: 0,
            },
            (None, _) => return,
        };
        // One prediction (64) per elapsed tick: in real time a skipped tick still moved the
        // vehicle. The current force reading is the best known for each of them.
        let elapsed = ((t - filter.t) / self.tick_s).round().max(0.0) as u32;
        let drive = self.b * (u + filter.d);
        for _ in 0..elapsed {
            filter.x = self.a * filter.x + drive;
        }
        filter.t = t;
        filter.ticks_since_fix += elapsed;
        let prior = filter.x;
        // A new fix is a new seq, whether or not this tick saw it fresh.
        let new_fix = fix_valid && filter.fix_seq != Some(position.seq);
        if new_fix {
            filter.fix_seq = Some(position.seq);
            self.correct(&mut filter, &fix());
        }
        let corrected = initialising || new_fix;
        estimate[layout::POSITION].copy_from_slice(filter.x.fixed_rows::<3>(0).as_slice());
        estimate[layout::VELOCITY].copy_from_slice(filter.x.fixed_rows::<3>(3).as_slice());
        estimate[layout::DISTURBANCE].copy_from_slice(filter.d.as_slice());
        estimate[layout::PRIOR_POSITION].copy_from_slice(prior.fixed_rows::<3>(0).as_slice());
        estimate[layout::CORRECTED] = if corrected { 1.0 } else { 0.0 };
        estimate[layout::FIX_AGE] = t - position.sample_time;
        self.filter = Some(filter);
    }
}

#[cfg(test)]
#[path = "estimator_tests.rs"]
mod tests;
