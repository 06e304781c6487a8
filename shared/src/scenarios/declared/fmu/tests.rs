//! The loader against the project's own pendulum FMU, built here with `cc`: its Model Exchange
//! derivative is the built-in pendulum's bit for bit, its Co-Simulation steps are its RK4's and
//! fmpy's, its state survives serialisation, and bad input gives one line.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use nalgebra::Vector3;

use super::*;
use crate::model::integrate::rk4;
use crate::model::plant_model::{ModelSpec, Stepping};
use crate::scenarios::pendulum::params::tests::paper_model;

/// target/fmu-tests/, where the test FMUs and fmpy's venv live.
fn work_dir() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/fmu-tests");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The pendulum FMU for `version`, built once per test process (written under a name of this
/// process's own and renamed, so that concurrent test binaries do not race).
pub(crate) fn pendulum_fmu(version: Version) -> PathBuf {
    static BUILT: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    let (two, three) = BUILT.get_or_init(|| {
        let build = |v: Version, n: u8| {
            let out = work_dir().join(format!("pendulum-fmi{n}.fmu"));
            let partial = work_dir().join(format!("pendulum-fmi{n}.fmu.{}", std::process::id()));
            build_fmu(&pendulum_source(), v, &partial).unwrap();
            std::fs::rename(&partial, &out).unwrap();
            out
        };
        (build(Version::Fmi2, 2), build(Version::Fmi3, 3))
    });
    if version == Version::Fmi2 { two.clone() } else { three.clone() }
}

fn spec(state: &[&str]) -> ModelSpec {
    ModelSpec {
        file: "system.toml".into(),
        folder: PathBuf::from("."),
        state: state.iter().map(|s| s.to_string()).collect(),
        input: vec!["current".into()],
        outputs: vec!["energy".into()],
        initial: vec![None; state.len()],
        parameters: vec![],
        dt: 1e-3,
    }
}

fn pendulum_spec() -> ModelSpec {
    spec(&["theta", "theta_dot", "wheel_speed"])
}

const VERSIONS: [Version; 2] = [Version::Fmi2, Version::Fmi3];

#[test]
fn model_exchange_derivative_is_the_builtin_pendulums_bit_for_bit() {
    let model = paper_model();
    for version in VERSIONS {
        let mut fmu = load(&pendulum_spec(), &pendulum_fmu(version)).unwrap();
        assert_eq!(fmu.stepping(), Stepping::Derivative, "{}", fmu.describe());
        let mut dx = [0.0; 3];
        for k in 0..200 {
            let k = f64::from(k);
            let x = Vector3::new((k * 0.173).sin() * 3.0, (k * 0.31).cos() * 7.0, k * 0.9 - 50.0);
            let current = (k * 0.07).sin() * 5.0;
            fmu.derivative(k * 1e-3, x.as_slice(), &[current], &mut dx).unwrap();
            let expected = model.derivative(&x, current);
            for i in 0..3 {
                assert_eq!(dx[i].to_bits(), expected[i].to_bits(), "{version:?} ẋ[{i}] at x = {x:?}, I = {current}");
            }
            let mut y = [0.0];
            fmu.outputs(0.0, x.as_slice(), &[current], &mut y).unwrap();
            assert_eq!(y[0].to_bits(), model.energy(&x).to_bits(), "{version:?} energy");
        }
    }
}

#[test]
fn the_declared_order_and_parameters_map_by_name() {
    let mut model = paper_model();
    model.j_r = 2e-3;
    model.g = 9.80665;
    for version in VERSIONS {
        let mut s = spec(&["wheel_speed", "theta", "theta_dot"]);
        s.parameters = vec![("j_r".into(), 2e-3), ("g".into(), 9.80665)];
        s.initial = vec![Some(1.5), None, Some(-0.25)];
        let mut fmu = load(&s, &pendulum_fmu(version)).unwrap();
        assert_eq!(fmu.initial_state().unwrap(), vec![1.5, 0.05, -0.25], "{version:?}");
        let x = Vector3::new(0.3, -1.0, 12.0);
        let mut dx = [0.0; 3];
        fmu.derivative(0.0, &[x[2], x[0], x[1]], &[2.0], &mut dx).unwrap();
        let e = model.derivative(&x, 2.0);
        assert_eq!(dx.map(f64::to_bits), [e[2], e[0], e[1]].map(f64::to_bits), "{version:?}");
    }
}

/// The pendulum FMU's doStep runs RK4 with the input held, `substeps` per step: the built-in
/// pendulum's integration, bit for bit.
#[test]
fn co_simulation_steps_are_the_builtin_rk4() {
    let model = paper_model();
    for version in VERSIONS {
        let mut s = pendulum_spec();
        s.parameters = vec![("substeps".into(), 7.0)];
        let mut fmu = load_as(&s, &pendulum_fmu(version), Some(FmiKind::CoSimulation)).unwrap();
        assert_eq!(fmu.stepping(), Stepping::OwnStep);
        let mut x = fmu.initial_state().unwrap();
        let mut reference = Vector3::new(0.05, 0.0, 0.0);
        for k in 0..500 {
            let current = (f64::from(k) * 0.01).sin() * 3.0;
            fmu.do_step(f64::from(k) * 1e-3, 1e-3, &[current], &mut x).unwrap();
            reference = rk4(&|x: &Vector3<f64>| model.derivative(x, current), &reference, 1e-3, 7);
        }
        assert_eq!(
            x.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            reference.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
        );
    }
}

/// A restarted plant is a new process: a fresh instance loads the bytes another one saved, and
/// both go on identically.
#[test]
fn a_saved_state_restores_into_a_fresh_instance() {
    for version in VERSIONS {
        for kind in [FmiKind::ModelExchange, FmiKind::CoSimulation] {
            let path = pendulum_fmu(version);
            let mut first = load_as(&pendulum_spec(), &path, Some(kind)).unwrap();
            let mut x = first.initial_state().unwrap();
            let step = |m: &mut Box<dyn PlantModel>, x: &mut Vec<f64>, k: u32| {
                let t = f64::from(k) * 1e-3;
                if kind == FmiKind::CoSimulation {
                    m.do_step(t, 1e-3, &[0.5], x).unwrap();
                } else {
                    let mut dx = vec![0.0; 3];
                    m.derivative(t, x, &[0.5], &mut dx).unwrap();
                    x.iter_mut().zip(&dx).for_each(|(x, d)| *x += d * 1e-3);
                }
            };
            (0..100).for_each(|k| step(&mut first, &mut x, k));
            let bytes = first.freeze().unwrap().expect("the pendulum FMU serialises its state");
            let mut second = load_as(&pendulum_spec(), &path, Some(kind)).unwrap();
            second.thaw(&bytes).unwrap();
            second.set_state(&x).or_else(|e| if kind == FmiKind::CoSimulation { Ok(()) } else { Err(e) }).unwrap();
            let mut x2 = x.clone();
            for k in 100..200 {
                step(&mut first, &mut x, k);
                step(&mut second, &mut x2, k);
            }
            assert_eq!(x, x2, "{version:?} {kind:?}");
            assert!(second.thaw(&bytes[1..]).is_err(), "a truncated state is refused");
        }
    }
}

/// fmpy (an independent FMI importer, installed into target/fmu-tests/venv) drives the same FMU
/// in Co-Simulation with the same inputs.
#[test]
fn co_simulation_agrees_with_fmpy() {
    let python = fmpy_python();
    for version in VERSIONS {
        let path = pendulum_fmu(version);
        let inputs: Vec<f64> = (0..1000).map(|k| (f64::from(k) * 0.013).sin() * 2.0).collect();
        let mut fmu = load_as(&pendulum_spec(), &path, Some(FmiKind::CoSimulation)).unwrap();
        let mut x = fmu.initial_state().unwrap();
        let mut ours = Vec::new();
        for (k, u) in inputs.iter().enumerate() {
            fmu.do_step(k as f64 * 1e-3, 1e-3, &[*u], &mut x).unwrap();
            ours.push(x.clone());
        }
        let script = r#"
import sys
from fmpy import read_model_description, extract
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
path, inputs = sys.argv[1], [float(v) for v in sys.stdin.read().split()]
md = read_model_description(path)
vr = {v.name: v.valueReference for v in md.modelVariables}
states = [vr['theta'], vr['theta_dot'], vr['wheel_speed']]
cls = FMU2Slave if md.fmiVersion.startswith('2') else FMU3Slave
fmu = cls(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier)
fmu.instantiate()
if md.fmiVersion.startswith('2'):
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode(); fmu.exitInitializationMode()
    get, set_ = fmu.getReal, fmu.setReal
else:
    fmu.enterInitializationMode(startTime=0.0); fmu.exitInitializationMode()
    get, set_ = fmu.getFloat64, fmu.setFloat64
for k, u in enumerate(inputs):
    set_([vr['current']], [u])
    fmu.doStep(currentCommunicationPoint=k * 1e-3, communicationStepSize=1e-3)
    print(' '.join(repr(v) for v in get(states)))
"#;
        let mut child = Command::new(&python)
            .args(["-c", script])
            .arg(&path)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let text: Vec<String> = inputs.iter().map(|u| format!("{u:?}")).collect();
        std::io::Write::write_all(&mut child.stdin.take().unwrap(), text.join("\n").as_bytes()).unwrap();
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "fmpy failed");
        let theirs: Vec<Vec<f64>> = String::from_utf8(out.stdout)
            .unwrap()
            .lines()
            .map(|l| l.split(' ').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert_eq!(theirs.len(), ours.len());
        // The same binary stepped with the same inputs: equal to the bit (the tolerance the FMU's
        // fixed-step solver allows is exactly zero).
        assert_eq!(ours, theirs, "{version:?}");
    }
}

/// A python3 with fmpy: target/fmu-tests/venv, made and filled by pip the first time.
fn fmpy_python() -> PathBuf {
    static PYTHON: OnceLock<PathBuf> = OnceLock::new();
    PYTHON
        .get_or_init(|| {
            let venv = work_dir().join("venv");
            let python = venv.join("bin/python3");
            let has_fmpy = |p: &Path| Command::new(p).args(["-c", "import fmpy"]).status().is_ok_and(|s| s.success());
            if !has_fmpy(&python) {
                let made = Command::new("python3").args(["-m", "venv"]).arg(&venv).status().unwrap();
                assert!(made.success(), "python3 -m venv failed");
                let pip = Command::new(venv.join("bin/pip")).args(["install", "-q", "fmpy"]).status().unwrap();
                assert!(pip.success(), "pip install fmpy failed");
            }
            python
        })
        .clone()
}

fn error(spec: &ModelSpec, path: &Path, kind: Option<FmiKind>) -> String {
    match load_as(spec, path, kind) {
        Ok(m) => panic!("{} loaded", m.describe()),
        Err(e) => e,
    }
}

#[test]
fn bad_input_is_one_line_naming_the_fmu_and_what_it_has() {
    let dir = tempfile::tempdir().unwrap();
    let fmu2 = pendulum_fmu(Version::Fmi2);
    let s = pendulum_spec();
    let cases: Vec<(String, &str)> = vec![
        (error(&s, &dir.path().join("missing.fmu"), None), "missing.fmu"),
        (
            {
                let bad = dir.path().join("corrupt.fmu");
                std::fs::write(&bad, b"not a zip").unwrap();
                error(&s, &bad, None)
            },
            "not an FMU (a zip archive)",
        ),
        (
            {
                // The same FMU with its binary moved to another platform's folder.
                let other = dir.path().join("windows.fmu");
                let mut zip = zip::ZipWriter::new(std::fs::File::create(&other).unwrap());
                let mut from = zip::ZipArchive::new(std::fs::File::open(&fmu2).unwrap()).unwrap();
                let options = zip::write::SimpleFileOptions::default();
                zip.start_file("modelDescription.xml", options).unwrap();
                std::io::copy(&mut from.by_name("modelDescription.xml").unwrap(), &mut zip).unwrap();
                zip.start_file("binaries/win64/pendulum.dll", options).unwrap();
                zip.finish().unwrap();
                error(&s, &other, None)
            },
            "windows.fmu: no binary for this platform (linux64); the FMU has binaries for: win64",
        ),
        (
            error(&spec(&["theta", "theta_dot", "wheel"]), &fmu2, None),
            "has no continuous state \"wheel\" ([system] state); its continuous states: theta, theta_dot, wheel_speed",
        ),
        (
            error(&spec(&["theta", "theta_dot"]), &fmu2, None),
            "has 3 continuous states (theta, theta_dot, wheel_speed); [system] state declares 2",
        ),
        (
            {
                let mut s = pendulum_spec();
                s.input = vec!["torque".into()];
                error(&s, &fmu2, None)
            },
            "has no input \"torque\" ([system] input); its inputs: current",
        ),
        (
            {
                let mut s = pendulum_spec();
                s.outputs = vec!["power".into()];
                error(&s, &pendulum_fmu(Version::Fmi3), Some(FmiKind::CoSimulation))
            },
            "has no output \"power\" ([system] outputs); its outputs: energy",
        ),
        (
            {
                let mut s = pendulum_spec();
                s.parameters = vec![("mass".into(), 1.0)];
                error(&s, &fmu2, None)
            },
            "pendulum-fmi2.fmu has no parameter \"mass\" ([plant.parameters]); its parameters: m_p, l_p",
        ),
        (
            {
                let mut s = pendulum_spec();
                s.parameters = vec![("substeps".into(), 2.5)];
                error(&s, &fmu2, None)
            },
            "pendulum-fmi2.fmu: parameter substeps is an integer, [plant.parameters] gives 2.5",
        ),
    ];
    for (message, expected) in cases {
        assert!(message.contains(expected), "{message}\n  should say: {expected}");
        assert!(!message.contains('\n'), "{message}");
    }
    let platform = platform(Version::Fmi2);
    assert_eq!(platform, "linux64", "the tests' platform names are Linux x86-64's");
}

/// The plant's step cost per tick (1 kHz, 10 RK4 substeps), printed: the built-in pendulum, the
/// FMU in Model Exchange (LoopLab's RK4 over 40 derivative calls through the FMI functions) and in
/// Co-Simulation (one doStep). A measurement, not a check:
/// `cargo test --release -p looplab-shared --lib step_cost_per_tick -- --ignored --nocapture`.
#[test]
#[ignore]
fn step_cost_per_tick() {
    use crate::model::scenario::Plant;
    use crate::scenarios::pendulum::plant::PendulumPlant;
    const TICKS: u32 = 200_000;
    let time = |label: &str, f: &mut dyn FnMut(u32)| {
        (0..1000).for_each(&mut *f);
        let start = std::time::Instant::now();
        (0..TICKS).for_each(&mut *f);
        println!("{label}: {:.0} ns/tick", start.elapsed().as_nanos() as f64 / f64::from(TICKS));
    };
    let mut builtin = PendulumPlant::new(paper_model(), 10, Vector3::new(0.05, 0.0, 0.0));
    time("built-in pendulum", &mut |k| builtin.step(f64::from(k) * 1e-3, &[0.1], 1e-3).unwrap());
    for version in VERSIONS {
        let mut me = load(&pendulum_spec(), &pendulum_fmu(version)).unwrap();
        let mut x = me.initial_state().unwrap();
        let (mut k1, mut k2, mut k3, mut k4, mut tmp) = ([0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3], [0.0; 3]);
        time(&format!("{version:?} Model Exchange"), &mut |k| {
            let h = 1e-3 / 10.0;
            let t0 = f64::from(k) * 1e-3;
            for s in 0..10 {
                let t = t0 + f64::from(s) * h;
                me.derivative(t, &x, &[0.1], &mut k1).unwrap();
                (0..3).for_each(|i| tmp[i] = x[i] + k1[i] * (h / 2.0));
                me.derivative(t + h / 2.0, &tmp, &[0.1], &mut k2).unwrap();
                (0..3).for_each(|i| tmp[i] = x[i] + k2[i] * (h / 2.0));
                me.derivative(t + h / 2.0, &tmp, &[0.1], &mut k3).unwrap();
                (0..3).for_each(|i| tmp[i] = x[i] + k3[i] * h);
                me.derivative(t + h, &tmp, &[0.1], &mut k4).unwrap();
                (0..3).for_each(|i| x[i] += (k1[i] + k2[i] * 2.0 + k3[i] * 2.0 + k4[i]) * (h / 6.0));
            }
        });
        let mut cs = load_as(&pendulum_spec(), &pendulum_fmu(version), Some(FmiKind::CoSimulation)).unwrap();
        let mut x = cs.initial_state().unwrap();
        time(&format!("{version:?} Co-Simulation"), &mut |k| {
            cs.do_step(f64::from(k) * 1e-3, 1e-3, &[0.1], &mut x).unwrap()
        });
        let mut saved = 0;
        time(&format!("{version:?} Co-Simulation save (serialise)"), &mut |_| {
            saved = cs.freeze().unwrap().unwrap().len()
        });
        println!("{version:?} serialised state: {saved} bytes");
    }
}

/// An FMU unpacks into a folder only its process's user can enter, named after the process, its
/// files created new and private; the folder goes when the model does.
#[test]
fn an_fmu_unpacks_into_a_private_folder_of_its_process() {
    use std::os::unix::fs::PermissionsExt;
    let label = "pendulum-fmi2.fmu";
    let unpacked = archive::open(&pendulum_fmu(Version::Fmi2), label).unwrap().unpack(label).unwrap();
    let folder = unpacked.folder.path().to_path_buf();
    let name = folder.file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with(&format!("looplab-fmu-{}-", std::process::id())), "{name}");
    assert_eq!(folder.metadata().unwrap().permissions().mode() & 0o777, 0o700);
    let binary = unpacked.binary("pendulum");
    assert_eq!(binary.metadata().unwrap().permissions().mode() & 0o777, 0o600, "{}", binary.display());
    drop(unpacked);
    assert!(!folder.exists());
}
