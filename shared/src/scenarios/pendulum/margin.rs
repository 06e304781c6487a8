//! The pendulum loop's delay margin from its linearised model: how much extra command delay
//! (the command of loop k applied over tick k+d → k+d+1) the loop tolerates, to compare with a
//! measured sweep.
//!
//! Two answers:
//! - exact, for the sampled loop as the simulator runs it ([`spectral_radius_per_tick`]): the
//!   loop is linear and periodic over the sensors' periods, so it is stable exactly when the
//!   monodromy matrix (the product of the per-tick maps over one period) has spectral radius
//!   below 1;
//! - a continuous estimate ([`continuous_margin`]): φ_m/ω_c of the loop broken at the plant
//!   input, with the observer continuous and the sampling ignored.
//!
//! The linearisation is at the upright equilibrium with the encoder bias δ. There y = δ and
//! x̂₃ = δ, so the bias observer's a·sin(y − x̂₃) becomes a·(y − x̂₃) whatever δ is. δ then only
//! enters as a constant input (the loop is affine in δ): stability is the homogeneous part's,
//! so δ = 0 below and x̂₃ stays a state. Noise, quantisation and the current limit are left out.

use nalgebra::{Complex, DMatrix, DVector, Matrix3, Matrix4, RowVector3, SMatrix, Vector3};

use super::Pendulum;
use super::estimator::Kind;
use crate::config::launch::{LaunchConfig, SensorSpec};
use crate::model::integrate::rk4;
use crate::model::poly::wrap_to_turn;

/// The exact search gives up here: a second of delay at 1 kHz.
const MAX_DELAY_TICKS: u32 = 1000;
/// Larger sampled loops (a long sampling pattern, long sensor delays) are not analysed: the
/// search would take hours.
const MAX_PERIOD_TICKS: u64 = 10_000;
const MAX_SENSOR_MEMORY: usize = 1000;

/// How much extra command delay the loop tolerates, from theory.
///
/// With the defaults (1 kHz, the encoder every tick, the wheel speed every 10) the exact margin
/// is 31 ticks for both estimators. The continuous estimate φ_m/ω_c is 29.1 ticks with the bias
/// observer (ω_c = 45.2 rad/s, φ_m = 75.4°) and 29.0 with the no-bias one (46.7 rad/s, 77.5°).
/// The two ticks between them are the sampling's lags on the loop's paths, which the
/// continuous loop leaves out:
/// - the command's zero-order hold, half a tick: half a tick less margin;
/// - the estimator holds each encoder reading over the tick that ends at it, half a tick of
///   lead on θ: about a tick less;
/// - the wheel speed's 10-tick hold, 4.5 ticks of mean lag: about three ticks *more*. At ω_c
///   the term K₃φ̇ works against the rate term K₂θ̇ (it takes damping away), and lagging it
///   turns it away from that.
///
/// Put into the continuous loop as pure delays ([`Lags::of_sampling`]) they give
/// `lagged_ticks` = 30.9 and 31.0, whose ceiling is the exact margin, here and in every
/// variant the tests try (sensor delays, slower sensors).
#[derive(Debug, Clone, PartialEq)]
pub struct DelayMargin {
    /// The smallest extra command delay d (ticks) at which the linearised sampled loop is
    /// unstable: a command computed at loop k is applied over tick k+d → k+d+1.
    pub ticks: u32,
    /// Per-tick spectral radius of the sampled loop at d = `ticks` (≥ 1).
    pub radius_at_margin: f64,
    /// Per-tick spectral radius at d = `ticks` − 1 (< 1); NaN when the loop is unstable at d = 0.
    pub radius_before: f64,
    /// ω_c of the continuous loop gain at the crossover that sets the continuous margin.
    pub crossover_rad_s: f64,
    /// 180° + ∠L(jω_c), taken in [0°, 360°): the phase a delay must add there to reach −1.
    pub phase_margin_deg: f64,
    /// φ_m/ω_c, seconds.
    pub continuous_s: f64,
    /// φ_m/ω_c in ticks.
    pub continuous_ticks: f64,
    /// The same with the sampling's mean lags on the loop's paths ([`Lags::of_sampling`]).
    pub lagged_ticks: f64,
}

/// Both margins of the loop `p` (built from `config`).
///
/// None where theory has no answer for this launch file: the sampled loop is still stable with
/// [`MAX_DELAY_TICKS`] of delay, its Schur form does not converge, the continuous loop gain
/// never crosses 1, or the loop is too large to analyse (see [`MAX_PERIOD_TICKS`]).
pub fn delay_margin(p: &Pendulum, config: &LaunchConfig) -> Option<DelayMargin> {
    let base = SampledLoop::new(p, config, 0);
    if base.period() > MAX_PERIOD_TICKS || base.encoder.memory() + base.wheel.memory() > MAX_SENSOR_MEMORY {
        return None;
    }
    let mut radius_before = f64::NAN;
    let mut unstable = None;
    for d in 0..=MAX_DELAY_TICKS {
        let r = spectral_radius_per_tick(p, config, d)?;
        if r >= 1.0 {
            unstable = Some((d, r));
            break;
        }
        radius_before = r;
    }
    let (ticks, radius_at_margin) = unstable?;
    let c = continuous_margin(p, Lags::default())?;
    let lagged = continuous_margin(p, Lags::of_sampling(config))?;
    Some(DelayMargin {
        ticks,
        radius_at_margin,
        radius_before,
        crossover_rad_s: c.omega,
        phase_margin_deg: c.phase.to_degrees(),
        continuous_s: c.delay_s,
        continuous_ticks: c.delay_s / p.dt,
        lagged_ticks: lagged.delay_s / p.dt,
    })
}

/// Per-tick spectral radius of the linearised sampled loop with `d` ticks of extra command
/// delay: ρ(monodromy)^(1/P) over the period P (ticks) after which the sensors' sampling
/// pattern repeats. Below 1: stable. None if the Schur form does not converge.
pub fn spectral_radius_per_tick(p: &Pendulum, config: &LaunchConfig, d: u32) -> Option<f64> {
    let lp = SampledLoop::new(p, config, d as usize);
    Some(spectral_radius(lp.monodromy())?.powf(1.0 / lp.period() as f64))
}

fn spectral_radius(m: DMatrix<f64>) -> Option<f64> {
    let schur = nalgebra::linalg::Schur::try_new(m, f64::EPSILON, 1_000_000)?;
    Some(schur.complex_eigenvalues().iter().map(|z| z.norm()).fold(0.0, f64::max))
}

/// The continuous observer, linearised: dx̂/dt = M (x̂₁, x̂₂, x̂₃, y, I), with y the encoder
/// reading and I the applied current (the equations are in `estimator.rs`).
fn observer_matrix(p: &Pendulum) -> SMatrix<f64, 3, 5> {
    let (a, b) = (p.model.a(), p.model.b());
    #[rustfmt::skip]
    let rows = match p.estimator.kind {
        Kind::BiasObserver => {
            let l = p.bias_gains;
            [
                -l[0], 1.0, -l[0],     l[0],     0.0,
                -l[1], 0.0, -a - l[1], a + l[1], b,
                -l[2], 0.0, -l[2],     l[2],     0.0,
            ]
        }
        // No gravity term and no bias state.
        Kind::NoBias => {
            let l = p.no_bias_gains;
            [
                -l[0], 1.0, 0.0, l[0], 0.0,
                -l[1], 0.0, 0.0, l[1], b,
                0.0,   0.0, 0.0, 0.0,  0.0,
            ]
        }
    };
    SMatrix::from_row_slice(&rows)
}

/// One estimator update, x̂ₖ = F x̂ₖ₋₁ + g_y yₖ + g_u Iₖ₋₁, as [F | g_y | g_u]: RK4 over one
/// tick with the reading and the current held, as the code does it. RK4 on a linear system is
/// a linear map, so integrating the basis vectors with the crate's `rk4` gives it exactly.
fn observer_step(p: &Pendulum) -> SMatrix<f64, 3, 5> {
    let m = observer_matrix(p);
    // The held reading and current are states with zero derivative.
    let f = |z: &SMatrix<f64, 5, 1>| {
        let dx = m * z;
        SMatrix::<f64, 5, 1>::new(dx[0], dx[1], dx[2], 0.0, 0.0)
    };
    let mut step = SMatrix::<f64, 3, 5>::zeros();
    for j in 0..5 {
        let z = rk4(&f, &SMatrix::<f64, 5, 1>::ith(j, 1.0), p.dt, super::estimator::SUBSTEPS);
        step.set_column(j, &z.fixed_rows::<3>(0));
    }
    if p.estimator.kind == Kind::NoBias {
        // That estimator reports δ̂ = 0 rather than keeping it.
        step.row_mut(2).fill(0.0);
    }
    step
}

/// The linearised plant over one tick with the current held: x⁺ = Φ x + Γ I, from the
/// exponential of the augmented matrix [[A, B], [0, 0]]·dt.
fn plant_step(p: &Pendulum) -> (Matrix3<f64>, Vector3<f64>) {
    let (a, b) = p.model.linearised();
    let mut augmented = Matrix4::zeros();
    augmented.fixed_view_mut::<3, 3>(0, 0).copy_from(&a);
    augmented.fixed_view_mut::<3, 1>(0, 3).copy_from(&b);
    let e = (augmented * p.dt).exp();
    (e.fixed_view::<3, 3>(0, 0).into_owned(), e.fixed_view::<3, 1>(0, 3).into_owned())
}

/// A sensor as `crate::model::sensors` runs it: samples every `period` ticks from tick 0, delivers
/// `delay` ticks later, holds in between.
#[derive(Debug, Clone, Copy)]
struct Sampling {
    period: u64,
    delay: usize,
}

impl Sampling {
    fn of(config: &LaunchConfig, spec: &SensorSpec) -> Self {
        Self { period: config.period_ticks(spec), delay: spec.delay_ticks as usize }
    }

    /// How many past values of its sample-and-hold signal g the loop state keeps:
    /// gₖ₋₁ (to hold) up to gₖ₋D (delivered at tick k).
    fn memory(self) -> usize {
        self.delay.max(1)
    }
}

/// Where the plant state, the estimate and the applied current sit in the loop state; the
/// sensors' memories and the command delay line follow (see [`SampledLoop`]).
const X: usize = 0;
const XHAT: usize = 3;
const APPLIED: usize = 6;
const ENCODER: usize = 7;

/// The linearised loop over one tick, in lockstep order (`stages.rs`): the sensors read xₖ,
/// the estimator updates with their readings and the current applied over k−1 → k, the
/// controller computes cₖ, and the plant applies cₖ₋d over k → k+1. The state at the start of
/// tick k is
/// - xₖ, the plant state;
/// - x̂ₖ₋₁ = (θ̂, θ̂̇, δ̂), the estimator state;
/// - the current applied over k−1 → k (the estimator's `u_applied`);
/// - for the encoder and then the wheel-speed sensor: gₖ₋₁ … gₖ₋ₘ, where g is the sensor's
///   sample-and-hold signal before the transport delay, so its reading at tick k is gₖ₋D;
/// - cₖ₋₁ … cₖ₋d, the commands computed but not yet applied.
struct SampledLoop {
    phi: Matrix3<f64>,
    gamma: Vector3<f64>,
    observer: SMatrix<f64, 3, 5>,
    gains: RowVector3<f64>,
    encoder: Sampling,
    wheel: Sampling,
    delay: usize,
}

impl SampledLoop {
    fn new(p: &Pendulum, config: &LaunchConfig, delay: usize) -> Self {
        let spec = |signal| config.sensor_for(signal).expect("the pendulum's sensors are checked at load").2;
        let (phi, gamma) = plant_step(p);
        Self {
            phi,
            gamma,
            observer: observer_step(p),
            gains: RowVector3::from(p.controller.gains),
            encoder: Sampling::of(config, spec("theta")),
            wheel: Sampling::of(config, spec("wheel_speed")),
            delay,
        }
    }

    fn wheel_at(&self) -> usize {
        ENCODER + self.encoder.memory()
    }

    fn commands_at(&self) -> usize {
        self.wheel_at() + self.wheel.memory()
    }

    fn dim(&self) -> usize {
        self.commands_at() + self.delay
    }

    /// Ticks after which the sampling pattern repeats.
    fn period(&self) -> u64 {
        let (a, b) = (self.encoder.period, self.wheel.period);
        let gcd = |mut a: u64, mut b: u64| {
            while b != 0 {
                (a, b) = (b, a % b);
            }
            a
        };
        a / gcd(a, b) * b
    }

    /// Tick k: from the loop state at tick k to the one at tick k+1.
    fn step(&self, k: u64, s: &DVector<f64>) -> DVector<f64> {
        let mut next = DVector::zeros(self.dim());
        let x = s.fixed_rows::<3>(X).into_owned();
        let y = sense(k, self.encoder, ENCODER, x[0], s, &mut next);
        let w = sense(k, self.wheel, self.wheel_at(), x[2], s, &mut next);
        let obs = &self.observer;
        let xhat = obs.fixed_columns::<3>(0) * s.fixed_rows::<3>(XHAT) + obs.column(3) * y + obs.column(4) * s[APPLIED];
        let c = -(self.gains * Vector3::new(xhat[0], xhat[1], w))[0];
        let at = self.commands_at();
        let applied = if self.delay == 0 { c } else { s[at + self.delay - 1] };
        if self.delay > 0 {
            next[at] = c;
            for i in 1..self.delay {
                next[at + i] = s[at + i - 1];
            }
        }
        next.fixed_rows_mut::<3>(X).copy_from(&(self.phi * x + self.gamma * applied));
        next.fixed_rows_mut::<3>(XHAT).copy_from(&xhat);
        next[APPLIED] = applied;
        next
    }

    /// The matrix of [`Self::step`] (linear, so its columns are the images of the basis).
    fn tick_matrix(&self, k: u64) -> DMatrix<f64> {
        let n = self.dim();
        let columns: Vec<_> = (0..n).map(|j| self.step(k, &DVector::from_fn(n, |i, _| f64::from(i == j)))).collect();
        DMatrix::from_columns(&columns)
    }

    /// The map over one sampling period from tick 0, where every sensor samples.
    fn monodromy(&self) -> DMatrix<f64> {
        (0..self.period()).fold(DMatrix::identity(self.dim(), self.dim()), |m, k| self.tick_matrix(k) * m)
    }
}

/// One sensor at tick k: samples `truth` at its instants and holds otherwise, shifts that into
/// its memory (at `at`) in `next`, and returns its reading, the value D ticks old.
fn sense(k: u64, sensor: Sampling, at: usize, truth: f64, s: &DVector<f64>, next: &mut DVector<f64>) -> f64 {
    let g = if k.is_multiple_of(sensor.period) { truth } else { s[at] };
    next[at] = g;
    for i in 1..sensor.memory() {
        next[at + i] = s[at + i - 1];
    }
    if sensor.delay == 0 { g } else { s[at + sensor.delay - 1] }
}

/// Lags of the loop's paths, in seconds (negative: a lead), for the continuous estimate.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Lags {
    /// On the applied current (plant and estimator alike).
    pub command: f64,
    /// On the encoder reading the estimator uses.
    pub encoder: f64,
    /// On the wheel speed the controller uses.
    pub wheel: f64,
}

impl Lags {
    /// The sampled loop's, to first order: half a tick for the command's zero-order hold; for
    /// each sensor its reading's mean age, (P − 1)/2 + D ticks; less half a tick on the encoder,
    /// because the estimator holds each reading over the tick that ends at it.
    pub fn of_sampling(config: &LaunchConfig) -> Self {
        let dt = config.dt();
        let age = |signal| {
            let spec = config.sensor_for(signal).expect("the pendulum's sensors are checked at load").2;
            (config.period_ticks(spec) as f64 - 1.0) / 2.0 + f64::from(spec.delay_ticks)
        };
        Self { command: 0.5 * dt, encoder: (age("theta") - 0.5) * dt, wheel: age("wheel_speed") * dt }
    }
}

/// The continuous loop gain broken at the plant input: L(jω) = −c/I for a current I that
/// drives both the plant and the estimator (which is fed the applied current), with
/// c = −K (x̂₁, x̂₂, φ̇) and the given lags on the paths. A delay τ at the break closes the
/// loop as 1 + L(s)e^{−sτ} = 0.
pub fn loop_gain(p: &Pendulum, omega: f64, lags: Lags) -> Complex<f64> {
    let s = Complex::new(0.0, omega);
    let lag = |tau: f64| (-s * tau).exp();
    let resolvent = |m: Matrix3<f64>| Matrix3::<Complex<f64>>::identity() * s - m.map(Complex::from);
    let (a, b) = p.model.linearised();
    let x = resolvent(a).lu().solve(&b.map(Complex::from)).expect("jω is not a pole of the plant");
    let m = observer_matrix(p);
    let drive = m.column(3).map(Complex::from) * (x[0] * lag(lags.encoder)) + m.column(4).map(Complex::from);
    let xhat =
        resolvent(m.fixed_columns::<3>(0).into_owned()).lu().solve(&drive).expect("jω is not a pole of the estimator");
    let k = p.controller.gains;
    lag(lags.command) * (xhat[0] * k[0] + xhat[1] * k[1] + x[2] * lag(lags.wheel) * k[2])
}

/// One crossover of the continuous loop gain, |L(jω)| = 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossover {
    pub omega: f64,
    /// 180° + ∠L(jω) in [0, 2π), radians: the phase lag that puts L on −1.
    pub phase: f64,
    /// phase/ω: the delay that does it.
    pub delay_s: f64,
}

/// Every crossover of |L(jω)| = 1 between 10⁻³ and 10⁵ rad/s.
pub fn crossovers(p: &Pendulum, lags: Lags) -> Vec<Crossover> {
    let log_gain = |log_w: f64| loop_gain(p, log_w.exp(), lags).norm().ln();
    let (from, to, n) = (1e-3f64.ln(), 1e5f64.ln(), 1600);
    let grid: Vec<f64> = (0..=n).map(|i| from + (to - from) * f64::from(i) / f64::from(n)).collect();
    grid.windows(2)
        .filter(|w| log_gain(w[0]).signum() != log_gain(w[1]).signum())
        .map(|w| {
            // Bisection in log ω, keeping the sign change inside [lo, hi].
            let (mut lo, mut hi) = (w[0], w[1]);
            let below_at_lo = log_gain(lo) < 0.0;
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if (log_gain(mid) < 0.0) == below_at_lo {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let omega = (0.5 * (lo + hi)).exp();
            let phase = wrap_to_turn(loop_gain(p, omega, lags).arg() + std::f64::consts::PI);
            Crossover { omega, phase, delay_s: phase / omega }
        })
        .collect()
}

/// The continuous delay margin: the crossover with the smallest phase/ω, the first that a
/// growing delay turns onto −1. None if |L| never crosses 1.
pub fn continuous_margin(p: &Pendulum, lags: Lags) -> Option<Crossover> {
    crossovers(p, lags).into_iter().min_by(|a, b| a.delay_s.total_cmp(&b.delay_s))
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;

    use super::*;
    use crate::config::launch::Override;
    use crate::contract::msg::SensorReading;
    use crate::model::scenario::ScenarioParts;
    use crate::model::sensors::SensorEmulator;
    use crate::scenarios::resolve;

    fn pendulum(sets: &[&str]) -> (LaunchConfig, Pendulum) {
        let overrides: Vec<_> = ["mode=lockstep"].iter().chain(sets).map(|s| Override::parse(s).unwrap()).collect();
        let (config, _) = resolve("pendulum", &overrides).unwrap();
        let p = Pendulum::from_config(&config).unwrap();
        (config, p)
    }

    const KINDS: [&str; 2] = ["estimator.kind=bias-observer", "estimator.kind=no-bias"];

    #[test]
    fn loops_too_large_to_analyse_have_no_margin_instead_of_a_panic_or_a_hang() {
        let (config, p) = pendulum(&["duration_s=20", "sensors.wheel_speed.period_s=10.007"]);
        assert!(delay_margin(&p, &config).is_none());
        let (config, p) = pendulum(&["sensors.encoder.delay_ticks=5000"]);
        assert!(delay_margin(&p, &config).is_none());
    }

    /// One tick of a simulation of the loop's own components.
    struct Recorded {
        x: Vector3<f64>,
        xhat: Vector3<f64>,
        command: f64,
        applied: f64,
    }

    /// Runs the plant, sensor emulator, estimator and controller in lockstep order, with the
    /// command of loop k applied over tick k+d → k+d+1 (zero before that).
    fn simulate(p: &Pendulum, config: &LaunchConfig, d: usize, ticks: u64) -> Vec<Recorded> {
        let (mut plant, mut estimator, mut controller) = (p.plant(), p.estimator(), p.controller());
        let mut sensors = SensorEmulator::new(config, crate::scenarios::pendulum::VECTORS.signals);
        let mut readings = vec![SensorReading::default(); config.sensors.len()];
        let (mut estimate, mut command) = ([0.0; 4], [0.0]);
        let mut pending: VecDeque<f64> = std::iter::repeat_n(0.0, d).collect();
        let mut applied = 0.0;
        let mut out = Vec::new();
        for k in 0..ticks {
            let t = k as f64 * p.dt;
            let x = Vector3::from_column_slice(plant.state());
            sensors.tick(k, t, x.as_slice(), &[applied], &mut readings);
            estimator.update(t, &readings, &[applied], &mut estimate);
            controller.update(t, &estimate, &mut command);
            pending.push_back(command[0]);
            applied = pending.pop_front().unwrap();
            plant.step(0.0, &[applied], p.dt).unwrap();
            out.push(Recorded {
                x,
                xhat: Vector3::new(estimate[0], estimate[1], estimate[3]),
                command: command[0],
                applied,
            });
        }
        out
    }

    /// The linear loop's state at the start of tick k0 ≥ 1, read off a simulation.
    fn state_at(lp: &SampledLoop, sim: &[Recorded], k0: usize) -> DVector<f64> {
        let mut s = DVector::zeros(lp.dim());
        s.fixed_rows_mut::<3>(X).copy_from(&sim[k0].x);
        s.fixed_rows_mut::<3>(XHAT).copy_from(&sim[k0 - 1].xhat);
        s[APPLIED] = sim[k0 - 1].applied;
        for (sensor, at, component) in [(lp.encoder, ENCODER, 0), (lp.wheel, lp.wheel_at(), 2)] {
            let period = sensor.period as usize;
            for i in 0..sensor.memory() {
                // gⱼ is the truth at the last sample instant at or before j.
                if let Some(j) = (k0 - 1).checked_sub(i) {
                    s[at + i] = sim[j / period * period].x[component];
                }
            }
        }
        for i in 0..lp.delay {
            if let Some(j) = (k0 - 1).checked_sub(i) {
                s[lp.commands_at() + i] = sim[j].command;
            }
        }
        s
    }

    /// Runs the linear map from a simulation's state against the simulation (the nonlinear
    /// plant with RK4, the estimator's code, the sensor emulator) at an amplitude small enough
    /// for the two to agree to rounding; returns the largest difference relative to the
    /// largest value.
    fn linear_loop_error(sets: &[&str], d: usize) -> f64 {
        let small = ["plant.initial.theta=1e-6", "sensors.encoder.bias=0.0", "sensors.encoder.quantum=0.0"];
        let all: Vec<&str> = small.iter().chain(&["sensors.wheel_speed.noise_std=0.0"]).chain(sets).copied().collect();
        let (config, p) = pendulum(&all);
        let lp = SampledLoop::new(&p, &config, d);
        let sim = simulate(&p, &config, d, 400);
        let k0 = lp.encoder.delay.max(lp.wheel.delay) + 1;
        let mut s = state_at(&lp, &sim, k0);
        let mut worst: f64 = 0.0;
        for k in k0..sim.len() - 1 {
            s = lp.step(k as u64, &s);
            worst = worst.max((s.fixed_rows::<3>(X) - sim[k + 1].x).amax());
            worst = worst.max((s.fixed_rows::<3>(XHAT) - sim[k].xhat).amax());
        }
        worst / sim.iter().map(|r| r.x.amax().max(r.xhat.amax())).fold(0.0, f64::max)
    }

    #[test]
    fn linear_loop_matches_the_simulated_components() {
        let delays =
            ["sensors.encoder.period_s=0.002", "sensors.encoder.delay_ticks=2", "sensors.wheel_speed.delay_ticks=3"];
        for kind in KINDS {
            for (sets, d) in [(vec![kind], 0), (vec![kind], 3), ([kind].iter().chain(&delays).copied().collect(), 4)] {
                let error = linear_loop_error(&sets, d);
                println!("{sets:?}, d = {d}: {error:e}");
                // Rounding only (about 1e-13); a different RK4 step count gives 1e-10 to 1e-9.
                assert!(error < 1e-11, "{sets:?}, d = {d}: relative error {error:e}");
            }
        }
    }

    /// Sorted by real part, then imaginary part.
    fn sorted(mut v: Vec<Complex<f64>>) -> Vec<Complex<f64>> {
        v.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        v
    }

    #[test]
    fn with_the_controller_open_the_poles_are_the_plants_and_the_observers() {
        // With K = 0 the plant runs open and drives the estimator, which does not act back: over
        // one period P the monodromy's eigenvalues are exp(λ P dt) for the plant's poles and the
        // observer's (zeros for the memories). Checks the discretisations, exactly.
        for kind in KINDS {
            let (config, p) = pendulum(&[kind, "controller.gains=[0.0, 0.0, 0.0]"]);
            let lp = SampledLoop::new(&p, &config, 2);
            let span = lp.period() as f64 * p.dt;
            let observer: Vec<f64> = match p.estimator.kind {
                Kind::BiasObserver => p.estimator.bias_observer.poles.into(),
                Kind::NoBias => p.estimator.no_bias.poles.into(),
            };
            let (a, _) = p.model.linearised();
            let plant = a.complex_eigenvalues();
            let continuous = plant.iter().copied().chain(observer.iter().map(|&l| Complex::from(l)));
            let mut expected: Vec<_> = continuous.map(|l| (l * span).exp()).collect();
            expected.resize(lp.dim(), Complex::from(0.0));
            let (got, want) =
                (sorted(lp.monodromy().complex_eigenvalues().iter().copied().collect()), sorted(expected));
            for (g, w) in got.iter().zip(&want) {
                // The no-bias observer's double pole splits by about √ε.
                assert!((g - w).norm() < 1e-7, "{kind}: {got:?} vs {want:?}");
            }
        }
    }

    /// The continuous loop, plant and observer, closed with the state feedback.
    fn continuous_closed_loop(p: &Pendulum) -> DMatrix<f64> {
        let (a, b) = p.model.linearised();
        let m = observer_matrix(p);
        let mut open = DMatrix::zeros(6, 6);
        open.view_mut((0, 0), (3, 3)).copy_from(&a);
        open.view_mut((3, 0), (3, 1)).copy_from(&m.column(3));
        open.view_mut((3, 3), (3, 3)).copy_from(&m.fixed_columns::<3>(0));
        let input = DVector::from_iterator(6, b.iter().chain(m.column(4).iter()).copied());
        let k = p.controller.gains;
        let feedback = DVector::from_vec(vec![0.0, 0.0, k[2], k[0], k[1], 0.0]).transpose();
        open - input * feedback
    }

    #[test]
    fn loop_poles_approach_the_continuous_ones_as_the_rate_rises() {
        // With every sensor every tick. Slowly for the bias observer: the estimator holds each
        // reading over the tick that ends at it, half a tick of lead on θ, and through its
        // large opposing gains (l₁ ≈ 214, l₃ ≈ −154 s⁻¹) that moves the close-together poles
        // (−16, −20, −24 and the state feedback's −32.1) far more than O(λ dt), and less than
        // linearly in dt. (With the reading centred on the tick the error is 0.13 at 1 kHz.)
        for kind in KINDS {
            let mut previous = f64::INFINITY;
            for rate in [1e3, 1e4, 1e5] {
                let period = format!("{}", 1.0 / rate);
                let sets = [
                    kind,
                    &format!("rate_hz={rate}"),
                    &format!("sensors.encoder.period_s={period}"),
                    &format!("sensors.wheel_speed.period_s={period}"),
                ];
                let (config, p) = pendulum(&sets);
                let lp = SampledLoop::new(&p, &config, 0);
                assert_eq!(lp.period(), 1);
                let sampled: Vec<_> = lp
                    .monodromy()
                    .complex_eigenvalues()
                    .iter()
                    .filter(|z| z.norm() > 1e-3)
                    .map(|z| z.ln() / p.dt)
                    .collect();
                let continuous: Vec<_> = continuous_closed_loop(&p)
                    .complex_eigenvalues()
                    .iter()
                    .copied()
                    .filter(|l| l.norm() > 1e-6)
                    .collect();
                assert!(continuous.iter().all(|l| l.re < 0.0));
                assert!(spectral_radius_per_tick(&p, &config, 0).unwrap() < 1.0);
                let error = continuous
                    .iter()
                    .map(|l| sampled.iter().map(|s| (s - l).norm() / l.norm()).fold(f64::INFINITY, f64::min))
                    .fold(0.0, f64::max);
                println!(
                    "{kind} at {rate} Hz: relative pole error {error:.3}\n  sampled {:.2?}\n  continuous {:.2?}",
                    sorted(sampled),
                    sorted(continuous)
                );
                assert!(error < previous, "{kind} at {rate} Hz: {error} after {previous}");
                previous = error;
            }
            assert!(previous < 0.15, "{kind}: {previous}");
        }
    }

    #[test]
    fn bias_observer_loop_gain_is_the_state_feedback_loop_gain() {
        // Fed the applied current, the bias observer's error does not depend on it, so broken
        // at the plant input the loop is K (sI − A)⁻¹ B, as without an observer.
        let (_, p) = pendulum(&[]);
        let (a, b) = p.model.linearised();
        let k = RowVector3::from(p.controller.gains).map(Complex::from);
        for omega in [0.1, 3.0, 40.0, 500.0] {
            let s = Complex::new(0.0, omega);
            let x = (Matrix3::<Complex<f64>>::identity() * s - a.map(Complex::from)).lu().solve(&b.map(Complex::from));
            let want = (k * x.unwrap())[0];
            let got = loop_gain(&p, omega, Lags::default());
            assert!((got - want).norm() < 1e-9 * want.norm(), "ω = {omega}: {got} vs {want}");
        }
    }

    /// The margins for these settings, checked: stable without delay, unstable at the margin,
    /// the lagged continuous estimate just below the exact margin.
    fn checked_margin(sets: &[&str]) -> DelayMargin {
        let (config, p) = pendulum(sets);
        let m = delay_margin(&p, &config).unwrap();
        let crossovers = crossovers(&p, Lags::default());
        println!("{sets:?}: {m:?}, crossovers {crossovers:?}");
        assert!(spectral_radius_per_tick(&p, &config, 0).unwrap() < 1.0, "{m:?}");
        assert!(m.ticks > 0 && m.radius_before < 1.0 && 1.0 <= m.radius_at_margin, "{m:?}");
        assert_eq!(m.lagged_ticks.ceil(), f64::from(m.ticks), "{m:?}");
        m
    }

    #[test]
    fn margins_with_the_defaults() {
        for kind in KINDS {
            let m = checked_margin(&[kind]);
            assert_eq!(m.ticks, 31, "{m:?}");
            assert!((m.continuous_ticks - f64::from(m.ticks)).abs() < 2.5, "{m:?}");
        }
    }

    #[test]
    fn sensor_lags_move_the_margin_as_the_lagged_estimate_predicts() {
        let variants = [
            "sensors.wheel_speed.period_s=0.001",
            "sensors.wheel_speed.period_s=0.02",
            "sensors.wheel_speed.delay_ticks=5",
            "sensors.encoder.period_s=0.004",
            "sensors.encoder.delay_ticks=3",
        ];
        for kind in KINDS {
            for variant in variants {
                checked_margin(&[kind, variant]);
            }
        }
    }
}
