//! The quadcopter (paper 001) in lockstep mode: each case is a launch file in
//! `launch/quadcopter/`, checked against the paper's numbers or an analytic result. The cases run
//! in-process (byte-identical to the five processes, see tests/trajectory_hashes.rs); the
//! restarted estimator runs through the real processes.

use crate::common;

use common::{looplab, run, run_in_process};

const CASES: &str = "launch/quadcopter";

fn case(name: &str) -> String {
    format!("{CASES}/{name}.toml")
}

/// Case 1, section 8.1: with the nominal controller, δ = (0, 0, 0.1) and γ = 0 the vehicle moves
/// only along z, p₃(t) = 0.05 − 0.15e^{−2t} + 0.1e^{−3t} and v₃(t) = 0.3(e^{−2t} − e^{−3t}).
#[test]
fn analytic_altitude_response() {
    let r = run_in_process("quad-analytic", &[&case("1-analytic")]);
    let t = r.trajectory();
    let time = t.col("t_s");
    assert_eq!(time.len(), 10_000);
    // Each column parsed once, not once per row.
    let (p_z, v_z) = (t.col("p_z_m"), t.col("v_z_m_per_s"));
    let others: Vec<(&str, Vec<f64>)> = [
        "p_x_m",
        "p_y_m",
        "v_x_m_per_s",
        "v_y_m_per_s",
        "w_x_rad_per_s",
        "w_y_rad_per_s",
        "w_z_rad_per_s",
        "R_12",
        "R_13",
        "R_23",
    ]
    .into_iter()
    .map(|name| (name, t.col(name)))
    .collect();
    let (mut worst_p, mut worst_v) = (0.0f64, 0.0f64);
    for (k, &s) in time.iter().enumerate() {
        let p = 0.05 - 0.15 * (-2.0 * s).exp() + 0.1 * (-3.0 * s).exp();
        let v = 0.3 * ((-2.0 * s).exp() - (-3.0 * s).exp());
        worst_p = worst_p.max((p_z[k] - p).abs());
        worst_v = worst_v.max((v_z[k] - v).abs());
        for (other, values) in &others {
            assert_eq!(values[k], 0.0, "{other} at t = {s}");
        }
    }
    assert!(worst_p < 1e-4 && worst_v < 1e-4, "p₃ off by {worst_p} m, v₃ by {worst_v} m/s");
}

/// Case 2, section 7.1 not rich: ‖z₁‖ → δ₃/k₁ = 0.05 m; ξ₃ and ξ₄ are not excited and their
/// estimates never move, and the summary says they are unobservable.
#[test]
fn not_rich_hover_leaves_xi3_and_xi4_unidentified() {
    let r = run_in_process("quad-not-rich", &[&case("2-not-rich")]);
    let z1 = r.metric("z1_final_m");
    assert!((z1 - 0.05).abs() < 0.01 * 0.05, "‖z₁‖ settles at {z1} m, not 0.05");
    assert_eq!(r.metric("xi3_change_max_rel"), 0.0);
    assert_eq!(r.metric("xi4_change_max_rel"), 0.0);
    let notes = r.summary["notes"].to_string();
    for block in ["xi_3", "xi_4"] {
        assert!(notes.contains(&format!("{block} stayed at its initial estimate")), "{notes}");
    }
    assert!(notes.contains("unobservable"), "{notes}");
}

/// Case 3, section 7.1 rich: γ = 30 sin t excites everything; by 30 s every parameter estimate
/// is within 1% of the truth (and so are m̂, ĵ through the cascaded filters).
#[test]
fn rich_excitation_identifies_every_parameter() {
    let r = run_in_process("quad-rich", &[&case("3-rich")]);
    let error = r.metric("param_rel_error_max_final");
    assert!(error < 0.01, "largest relative error of ξ̂ at 30 s: {error}");
    let mass = r.metric("mass_estimate_final_kg");
    assert!((mass - 0.2).abs() < 0.01 * 0.2, "m̂ = {mass} kg");
    // The estimates did start away from the truth: ξ̂₄(0) = 2ξ₄.
    assert!(r.metric("xi4_change_max_rel") > 0.49);
}

/// Case 4, section 7.3: with the estimates in the loop, ‖z₁‖ ≤ 0.09 m from 5 s on (the paper:
/// "about 0.08 m after about 5 seconds").
#[test]
fn closed_loop_tracking_stays_within_the_papers_ball() {
    let r = run_in_process("quad-closed", &[&case("4-closed-loop")]);
    let worst = r.metric("z1_max_after_5s_m");
    assert!(worst <= 0.09, "‖z₁‖ reaches {worst} m after 5 s");
    assert!(r.metric("param_rel_error_max_final") < 0.01);
}

/// Case 5, section 7.2, Table 2: the mean steady-state SNR (60) for the seven (R, Q) pairs.
///
/// The SNR depends only on Q/R here (the covariance forgets P(0), and noise barely moves the
/// trajectory), so the three pairs with Q/R = 1 give the same value. The paper's own values for
/// two of them agree (9.27, 9.24·10³) but the third is 7.47·10³: it departs from the paper's
/// pattern, and ours is 22% above it. That pair is checked against its Q/R twins instead; the
/// other six are within 20% of the paper.
#[test]
fn stochastic_snr_matches_table_2() {
    const TABLE_2: [(f64, f64, f64); 7] = [
        (0.01, 0.1, 30.43e3),
        (0.1, 0.1, 7.47e3),
        (0.1, 1.0, 29.00e3),
        (1.0, 1.0, 9.27e3),
        (10.0, 1.0, 2.91e3),
        (10.0, 10.0, 9.24e3),
        (100.0, 10.0, 2.89e3),
    ];
    let ours: Vec<f64> = std::thread::scope(|scope| {
        let handles: Vec<_> = TABLE_2
            .iter()
            .map(|&(r_scale, q_scale, _)| {
                scope.spawn(move || {
                    let r = format!("estimator.r_scale={r_scale:?}");
                    let q = format!("estimator.q_scale={q_scale:?}");
                    run_in_process("quad-snr", &[&case("5-stochastic-snr"), "--set", &r, "--set", &q])
                        .metric("snr_mean")
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("run")).collect()
    });
    let mut failures = Vec::new();
    for (i, ((r_scale, q_scale, paper), snr)) in TABLE_2.iter().zip(&ours).enumerate() {
        let ratio = snr / paper;
        println!("R = {r_scale}R̄, Q = {q_scale}Q̄: SNR {snr:.0} against {paper:.0}, ratio {ratio:.3}");
        if i != 1 && (ratio - 1.0).abs() > 0.2 {
            failures.push(format!("({r_scale}, {q_scale}): {snr:.0} vs {paper:.0}"));
        }
    }
    assert!(failures.is_empty(), "SNR off by more than 20%: {failures:?}");
    for twin in [3, 5] {
        assert!((ours[1] / ours[twin] - 1.0).abs() < 0.01, "Q/R = 1 pairs differ: {ours:?}");
    }
}

/// Case 6, section 7.4: the lemniscate with b = (−0.3, 0.2, −0.1) N. The steady-state RMS of ‖z₁‖
/// is reported, and the disturbance estimate b̂ = ξ̂₂/ξ̂₁ converges to b.
#[test]
fn lemniscate_with_a_disturbance_finds_the_disturbance() {
    let r = run_in_process("quad-lemniscate", &[&case("6-lemniscate")]);
    let rms = r.metric("z1_rms_m");
    assert!(rms > 0.0 && rms < 0.08, "steady-state RMS ‖z₁‖ {rms} m");
    let b = [-0.3, 0.2, -0.1];
    let t = r.trajectory();
    let (time, xi1) = (t.col("t_s"), t.col("est.xi_1_per_kg"));
    let xi2 = ["est.xi_2x_m_per_s2", "est.xi_2y_m_per_s2", "est.xi_2z_m_per_s2"].map(|name| t.col(name));
    let error_at = |at: f64| {
        let k = time.iter().position(|s| *s >= at).expect("the run reaches the time");
        let error: f64 = xi2.iter().zip(b).map(|(xi2, b)| (xi2[k] / xi1[k] - b).powi(2)).sum();
        error.sqrt()
    };
    let errors = [error_at(10.0), error_at(20.0), error_at(29.99)];
    assert!(errors[0] > errors[1] && errors[1] > errors[2], "‖b̂ − b‖ at 10, 20, 30 s: {errors:?} N");
    assert!(errors[2] < 0.02, "‖b̂ − b‖ = {} N at 30 s (‖b‖ = 0.37 N)", errors[2]);
    assert!((r.metric("disturbance_error_n") - errors[2]).abs() < 1e-3);
}

/// Case 7, section 9.2 in the lab profile (pose at 120 Hz, 45 ms command link, rate loop): the
/// mass estimate rises by 0.045 ± 0.01 kg after the mass is added and settles; the position
/// error stays bounded.
#[test]
fn hover_mass_step_in_the_lab_profile() {
    let r = run_in_process("quad-mass-step", &[&case("7-hover-mass-step")]);
    assert_eq!(r.metric("mass_true_kg"), 0.262);
    let rise = r.metric("mass_estimate_rise_kg");
    assert!((rise - 0.045).abs() <= 0.01, "m̂ rose by {rise} kg");
    let spread = r.metric("mass_estimate_spread_last_5s_kg");
    assert!(spread < 0.01, "m̂ still moves by {spread} kg over the last 5 s");
    let worst = r.metric("z1_max_after_step_m");
    assert!(worst < 1.0, "‖z₁‖ reaches {worst} m after the step");
    // The link holds each command 54 ticks: the vehicle acts on a command up to 53 ticks old,
    // computed from a pose up to 8 ticks older still (sampled every 10 ticks; 54k mod 10 ≤ 8).
    let ticks = |seconds: f64| (seconds * 1200.0 * 1e6).round() / 1e6;
    assert_eq!(ticks(r.metric("command_hold_max_s")), 53.0);
    assert_eq!(ticks(r.metric("actuation_data_age_max_s")), 61.0);
    // The pose is the only sensor, sampled every 10 ticks at 1200 Hz.
    let age = &r.summary["data_age_ns"]["pose"];
    assert_eq!(age["max"].as_f64().unwrap().round(), (9.0 / 1200.0 * 1e9f64).round(), "{age}");
}

#[test]
fn bad_quadcopter_settings_name_the_key() {
    for (set, expected) in [
        ("controller.delta=[0.1, 0.0, 0.0]", "key `controller.delta`: δ₃ (the third component) must not be 0"),
        (
            "sensors.angular_rate.enabled=false",
            "key `sensors`: the quadcopter needs both a velocity and an angular_rate sensor",
        ),
        ("controller.parameters=true", "key `controller.parameters`"),
        ("model.inertia_kg_m2=[1e-3, 0.0, 1e-3]", "key `model.inertia_kg_m2.1`: must be a positive number, got 0"),
    ] {
        let output = looplab().args(["run", "quadcopter", "--mode", "lockstep", "--set", set]).output().unwrap();
        assert_eq!(output.status.code(), Some(2), "{set}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(&format!("--set {set}")) && stderr.contains(expected), "{set}: {stderr}");
    }
}

/// A killed estimator comes back with what it had learnt (ξ̂, m̂, ĵ and their variances): in the
/// closed loop of case 4, ‖z₁‖ stays within the paper's ball through the restart, and the
/// estimates end as accurate as without the fault.
#[test]
fn a_restarted_estimator_keeps_its_parameter_estimates() {
    let r = run("quad-kill", &[&case("4-closed-loop"), "--fault", "kill estimator at 15"]);
    let fault = &r.summary["faults"][0];
    assert_eq!(fault["effect"]["outage_ticks"], 0, "{fault}");
    let worst = fault["effect"]["worst_error_after"].as_f64().unwrap();
    assert!(worst <= 0.09, "‖z₁‖ reached {worst} m after the restart");
    assert_eq!(r.summary["restarts"]["estimator"], 1);
    assert!(r.metric("param_rel_error_max_final") < 0.01);
}
