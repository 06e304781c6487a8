//! The flying inverted pendulum on a quadrotor (paper 000) in lockstep: the reference's speed
//! and lap, the three disturbance cases of section 6 and the 45 Hz experiment profile, each a
//! launch file in launch/fip/. The numerical cases run in-process (byte-identical to the five
//! processes: tests/trajectory_hashes.rs); one runs the five processes in real time.

use crate::common;

use common::{looplab, run, run_in_process};

fn case(name: &str) -> String {
    format!("launch/fip/{name}.toml")
}

/// The simulation's vehicle (section 7): m_T = 0.29 kg, k_p = 12.
const TOTAL_MASS: f64 = 0.29;
const G: f64 = 9.81;
const K_P: f64 = 12.0;

/// (68)–(69): ‖ṗ_Ld‖ = 0.5 m/s at every tick (exact derivatives of the ϑ series), and one lap
/// of the 5.48631 m ellipse takes 10.973 s (ϑ integrated to 2π).
#[test]
fn the_reference_keeps_its_speed_and_laps_in_10_973_s() {
    let r = run_in_process("fip-ref", &[&case("1-reference")]);
    let lap = r.metric("lap_period_s");
    assert!((lap - 10.9726).abs() < 5e-4, "one lap takes {lap} s");
    let speed_error = r.metric("reference_speed_err_max_m_s");
    assert!(speed_error < 1e-12, "‖ṗ_Ld‖ is off 0.5 m/s by up to {speed_error}");
}

/// Case (i): after the transient (t > 20 s) the estimated load speed stays within 2 % of
/// 0.5 m/s at every tick, ‖z_p‖ stays below a third of the experiment's 9.72 cm, and the thrust
/// averages the hover thrust m_T g (the path's centripetal load adds 0.03 %).
#[test]
fn without_disturbance_the_load_tracks_the_path_at_its_speed() {
    let r = run_in_process("fip-none", &[&case("2-no-disturbance")]);
    let t = r.trajectory();
    let (time, vx, vy, vz) = (
        t.col("t_s"),
        t.col("est.load_vx_hat_m_per_s"),
        t.col("est.load_vy_hat_m_per_s"),
        t.col("est.load_vz_hat_m_per_s"),
    );
    let mut checked = 0;
    for i in 0..time.len() {
        if time[i] > 20.0 {
            let speed = (vx[i] * vx[i] + vy[i] * vy[i] + vz[i] * vz[i]).sqrt();
            assert!((speed / 0.5 - 1.0).abs() < 0.02, "‖v̂_L‖ = {speed} m/s at t = {}", time[i]);
            checked += 1;
        }
    }
    assert_eq!(checked, 100_000 - 1);
    let mean = r.metric("vl_hat_speed_mean_m_s");
    assert!((mean / 0.5 - 1.0).abs() < 0.005, "mean ‖v̂_L‖ {mean}");
    let worst = r.metric("zp_max_after_20s_m");
    assert!(worst < 0.0972 / 3.0, "‖z_p‖ reaches {worst} m after 20 s");
    let thrust = r.metric("thrust_mean_n");
    assert!((thrust / (TOTAL_MASS * G) - 1.0).abs() < 0.002, "mean thrust {thrust} N");
    // Never the pendulum more than 3° from upright once on the path.
    assert!(r.metric("theta_pendulum_max_after_20s_rad") < 3f64.to_radians());
}

/// Case (ii), b = [−0.5, 0.5, −0.8] N: b̂ converges in x and y within a few hundredths of a
/// newton; the mean thrust is ‖−b − m_T g e₃‖ = 2.164 N. b_z is poorly observable with the rod
/// upright (Remark 5): b̂_z keeps what the filter learnt in the transient, and z is offset by
/// exactly that error over m_T k_p (the derived 0.23 m is the offset if b̂_z had learnt nothing).
#[test]
fn a_constant_disturbance_is_estimated_in_x_and_y_and_offsets_z_by_its_error() {
    let r = run_in_process("fip-const", &[&case("3-constant-disturbance")]);
    for axis in ["x", "y"] {
        let error = r.metric(&format!("b_hat_err_rms_n_{axis}"));
        assert!(error < 0.01, "b̂_{axis} is off by {error} N (RMS)");
    }
    let expected = (0.5f64.powi(2) + 0.5f64.powi(2) + (TOTAL_MASS * G - 0.8).powi(2)).sqrt();
    assert!((expected - 2.164).abs() < 5e-4);
    let thrust = r.metric("thrust_mean_n");
    assert!((thrust / expected - 1.0).abs() < 0.002, "mean thrust {thrust} N, expected {expected}");
    let b_z_error = r.metric("b_hat_mean_n_z") - r.metric("b_mean_n_z");
    let offset = r.metric("zp_z_mean_m");
    let predicted = -b_z_error / (TOTAL_MASS * K_P);
    assert!(b_z_error.abs() > 0.01, "b̂_z learnt b_z to {b_z_error} N: Remark 5 would not show");
    assert!((offset / predicted - 1.0).abs() < 0.05, "z offset {offset} m, b̂_z error {b_z_error} N → {predicted} m");
}

/// Case (iii), the Ornstein–Uhlenbeck b: the filter's errors stay bounded after the transient,
/// and b̂ follows b in x and y with an RMS error under half of b's own spread. b_z is not
/// followed (Remark 5): its error exceeds its spread.
#[test]
fn a_stochastic_disturbance_is_tracked_in_x_and_y() {
    let r = run_in_process("fip-ou", &[&case("4-stochastic-disturbance")]);
    assert!(r.metric("omega_err_rms_rad_s") < 0.05, "{}", r.metric("omega_err_rms_rad_s"));
    assert!(r.metric("vl_err_rms_m_s") < 0.05, "{}", r.metric("vl_err_rms_m_s"));
    assert!(r.metric("q_hat_err_rms") < 0.01, "{}", r.metric("q_hat_err_rms"));
    for axis in ["x", "y"] {
        let (error, spread) = (r.metric(&format!("b_hat_err_rms_n_{axis}")), r.metric(&format!("b_std_n_{axis}")));
        assert!(spread > 0.02, "b_{axis} hardly moves ({spread} N): nothing to track");
        assert!(error < 0.5 * spread, "b̂_{axis}: RMS error {error} N against b's spread {spread} N");
    }
    assert!(r.metric("b_hat_err_rms_n_z") > r.metric("b_std_n_z"));
    assert!(r.metric("zp_max_after_20s_m") < 0.2, "{}", r.metric("zp_max_after_20s_m"));
}

/// The experiment profile: commands over the 45 Hz link (held 22–23 ticks), the motion capture
/// at 100 Hz with noise, section 8's gains. The loop stays stable and ‖v̂_L‖ averages within
/// 2 % of the path's 0.5 m/s (the paper's lab: 0.51). The vehicle acts on a command up to 22
/// ticks old, computed from a frame up to 9 ticks older still: 31 ms at most.
#[test]
fn the_experiment_profile_is_stable_behind_the_45_hz_link() {
    let r = run_in_process("fip-exp", &[&case("5-experiment")]);
    let speed = r.metric("vl_hat_speed_mean_m_s");
    assert!((speed / 0.5 - 1.0).abs() < 0.02, "mean ‖v̂_L‖ {speed}");
    assert!(r.metric("zp_max_after_20s_m") < 0.3, "{}", r.metric("zp_max_after_20s_m"));
    assert!(r.metric("theta_pendulum_max_after_20s_rad") < 5f64.to_radians());
    let ticks = |name: &str| (r.metric(name) * 1000.0 * 1e6).round() / 1e6;
    assert_eq!(ticks("command_hold_max_s"), 22.0);
    assert_eq!(ticks("actuation_data_age_max_s"), 31.0);
}

/// The five processes in real time, the experiment profile: the run completes, the metrics are
/// there, and the report gives the motion capture's data age beside the loop's latency.
#[test]
fn the_experiment_profile_runs_in_real_time() {
    let r = run("fip-rt", &[&case("5-experiment"), "--mode", "realtime", "--duration", "3"]);
    let s = r.summary();
    assert!(s.completed, "{}", r.stdout());
    assert!(r.metric("actuation_data_age_mean_s") > 0.0);
    let (mocap, velocity) = (&s.data_age_ns["mocap_load"], &s.data_age_ns["uav_velocity"]);
    assert!(mocap.count > 0 && velocity.count > 0, "{mocap:?} {velocity:?}");
    let report = r.stdout();
    for line in ["data age: mocap_load", "END TO END"] {
        assert!(report.lines().any(|l| l.trim_start().starts_with(line)), "{line} missing:\n{report}");
    }
}

#[test]
fn bad_fip_settings_name_the_key() {
    for (set, expected) in [
        ("disturbance.kind=\"wind\"", "key `disturbance.kind`"),
        ("controller.beta=2.0", "key `controller.beta`: must be below min(√k_p, 4k_p k_v/(4k_p + k_v²)) = 1.4328"),
        (
            "sensors.mocap_uav.period_s=0.01",
            "key `sensors.mocap_uav`: must have the period and delay of sensors.mocap_load",
        ),
        (
            "plant.command_period_s=0.0001",
            "key `plant.command_period_s`: must be 0 (every tick) or from one loop period",
        ),
        (
            "estimator.initial_direction=[0.0, 0.0, 0.0]",
            "key `estimator.initial_direction`: must be a nonzero direction",
        ),
        ("plant.initial.tilt_deg=95.0", "key `plant.initial.tilt_deg`: must be 0 to 80 degrees from upright, got 95"),
        ("model.rod_length_m=0.0", "key `model.rod_length_m`: must be 0.01 to 100 m, got 0"),
    ] {
        let output = looplab().args(["run", "fip", "--mode", "lockstep", "--set", set]).output().unwrap();
        assert_eq!(output.status.code(), Some(2), "{set}");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(stderr.trim_end().lines().count(), 1, "{set}: {stderr}");
        assert!(stderr.contains(&format!("--set {set}")) && stderr.contains(expected), "{set}: {stderr}");
    }
}

/// The experiment's ‖z_p‖ (the paper: a mean of 9.72 cm once steady, Fig. 6). The profile's two
/// choices (launch/fip/5-experiment.toml): q̂(0) at the measured rod direction, and a 0.25 N
/// vertical force error that the experiment's q_b,z = 10⁻⁵ leaves unlearnt. On seeds no other
/// test uses, ‖z_p‖ averages 9.51–9.55 cm (within 2 % of the paper's; held to 10 % of 9.54), and
/// it is the offset b̃_z/(m_T k_p) (within 1 %; held to 5 %). Each choice isolated: without the
/// force the same profile gives 0.43 cm, and with the simulation's q̂(0) = e₃ the rod swings
/// past 80° (1.43 rad) and b̂_z ends far off.
#[test]
fn the_experiments_9_72_cm_is_the_offset_of_a_vertical_force_the_filter_does_not_learn() {
    let experiment = case("5-experiment");
    let cases: Vec<Vec<String>> = vec![
        vec!["seed=3".into()],
        vec!["seed=4".into()],
        vec!["seed=5".into()],
        vec!["seed=3".into(), "disturbance.kind=\"none\"".into()],
        vec!["seed=3".into(), "estimator.initial_direction=[0.0, 0.0, 1.0]".into()],
    ];
    let run_one = |sets: &Vec<String>| {
        let mut args = vec![experiment.as_str()];
        for set in sets {
            args.extend(["--set", set.as_str()]);
        }
        (sets.clone(), run_in_process("fip-exp-zp", &args))
    };
    let runs = common::on_two_threads(&cases, run_one);
    // The lab's vehicle: m_T = 0.285 kg, k_p = 9.
    let (total_mass, k_p) = (0.285, 9.0);
    for (sets, r) in &runs[..3] {
        let zp = r.metric("zp_mean_m");
        assert!((zp / 0.0954 - 1.0).abs() < 0.1, "{sets:?}: ‖z_p‖ averages {zp} m");
        assert!((zp / 0.0972 - 1.0).abs() < 0.25, "{sets:?}: ‖z_p‖ {zp} m against the paper's 0.0972 m");
        let offset = (r.metric("b_mean_n_z") - r.metric("b_hat_mean_n_z")) / (total_mass * k_p);
        let vertical = r.metric("zp_z_mean_m");
        assert!((vertical / offset - 1.0).abs() < 0.05, "{sets:?}: z offset {vertical} m, b̃_z/(m_T k_p) = {offset} m");
        assert!(
            r.metric("theta_pendulum_max_rad") < 0.31,
            "{sets:?}: the rod swung to {}",
            r.metric("theta_pendulum_max_rad")
        );
    }
    let (sets, without_force) = &runs[3];
    let zp = without_force.metric("zp_mean_m");
    assert!(zp < 1.1 * 0.0043, "{sets:?}: ‖z_p‖ {zp} m without the vertical force");
    let (sets, wrong_start) = &runs[4];
    let swing = wrong_start.metric("theta_pendulum_max_rad");
    assert!(swing > 0.9 * 1.43, "{sets:?}: the rod swung only to {swing} rad");
    let b_error = (wrong_start.metric("b_mean_n_z") - wrong_start.metric("b_hat_mean_n_z")).abs();
    assert!(b_error > 0.9 * 0.58, "{sets:?}: b̂_z off by only {b_error} N");
}
