//! The LKFUI's tests: a point mass under the paper's noise, the exact ensemble of its error,
//! and the fix bookkeeping.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::*;
use crate::scenarios::tiltrotor::params::Params;

const TICK: f64 = 0.01;
const FIX_TICKS: u64 = 10;
const INPUTS: Inputs = Inputs { position: 0, velocity: 1, attitude: 2, force: 3 };

/// Where [`run`]'s point mass starts, at rest: the filter's known start.
const START: [f64; 3] = [0.3, -0.2, 1.0];

fn filter(section: &EstimatorSection) -> Lkfui {
    let p = Params::table1();
    Lkfui::new(section, p.total_mass(), p.g, TICK, FIX_TICKS as u32, INPUTS, START)
}

/// The filter started from the first fix instead of the known start.
fn from_first_fix() -> EstimatorSection {
    EstimatorSection { initial: Initial::FirstFix, ..EstimatorSection::paper() }
}

fn reading(values: &[f64], sample_time: f64, seq: u64, fresh: bool) -> SensorReading {
    let mut r = SensorReading { sample_time, seq, fresh: u32::from(fresh), valid: 1, ..Default::default() };
    r.value[..values.len()].copy_from_slice(values);
    r
}

/// The known thrusters' force, N: the weight plus a smooth manoeuvre.
fn thrust(t: f64, mass: f64, g: f64) -> Vector3<f64> {
    Vector3::new(2.0 * (0.5 * t).sin(), 1.5 * (0.3 * t).cos(), mass * g + (0.7 * t).sin())
}

/// What one run gives: per tick the truth, the estimate and the fix's seq.
struct Trace {
    truth: Vec<Vector6>,
    estimates: Vec<[f64; layout::LEN]>,
    seqs: Vec<u64>,
}

/// A point mass of the nominal mass under the known thrust, the weight and a constant
/// unknown force, integrated exactly with the force held over each 1 ms. The sensors follow
/// the paper: a fix every 10 ticks (σ 0.05 m, 0.04 m/s), held between; the force reading
/// every tick with σ 1/3 N. `sigma` scales all noise (0: noise-free).
fn run(section: &EstimatorSection, seconds: f64, unknown: Vector3<f64>, sigma: f64, seed: u64) -> Trace {
    let params = Params::table1();
    let (m, g) = (params.total_mass(), params.g);
    let mut lkfui = filter(section);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut noise = |scale: f64| -> f64 {
        let n: f64 = StandardNormal.sample(&mut rng);
        sigma * scale * n
    };
    let (mut p, mut v) = (Vector3::from(START), Vector3::zeros());
    let mut readings = [SensorReading::default(); 4];
    let mut trace = Trace { truth: vec![], estimates: vec![], seqs: vec![] };
    let ticks = (seconds / TICK).round() as u64;
    for k in 0..=ticks {
        let t = k as f64 * TICK;
        // The force reading is the mean thrust applied over the tick just ended.
        let mut applied = thrust(t, m, g);
        if k > 0 {
            let dt = 0.001;
            applied = Vector3::zeros();
            for s in 0..10 {
                let ts = t - TICK + f64::from(s) * dt;
                applied += thrust(ts, m, g) / 10.0;
                let a = (thrust(ts, m, g) - Vector3::new(0.0, 0.0, m * g) + unknown) / m;
                p += v * dt + a * (0.5 * dt * dt);
                v += a * dt;
            }
        }
        if k % FIX_TICKS == 0 {
            let seq = k / FIX_TICKS;
            let pos: Vec<f64> = (0..3).map(|i| p[i] + noise(0.05)).collect();
            let vel: Vec<f64> = (0..3).map(|i| v[i] + noise(0.04)).collect();
            readings[0] = reading(&pos, t, seq, true);
            readings[1] = reading(&vel, t, seq, true);
        } else {
            readings[0].fresh = 0;
            readings[1].fresh = 0;
        }
        readings[2] = reading(&[0.01 * t; 14], t, k, true);
        let force: Vec<f64> = (0..3).map(|i| applied[i] + noise(1.0 / 3.0)).collect();
        readings[3] = reading(&force, t, k, true);
        let mut estimate = [0.0; layout::LEN];
        lkfui.update(t, &readings, &[], &mut estimate);
        trace.truth.push(Vector6::new(p[0], p[1], p[2], v[0], v[1], v[2]));
        trace.estimates.push(estimate);
        trace.seqs.push(readings[0].seq);
    }
    trace
}

/// The nearest-rank percentile.
fn percentile(values: &[f64], fraction: f64) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = ((fraction * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    sorted[rank - 1]
}

fn mean_std(values: &[f64]) -> (f64, f64) {
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / values.len() as f64;
    (mean, var.sqrt())
}

/// The d̂ assimilated at each correction (after the first second) on axis `axis`.
fn d_hat(trace: &Trace, axis: usize) -> Vec<f64> {
    trace
        .estimates
        .iter()
        .skip(100)
        .filter(|e| e[layout::CORRECTED] == 1.0)
        .map(|e| e[layout::DISTURBANCE.start + axis])
        .collect()
}

/// The exact ensemble mean square of [`run`]'s a-priori x error at each tick k = 0..=`ticks`,
/// from the known start under a constant unknown force `unknown_x` on x: the mean and
/// covariance of z = [x̂ − x, v̂ − v, d̂ − d] on x propagated tick by tick with the filter's own
/// gains (they do not depend on the data; the axes are alike and uncoupled). `sigma` are the
/// true noise σ of the force reading, the position fix and the velocity fix.
fn exact_mean_square(section: &EstimatorSection, ticks: u64, unknown_x: f64, sigma: [f64; 3]) -> Vec<f64> {
    use nalgebra::{Matrix2, Matrix3, SMatrix};
    let lkfui = filter(section);
    let (bp, bv) = (TICK * TICK / (2.0 * lkfui.mass), TICK / lkfui.mass);
    let a = Matrix3::new(1.0, TICK, bp, 0.0, 1.0, bv, 0.0, 0.0, 1.0);
    let b = Vector3::new(bp, bv, 0.0);
    let force_noise = b * b.transpose() * sigma[0].powi(2);
    let fix_noise = Matrix2::new(sigma[1].powi(2), 0.0, 0.0, sigma[2].powi(2));
    let left_inverse = [lkfui.nominal.g_bar_left_inverse[(0, 0)], lkfui.nominal.g_bar_left_inverse[(0, 3)]];
    let (mut p, mut cov, mut mean) = (lkfui.p0, Matrix3::zeros(), Vector3::new(0.0, 0.0, -unknown_x));
    let mut out = vec![0.0];
    for k in 1..=ticks {
        cov = a * cov * a.transpose() + force_noise;
        mean = a * mean;
        out.push(cov[(0, 0)] + mean[0].powi(2));
        if k % FIX_TICKS == 0 {
            let (l6, p_post) = lkfui.gain(&p, &lkfui.nominal);
            p = p_post;
            let l = Matrix2::new(l6[(0, 0)], l6[(0, 3)], l6[(3, 0)], l6[(3, 3)]);
            let gl = [0, 1].map(|j| left_inverse[0] * l[(0, j)] + left_inverse[1] * l[(1, j)]);
            // x̂ − x ← (I − L)(x̂ − x) + L n; d̂ − d ← d̂ − d + Ḡ⁺ L (n − (x̂ − x)).
            let f =
                Matrix3::new(1.0 - l[(0, 0)], -l[(0, 1)], 0.0, -l[(1, 0)], 1.0 - l[(1, 1)], 0.0, -gl[0], -gl[1], 1.0);
            let g = SMatrix::<f64, 3, 2>::new(l[(0, 0)], l[(0, 1)], l[(1, 0)], l[(1, 1)], gl[0], gl[1]);
            cov = f * cov * f.transpose() + g * fix_noise * g.transpose();
            mean = f * mean;
        }
    }
    out
}

fn rms(mean_squares: &[f64]) -> f64 {
    (mean_squares.iter().sum::<f64>() / mean_squares.len() as f64).sqrt()
}

/// Issue 34's point-mass case: the filter alone on a point mass with the paper's noise, over
/// the paper's Fig. 4 window (10 s from a known start, the error starting at 0). The paper's
/// ±2.54 cm (95 %) and ±3.81 cm (99.8 %) are 2σ and 3σ of one σ = 1.27 cm.
/// - The exact ensemble σ (rms) of the a-priori x error is 1.375 cm, 8 % above the paper's,
///   the same to 0.1 % for q_scale 1 and 1/9 (Q = B_Ts B_Tsᵀ lies almost along Ḡ, which the
///   constraint L Ḡ = Ḡ gives wholly to the measurement). In steady state it is 1.44 cm.
/// - 64 seeded windows pooled match it (sampling: about 3 %): p95 2.73 cm, p99.8 4.38 cm
///   expected. One window alone spreads: its sample σ lies in 0.83–1.66 cm (5–95 %), so the
///   paper's one realisation fits.
/// - σ(d̂_z) is √2·m·σ_v/T_s = 1.00 N (d̂ is the change of the velocity fix's error over one
///   interval, in force), 9 % above the paper's 0.92 N.
#[test]
fn the_a_priori_error_and_disturbance_spread_match_the_exact_ensemble_and_the_paper() {
    let ticks = 1000;
    let noise = [1.0 / 3.0, 0.05, 0.04];
    let exact = rms(&exact_mean_square(&EstimatorSection::paper(), ticks, 1.0, noise));
    let exact_q9 = rms(&exact_mean_square(
        &EstimatorSection { q_scale: 1.0 / 9.0, ..EstimatorSection::paper() },
        ticks,
        1.0,
        noise,
    ));
    let steady = exact_mean_square(&EstimatorSection::paper(), 100 * ticks, 1.0, noise);
    let steady = rms(&steady[99 * ticks as usize..]);
    eprintln!(
        "exact σ: {:.4} cm (q_scale 1/9: {:.4}), steady state {:.4} cm",
        exact * 100.0,
        exact_q9 * 100.0,
        steady * 100.0
    );
    assert!((1.04..1.13).contains(&(exact / 0.0127)), "exact σ {exact} against the paper's 0.0127");
    assert!((exact_q9 / exact - 1.0).abs() < 0.001);
    assert!((1.40..1.48).contains(&(steady * 100.0)), "steady σ {steady}");

    let (mut errors, mut d_z) = (vec![], vec![]);
    for seed in 1..=64 {
        let trace = run(&EstimatorSection::paper(), 10.0, Vector3::new(1.0, -0.5, 2.0), 1.0, seed);
        let x_prior = trace.estimates.iter().map(|e| e[layout::PRIOR_POSITION.start]);
        errors.extend(trace.truth.iter().zip(x_prior).map(|(x, prior)| prior - x[0]));
        let (mean, _) = mean_std(&d_hat(&trace, 2));
        d_z.extend(d_hat(&trace, 2).iter().map(|d| d - mean));
    }
    let sampled = rms(&errors.iter().map(|e| e * e).collect::<Vec<_>>());
    let magnitudes: Vec<f64> = errors.iter().map(|e| e.abs()).collect();
    let (p95, p998) = (percentile(&magnitudes, 0.95), percentile(&magnitudes, 0.998));
    let (_, d_std) = mean_std(&d_z);
    eprintln!(
        "64 windows: σ {:.3} cm, p95 {:.2} cm, p99.8 {:.2} cm, σ(d̂_z) {d_std:.3} N",
        sampled * 100.0,
        p95 * 100.0,
        p998 * 100.0
    );
    assert!((sampled / exact - 1.0).abs() < 0.08, "sampled σ {sampled} against the exact {exact}");
    assert!((1.0..1.18).contains(&(p95 / 0.0254)), "p95 {p95} against the paper's 0.0254");
    assert!((1.0..1.25).contains(&(p998 / 0.0381)), "p99.8 {p998} against the paper's 0.0381");
    let analytic = 2f64.sqrt() * Params::table1().total_mass() * 0.04 / 0.1;
    assert!((d_std / analytic - 1.0).abs() < 0.05, "σ(d̂_z) {d_std} against {analytic}");
    assert!((1.0..1.15).contains(&(d_std / 0.92)), "σ(d̂_z) {d_std} against the paper's 0.92");
}

#[test]
fn the_filter_starts_at_the_launch_start_and_takes_the_next_fix_first() {
    let mut lkfui = filter(&EstimatorSection::paper());
    for k in [0, 1, 9, 10] {
        let fix = k / FIX_TICKS;
        let readings = readings_at(k, Some((fix, fix * FIX_TICKS, k % FIX_TICKS == 0)));
        let mut e = [0.0; layout::LEN];
        lkfui.update(k as f64 * TICK, &readings, &[], &mut e);
        if k == 0 {
            // The fix held at t = 0 is not assimilated: x̂₀|₀ is the start, at rest.
            assert_eq!(&e[layout::POSITION], &START);
            assert_eq!(&e[layout::PRIOR_POSITION], &START);
            assert_eq!(&e[layout::VELOCITY], &[0.0; 3]);
        }
        assert_eq!(e[layout::CORRECTED], if k == 0 || k == 10 { 1.0 } else { 0.0 }, "tick {k}");
    }
    // Started from the first fix instead, x̂₀|₀ is that fix.
    let mut e = [0.0; layout::LEN];
    let readings = readings_at(0, Some((0, 0, true)));
    filter(&from_first_fix()).update(0.0, &readings, &[], &mut e);
    assert_eq!(&e[layout::POSITION], &readings[0].value[..3]);
}

#[test]
fn a_constant_unknown_force_is_recovered_exactly_without_noise_and_without_alternation() {
    let d = Vector3::new(1.0, -0.5, 2.0);
    let trace = run(&EstimatorSection::paper(), 10.0, d, 0.0, 0);
    let corrections: Vec<_> = trace.estimates.iter().filter(|e| e[layout::CORRECTED] == 1.0).collect();
    assert_eq!(corrections.len(), 101);
    // The first is the initialisation (d̂ = 0); from the second on d̂ = d, every time.
    for e in &corrections[1..] {
        for i in 0..3 {
            assert!((e[layout::DISTURBANCE.start + i] - d[i]).abs() < 1e-4, "{:?}", &e[layout::DISTURBANCE]);
        }
    }
    // And the state is the truth at every tick after the first interval, to the model error
    // of a force that varies within a tick.
    for (x, e) in trace.truth.iter().zip(&trace.estimates).skip(11) {
        for i in 0..3 {
            assert!((e[layout::PRIOR_POSITION.start + i] - x[i]).abs() < 2e-5);
            assert!((e[layout::VELOCITY.start + i] - x[i + 3]).abs() < 2e-4);
        }
    }
}

#[test]
fn the_mean_of_d_hat_recovers_a_constant_unknown_force_under_the_papers_noise() {
    let d = [1.0, -0.5, 2.0];
    let trace = run(&EstimatorSection::paper(), 60.0, Vector3::from(d), 1.0, 11);
    for (axis, truth) in d.iter().enumerate() {
        let (mean, _) = mean_std(&d_hat(&trace, axis));
        eprintln!("axis {axis}: mean d̂ {mean:.4} N against {truth}");
        // Each d̂ is a difference of two intervals' velocity errors, so the mean telescopes:
        // its error is about 1 N / N_fixes plus the force reading's noise averaged.
        assert!((mean - truth).abs() < 0.02, "axis {axis}: {mean}");
    }
}

#[test]
fn the_lifted_model_is_the_sum_over_the_ticks_and_matches_the_notes_numbers() {
    let m = Params::table1().total_mass();
    let (a, b) = (transition(TICK), force_map(TICK, m));
    let (mut a_j, mut q, mut g_bar) = (Matrix6::identity(), Matrix6::zeros(), Matrix6x3::zeros());
    for _ in 0..FIX_TICKS {
        q += (a_j * b) * (a_j * b).transpose();
        g_bar += a_j * b;
        a_j *= a;
    }
    let lifted = Lifted::new(TICK, m, FIX_TICKS as u32, 1.0);
    assert!((lifted.q - q).amax() < 1e-15);
    assert!((lifted.g_bar - g_bar).amax() < 1e-15);
    assert!((lifted.a - a_j).amax() < 1e-15);
    // Q_pp, Q_pv, Q_vv and Ḡ at the nominal mass.
    for (value, note) in [(q[(0, 0)], 1.06710e-6), (q[(0, 3)], 1.60466e-5), (q[(3, 3)], 3.20931e-4)] {
        assert!((value / note - 1.0).abs() < 1e-5, "{value} against {note}");
    }
    assert!((g_bar[(0, 0)] / 2.83254e-3 - 1.0).abs() < 1e-5 && (g_bar[(3, 0)] / 5.66508e-2 - 1.0).abs() < 1e-5);
    assert!((lifted.g_bar_left_inverse * g_bar - nalgebra::Matrix3::identity()).amax() < 1e-9);
}

/// A hand-made sequence of readings at tick k: the fix's seq and whether the tick saw it
/// fresh, the fix's value a deterministic wiggle so that a correction moves the state.
fn readings_at(k: u64, seq: Option<(u64, u64, bool)>) -> [SensorReading; 4] {
    let m = Params::table1().total_mass();
    let t = k as f64 * TICK;
    let mut readings = [SensorReading::default(); 4];
    if let Some((seq, sampled_at, fresh)) = seq {
        let wiggle = (seq as f64 * 1.7).sin() * 0.05;
        let sample_time = sampled_at as f64 * TICK;
        readings[0] = reading(&[1.0 + wiggle, 2.0 - wiggle, 3.0], sample_time, seq, fresh);
        readings[1] = reading(&[wiggle, 0.1, -wiggle], sample_time, seq, fresh);
    }
    readings[2] = reading(&(0..14).map(|i| f64::from(i) + t).collect::<Vec<_>>(), t, k, true);
    readings[3] = reading(&[0.5, 0.0, m * 9.81 + 0.3], t, k, true);
    readings
}

#[test]
fn it_corrects_exactly_when_the_fixs_seq_advances_and_only_predicts_otherwise() {
    // The fix arrives at tick 5 (the first valid one), then every 10 ticks; the one sampled
    // at tick 33 is seen only at 34 (tick 33 was skipped: real time), held, not fresh; two
    // fixes come on consecutive ticks 45 and 46.
    let arrivals = [5, 15, 25, 33, 45, 46, 55];
    let corrections = [5, 15, 25, 34, 45, 46, 55];
    let mut lkfui = filter(&from_first_fix());
    for k in (0..60).filter(|&k| k != 33) {
        let seen = arrivals.iter().rposition(|&a| a <= k);
        let seq = seen.map(|i| (i as u64, arrivals[i], arrivals[i] == k));
        let readings = readings_at(k, seq);
        let mut e = [f64::NAN; layout::LEN];
        lkfui.update(k as f64 * TICK, &readings, &[], &mut e);
        assert_eq!(&e[layout::ANGLES.start..layout::ANGLE_RATES.end], &readings[2].value[..14]);
        let Some(i) = seen else {
            assert!(e[..layout::ANGLES.start].iter().all(|&v| v == 0.0), "before any fix: {e:?}");
            continue;
        };
        assert_eq!(e[layout::FIX_AGE], k as f64 * TICK - arrivals[i] as f64 * TICK);
        let corrected = corrections.contains(&k);
        assert_eq!(e[layout::CORRECTED], if corrected { 1.0 } else { 0.0 }, "tick {k}");
        let (posterior, prior) = (&e[layout::POSITION], &e[layout::PRIOR_POSITION]);
        if !corrected {
            assert_eq!(posterior, prior, "tick {k}");
        } else if k != 5 {
            assert!(posterior.iter().zip(prior).all(|(a, b)| a != b), "tick {k}");
        }
    }
}

#[test]
fn skipped_ticks_are_predicted_one_by_one() {
    let run = |skipped: &[u64]| {
        let mut lkfui = filter(&EstimatorSection::paper());
        let mut e = [0.0; layout::LEN];
        for k in (0..=20).filter(|k| !skipped.contains(k)) {
            let fix = k / FIX_TICKS * FIX_TICKS;
            lkfui.update(k as f64 * TICK, &readings_at(k, Some((fix / FIX_TICKS, fix, fix == k))), &[], &mut e);
        }
        (e, lkfui.filter.expect("initialised").p)
    };
    let (every, p_every) = run(&[]);
    let (skipping, p_skipping) = run(&[3, 4, 12, 19]);
    for (a, b) in every.iter().zip(&skipping) {
        assert!((a - b).abs() < 1e-12, "{every:?}\n{skipping:?}");
    }
    assert!((p_every - p_skipping).amax() < 1e-15);
}

/// Also what a restarted estimator does: a filter that starts after the first tick starts
/// from the fix, even with `initial = "start"`.
#[test]
fn the_first_fix_is_predicted_from_its_sample_time() {
    let m = Params::table1().total_mass();
    let mut lkfui = filter(&EstimatorSection::paper());
    let mut e = [0.0; layout::LEN];
    // Started at tick 7 while the fix sampled at tick 0 is held: seven ticks of T^F = (0.5, 0, 0.3) N.
    let readings = readings_at(7, Some((0, 0, false)));
    lkfui.update(7.0 * TICK, &readings, &[], &mut e);
    let h = 7.0 * TICK;
    for i in 0..3 {
        let (p, v, f) = (readings[0].value[i], readings[1].value[i], [0.5, 0.0, 0.3][i]);
        assert!((e[layout::POSITION.start + i] - (p + v * h + f / m * h * h / 2.0)).abs() < 1e-12);
        assert!((e[layout::VELOCITY.start + i] - (v + f / m * h)).abs() < 1e-12);
    }
    assert_eq!(e[layout::CORRECTED], 1.0);
    assert!((e[layout::FIX_AGE] - h).abs() < 1e-15);
}
