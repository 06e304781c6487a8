//! Launch files resolved against the real scenarios: defaults, overrides, files, and the
//! errors that name the key and where its value came from. (The config layer's own unit tests
//! cannot name a scenario; these need the pendulum's and the quadcopter's sections.)

use std::path::Path;

use crate::config::launch::{LaunchConfig, LaunchError, Mode, Override, PerComponent};
use crate::scenarios::{self, resolve};

fn run(overrides: &[&str]) -> Result<LaunchConfig, LaunchError> {
    let overrides: Vec<Override> = overrides.iter().map(|s| Override::parse(s).unwrap()).collect();
    resolve("pendulum", &overrides).map(|(c, _)| c)
}

#[test]
fn builtin_defaults_load() {
    let c = run(&[]).unwrap();
    assert_eq!(c.scenario, "pendulum");
    assert_eq!(c.mode, Mode::Realtime);
    assert_eq!(c.rate_hz, 1000.0);
    assert_eq!(c.loops(), 10_000);
    assert_eq!(c.sensors.keys().collect::<Vec<_>>(), ["encoder", "wheel_speed"]);
    assert_eq!(c.period_ticks(&c.sensors["wheel_speed"]), 10);
}

#[test]
fn set_overrides_values_and_coerces_integers() {
    let c = run(&["sensors.encoder.bias=0.05", "duration_s=30", "mode=lockstep", "estimator.kind=no-bias"]).unwrap();
    assert_eq!(c.sensors["encoder"].bias, PerComponent::All(0.05));
    assert_eq!(c.duration_s, 30.0);
    assert_eq!(c.mode, Mode::Lockstep);
    assert_eq!(c.document["estimator"]["kind"].as_str(), Some("no-bias"));

    let c = run(&["controller.gains.1=-50"]).unwrap();
    assert_eq!(c.document["controller"]["gains"][1].as_float(), Some(-50.0));
    let e = run(&["controller.gains.3=1"]).unwrap_err();
    assert!(e.message.contains("is a list of 3; index it with 0 to 2"), "{e}");
}

#[test]
fn unknown_key_names_the_key_and_the_allowed_ones() {
    let e = run(&["sensors.encoder.biass=0.05"]).unwrap_err();
    assert_eq!(e.origin, "--set sensors.encoder.biass=0.05");
    assert_eq!(e.key.as_deref(), Some("sensors.encoder.biass"));
    assert!(e.message.contains("expected one of") && e.message.contains("`bias`"), "{e}");

    let e = run(&["durationn_s=3"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("durationn_s"));
    assert!(e.message.contains("duration_s"), "{e}");

    let e = run(&["estimator.kindd=x"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("estimator.kindd"), "{e}");
}

#[test]
fn bad_values_name_the_key_and_what_is_allowed() {
    let e = run(&["mode=fast"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("mode"));
    assert!(e.message.contains("realtime") && e.message.contains("lockstep"), "{e}");

    let e = run(&["estimator.kind=kalman"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("estimator.kind"));
    assert!(e.message.contains("bias-observer") && e.message.contains("no-bias"), "{e}");

    let e = run(&["rate_hz=-5"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("rate_hz"));

    let e = run(&["sensors.wheel_speed.period_s=0.0015"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("sensors.wheel_speed.period_s"));
    assert!(e.message.contains("multiple of the loop period"), "{e}");

    let e = run(&["sensors.encoder.signal=height"]).unwrap_err();
    assert!(e.message.contains("theta") && e.message.contains("wheel_speed"), "{e}");

    let e = run(&["duration_s=fast"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("duration_s"));
    assert!(e.message.contains("invalid type"), "{e}");
}

#[test]
fn unknown_scenario_lists_the_known_ones() {
    let e = resolve("pendulm", &[]).map(|_| ()).unwrap_err();
    assert!(e.message.contains("unknown scenario \"pendulm\"") && e.message.contains("pendulum"), "{e}");
}

#[test]
fn a_file_overrides_the_defaults_and_errors_name_the_file() {
    let dir = std::env::temp_dir().join(format!("looplab-launch-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let good = dir.join("good.toml");
    std::fs::write(&good, "scenario = \"pendulum\"\nmode = \"lockstep\"\n[sensors.encoder]\nbias = -0.02\n").unwrap();
    let (c, _) = resolve(good.to_str().unwrap(), &[]).unwrap();
    assert_eq!(c.mode, Mode::Lockstep);
    assert_eq!(c.sensors["encoder"].bias, PerComponent::All(-0.02));
    assert_eq!(c.sensors["encoder"].signal, "theta", "keys the file leaves out keep their defaults");

    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "scenario = \"pendulum\"\n[sensors.encoder]\nnoise = 1\n").unwrap();
    let e = resolve(bad.to_str().unwrap(), &[]).map(|_| ()).unwrap_err();
    assert_eq!(e.origin, bad.to_str().unwrap());
    assert_eq!(e.key.as_deref(), Some("sensors.encoder.noise"));

    let broken = dir.join("broken.toml");
    std::fs::write(&broken, "scenario = \"pendulum\"\nrate_hz = \n").unwrap();
    let e = resolve(broken.to_str().unwrap(), &[]).map(|_| ()).unwrap_err();
    assert!(e.message.starts_with("not valid TOML"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn non_finite_numbers_are_rejected_naming_the_key_and_origin() {
    for (set, key) in [
        ("plant.initial.theta=nan", "plant.initial.theta"),
        ("plant.initial.wheel_speed=-inf", "plant.initial.wheel_speed"),
        ("model.m_p=inf", "model.m_p"),
        ("controller.gains=[-378.0, nan, -1.0]", "controller.gains.1"),
        ("sensors.encoder.bias=[nan]", "sensors.encoder.bias.0"),
    ] {
        let e = run(&[set]).unwrap_err();
        assert_eq!(e.origin, format!("--set {set}"));
        assert_eq!(e.key.as_deref(), Some(key), "{e}");
        assert!(e.message.contains("must be a finite number"), "{e}");
    }

    let fault = Override::fault("delay controller by infs at 1s").unwrap();
    let e = resolve("pendulum", &[fault]).map(|_| ()).unwrap_err();
    assert_eq!(e.origin, "--fault delay controller by infs at 1s");
    assert_eq!(e.key.as_deref(), Some("faults.0.delay_s"), "{e}");

    let dir = std::env::temp_dir().join(format!("looplab-launch-nan-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("nan.toml");
    std::fs::write(&file, "scenario = \"quadcopter\"\n[plant.initial]\nposition_m = [0.0, nan, 0.0]\n").unwrap();
    let e = resolve(file.to_str().unwrap(), &[]).map(|_| ()).unwrap_err();
    assert_eq!(e.origin, file.to_str().unwrap());
    assert_eq!(e.key.as_deref(), Some("plant.initial.position_m.1"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Asserts that `sets` is rejected with an error on `key` whose message has `fragment`.
fn rejected(sets: &[&str], key: &str, fragment: &str) {
    let e = run(sets).unwrap_err();
    assert_eq!(e.key.as_deref(), Some(key), "{sets:?}: {e}");
    assert!(e.message.contains(fragment), "{sets:?}: {e}");
}

#[test]
fn durations_rates_and_counts_are_bounded() {
    rejected(&["duration_s=604801"], "duration_s", "at most 604800");
    rejected(&["duration_s=604800", "rate_hz=100000"], "duration_s", "at most 1000000000");
    assert_eq!(run(&["duration_s=604800"]).unwrap().loops(), 604_800_000);
    rejected(&["sensors.wheel_speed.period_s=604801"], "sensors.wheel_speed.period_s", "at most 604800");
    // A sensor slower than a short run samples once, at loop 0.
    run(&["duration_s=0.005"]).unwrap();
    rejected(&["sensors.encoder.delay_ticks=10001"], "sensors.encoder.delay_ticks", "at most the run's 10000 loops");
    run(&["sensors.encoder.delay_ticks=10000"]).unwrap();
    rejected(&["wait.lead_us=1000001"], "wait.lead_us", "0 to 1000000");
    rejected(&["wait.spin_cap_us=-1"], "wait.spin_cap_us", "0 to 1000000");
    rejected(&["wait.lockstep=sometimes"], "wait.lockstep", "`auto`, `poll`, `block`, `handoff`");
    rejected(&["plant.substeps=1001"], "plant.substeps", "1 to 1000");
    rejected(&["plant.substeps=0"], "plant.substeps", "1 to 1000");
}

#[test]
fn supervision_times_and_counts_are_bounded() {
    rejected(&["supervision.backoff_s=2e19"], "supervision.backoff_s", "0 to 60 seconds");
    rejected(&["supervision.controller.backoff_s=61"], "supervision.controller.backoff_s", "0 to 60");
    run(&["supervision.backoff_s=60", "supervision.max_restarts=1000"]).unwrap();
    rejected(&["supervision.max_restarts=1001"], "supervision.max_restarts", "0 to 1000");
    rejected(&["supervision.plant.max_restarts=5000"], "supervision.plant.max_restarts", "0 to 1000");
    for key in ["lockstep_stall_s", "stall_timeout_s", "command_timeout_s"] {
        rejected(&[&format!("supervision.{key}=1e20")], &format!("supervision.{key}"), "at most 3600");
        rejected(&[&format!("supervision.{key}=0")], &format!("supervision.{key}"), "positive");
    }
}

/// A rate from the command line that a sensor's period (from the file) no longer fits: the error
/// says where the rate came from and what to set with it.
#[test]
fn a_rate_that_breaks_a_sensor_period_says_what_to_set() {
    let e = run(&["rate_hz=250"]).unwrap_err();
    assert_eq!(e.key.as_deref(), Some("sensors.encoder.period_s"));
    assert!(
        e.message.ends_with(
            "rate_hz comes from --set rate_hz=250 (--rate): set the sensor's period with it, e.g. --set \
             sensors.encoder.period_s=0.004"
        ),
        "{e}"
    );
}

#[test]
fn scenario_parameters_that_overflow_the_physics_are_rejected() {
    rejected(&["model.torque_constant=1e307"], "model", "finite");
    rejected(&["estimator.bias-observer.poles=[-1e300, -1e300, -1e300]"], "estimator.bias-observer.poles", "gains");
    let quadcopter = |sets: &[&str]| {
        let overrides: Vec<Override> = sets.iter().map(|s| Override::parse(s).unwrap()).collect();
        resolve("quadcopter", &overrides).map(|_| ()).unwrap_err()
    };
    assert_eq!(quadcopter(&["model.mass_kg=1e-320"]).key.as_deref(), Some("model.mass_kg"));
    assert_eq!(
        quadcopter(&["estimator.initial_xi_factor=[0.0, 1.0, 1.0, 1.0]"]).key.as_deref(),
        Some("estimator.initial_xi_factor.0")
    );
    assert_eq!(quadcopter(&["plant.mass_step_at_s=-1"]).key.as_deref(), Some("plant.mass_step_at_s"));
    // Initial states and references the model cannot integrate (they overflowed in a run).
    rejected(&["plant.initial.theta_dot=1.7e308"], "plant.initial.theta_dot", "within ±10000");
    rejected(&["plant.initial.theta=4"], "plant.initial.theta", "within ±3.14");
    let e = quadcopter(&["reference.hover_position=[1e300, 0.0, 0.0]"]);
    assert_eq!((e.key.as_deref(), e.message.contains("within ±10000")), (Some("reference.hover_position.0"), true));
    let e = quadcopter(&["model.command_period_s=1e308"]);
    assert_eq!(e.key.as_deref(), Some("model.command_period_s"));
    assert!(e.message.contains("0 (every tick) or from one loop period"), "{e}");
}

/// Every number of each scenario's defaults, set to extreme values, loads or gives an error:
/// never a panic, and what loads builds a plant whose first step is finite.
#[test]
fn extreme_values_of_every_key_load_or_fail_cleanly() {
    fn numeric_keys(prefix: &str, value: &toml::Value, out: &mut Vec<(String, bool)>) {
        match value {
            toml::Value::Float(_) => out.push((prefix.to_owned(), true)),
            toml::Value::Integer(_) => out.push((prefix.to_owned(), false)),
            toml::Value::Table(t) => {
                for (k, v) in t {
                    let key = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                    numeric_keys(&key, v, out);
                }
            }
            toml::Value::Array(items) => {
                for (i, v) in items.iter().enumerate() {
                    numeric_keys(&format!("{prefix}.{i}"), v, out);
                }
            }
            _ => {}
        }
    }
    let floats = [0.0, -1.0, 1e300, -1e300, 1e-300];
    let integers = [0, -1, 1, i64::MAX, i64::MIN];
    for entry in scenarios::ALL {
        let mut keys = Vec::new();
        numeric_keys("", &toml::Value::Table(entry.defaults()), &mut keys);
        assert!(keys.len() > 20, "{}: {keys:?}", entry.name);
        for (key, is_float) in keys {
            let values: Vec<toml::Value> = if is_float {
                floats.iter().map(|v| toml::Value::Float(*v)).collect()
            } else {
                integers.iter().map(|v| toml::Value::Integer(*v)).collect()
            };
            for value in values {
                let text = format!("{key}={value}");
                let o = Override { key: key.clone(), value, text: text.clone(), append: false };
                let Ok((config, scenario)) = resolve(entry.name, &[o]) else { continue };
                let mut plant = scenario.plant();
                let _ = (scenario.estimator(), scenario.controller(), scenario.metrics());
                let u: Vec<f64> = scenario.input_limits().iter().map(|(lo, hi)| (lo + hi) / 2.0).collect();
                plant.step(0.0, &u, config.dt()).unwrap();
                let finite = plant.state().iter().all(|x| x.is_finite());
                assert!(finite, "{}: {text} loads, and the first step gives {:?}", entry.name, plant.state());
            }
        }
    }
}

/// Every launch file of the repository, `launch/*.toml` and `launch/*/*.toml`, listed now so that
/// a new file is covered without naming it here.
fn launch_files() -> Vec<std::path::PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../launch");
    let list = |dir: &Path| -> Vec<std::path::PathBuf> {
        let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()));
        entries.map(|e| e.unwrap().path()).collect()
    };
    let mut files = Vec::new();
    for path in list(&root) {
        if path.is_dir() {
            files.extend(list(&path).into_iter().filter(|p| p.extension().is_some_and(|e| e == "toml")));
        } else if path.extension().is_some_and(|e| e == "toml") {
            files.push(path);
        }
    }
    files.sort();
    files
}

/// Each launch file resolves (and its scenario builds), and names the scenario its place says:
/// `launch/<scenario>.toml` or `launch/<scenario>/<case>.toml`.
#[test]
fn every_launch_file_of_every_scenario_resolves_within_the_bounds() {
    let files = launch_files();
    assert!(!files.is_empty(), "no launch file found under launch/");
    for entry in scenarios::ALL {
        assert!(files.iter().any(|f| f.ends_with(entry.file)), "{} is not among {files:?}", entry.file);
    }
    for file in &files {
        let (config, _) = resolve(file.to_str().unwrap(), &[]).unwrap_or_else(|e| panic!("{e}"));
        let parent = file.parent().unwrap();
        let named_by_place = if parent.ends_with("launch") { file.file_stem() } else { parent.file_name() };
        assert_eq!(Some(config.scenario.as_ref()), named_by_place, "{}", file.display());
    }
}

/// `wait.lockstep = "auto"` is decided by the launcher for the machine, and the run's
/// launch.toml (which every process loads) says what was decided.
#[test]
fn lockstep_auto_is_decided_for_the_machine_and_written_down() {
    use crate::config::wait::LockstepWait;
    let config = run(&["mode=lockstep"]).unwrap();
    assert_eq!(config.wait.lockstep, LockstepWait::Auto);
    for (cpus, decided) in [(2, LockstepWait::Handoff), (4, LockstepWait::Handoff), (5, LockstepWait::Poll)] {
        let d = config.with_wait_decided(cpus);
        assert_eq!(d.wait.lockstep, decided, "{cpus} CPUs");
        let name: &str = decided.into();
        assert!(d.to_toml().contains(&format!("lockstep = \"{name}\"")), "{}", d.to_toml());
    }
    // An explicit choice stays.
    let forced = run(&["mode=lockstep", "wait.lockstep=poll"]).unwrap().with_wait_decided(2);
    assert_eq!(forced.wait.lockstep, LockstepWait::Poll);
}
