//! The declared system's metrics and error measure against values worked out by hand.

use super::*;
use crate::config::launch::LaunchConfig;
use crate::contract::limits::LimitsWatch;
use crate::contract::msg::SensorReading;

fn strings(names: &[&str]) -> Vec<String> {
    names.iter().map(|n| n.to_string()).collect()
}

/// A launch configuration whose document carries `sections` (TOML), on top of a built-in
/// scenario's (the metrics read only their own sections).
fn config(sections: &str) -> LaunchConfig {
    let (mut c, _) = crate::scenarios::resolve("pendulum", &[]).unwrap();
    c.document.remove("limits");
    let extra: toml::Table = toml::from_str(sections).unwrap();
    c.document.extend(extra);
    c
}

struct System {
    state: Vec<String>,
    outputs: Vec<String>,
    input: Vec<String>,
    units: Vec<String>,
}

impl System {
    /// state (x, v), output y, input u.
    fn new() -> Self {
        System {
            state: strings(&["x", "v"]),
            outputs: strings(&["y"]),
            input: strings(&["u"]),
            units: strings(&["m", "m/s", "N"]),
        }
    }
    fn declared(&self) -> Declared<'_> {
        Declared { state: &self.state, outputs: &self.outputs, input: &self.input, units: &self.units }
    }
    fn load(&self, sections: &str) -> Result<DeclaredMeasures, LaunchError> {
        DeclaredMeasures::load(&config(sections), self.declared())
    }
}

/// Feeds loops `ks` of `n` per second: state (x, v) and output y from `state(t)` (state message
/// order: x, v, y), applied input `input(t)`.
fn feed(
    metrics: &mut dyn Metrics,
    n: u64,
    ks: std::ops::Range<u64>,
    state: impl Fn(f64) -> [f64; 3],
    input: impl Fn(f64) -> f64,
) {
    let readings = [SensorReading::default()];
    for k in ks {
        let t = k as f64 / n as f64;
        let (x, u) = (state(t), [input(t)]);
        metrics.observe(&Row { k, t, state: &x, readings: &readings, estimate: &[], command: &u, applied: &u });
    }
}

const LIMITS: &str = "[limits]\nof = [\"state.x\"]\nerror_limit = 0.5\nrecovery_band = 0.1\n";

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(1.0)
}

/// x = sin 2πt over one whole period sampled N times: RMS √½ (Σ sin² = N/2 for N > 2), max 1
/// (N a multiple of 4); constants: their own value; every component keyed by its path.
#[test]
fn per_component_final_max_and_rms_are_the_analytic_ones() {
    let sys = System::new();
    let mut m = sys.load(LIMITS).unwrap().metrics();
    let n = 1000;
    let tau = std::f64::consts::TAU;
    feed(m.as_mut(), n, 0..n, |t| [(tau * t).sin(), -3.0, 2.0 * t], |_| 0.25);
    let r = m.finish();
    let last_t = (n - 1) as f64 / n as f64;
    assert!(close(r["state.x.rms"], 0.5f64.sqrt()), "{}", r["state.x.rms"]);
    assert!(close(r["state.x.max_abs"], 1.0));
    assert_eq!(r["state.x.final"], (tau * last_t).sin());
    assert_eq!((r["state.v.rms"], r["state.v.max_abs"], r["state.v.final"]), (3.0, 3.0, -3.0));
    // y = 2t: Σ (2k/N)² / N = 4 (N−1)(2N−1) / (6 N²).
    let nf = n as f64;
    assert!(close(r["output.y.rms"], (4.0 * (nf - 1.0) * (2.0 * nf - 1.0) / (6.0 * nf * nf)).sqrt()));
    assert!(close(r["output.y.max_abs"], 2.0 * last_t));
    assert_eq!((r["input.u.rms"], r["input.u.max_abs"], r["input.u.final"]), (0.25, 0.25, 0.25));
    assert_eq!(r.len(), 4 * 3, "{r:?}");
}

/// y = 2t tracks the table r = t (linear): e = t, RMS √((N−1)(2N−1)/(6N²)); x = 1 tracks the
/// expression r = 1 − t/2: e = t/2.
#[test]
fn tracking_errors_against_a_table_and_an_expression_are_the_analytic_ones() {
    let sys = System::new();
    let sections = format!(
        "{LIMITS}\n[[reference]]\ntrack = \"output.y\"\ntable = [[0.0, 0.0], [1.0, 1.0]]\n\n\
         [[reference]]\ntrack = \"state.x\"\nexpression = \"1 - t/2\"\n"
    );
    let mut m = sys.load(&sections).unwrap().metrics();
    let n = 400;
    feed(m.as_mut(), n, 0..n, |t| [1.0, 0.0, 2.0 * t], |_| 0.0);
    let r = m.finish();
    let (nf, last_t) = (n as f64, (n - 1) as f64 / n as f64);
    let rms_t = ((nf - 1.0) * (2.0 * nf - 1.0) / (6.0 * nf * nf)).sqrt();
    assert!(close(r["tracking.output.y.rms"], rms_t));
    assert!(close(r["tracking.output.y.max_abs"], last_t));
    assert!(close(r["tracking.output.y.final"], last_t));
    assert!(close(r["tracking.state.x.rms"], rms_t / 2.0));
    assert!(close(r["tracking.state.x.final"], last_t / 2.0));
    assert!(m.notes().is_empty(), "{:?}", m.notes());
}

#[test]
fn a_table_that_ends_before_the_run_says_so() {
    let sys = System::new();
    let sections = format!("{LIMITS}\n[[reference]]\ntrack = \"state.v\"\ntable = [[0.0, 1.0]]\nbetween = \"hold\"\n");
    let mut m = sys.load(&sections).unwrap().metrics();
    feed(m.as_mut(), 10, 0..20, |_| [0.0, 1.0, 0.0], |_| 0.0);
    assert_eq!(m.finish()["tracking.state.v.max_abs"], 0.0);
    let notes = m.notes();
    assert!(notes.len() == 1 && notes[0].contains("ends at t = 0 s"), "{notes:?}");
}

/// A monitor restarted half way goes on from the frozen metrics: every value bit for bit.
#[test]
fn metrics_go_on_after_a_freeze_and_thaw_as_if_never_stopped() {
    let sys = System::new();
    let sections = format!("{LIMITS}\n[[reference]]\ntrack = \"output.y\"\nexpression = \"sin(t)\"\n");
    let measures = sys.load(&sections).unwrap();
    let state = |t: f64| [(3.0 * t).cos(), t.sin() * 0.1, t * t];
    let input = |t: f64| (7.0 * t).sin();
    let mut whole = measures.metrics();
    feed(whole.as_mut(), 100, 0..300, state, input);
    let mut before = measures.metrics();
    feed(before.as_mut(), 100, 0..137, state, input);
    let mut after = measures.metrics();
    after.thaw(&before.freeze().unwrap()).unwrap();
    feed(after.as_mut(), 100, 137..300, state, input);
    let bits = |m: &dyn Metrics| m.finish().into_iter().map(|(k, v)| (k, v.to_bits())).collect::<Vec<_>>();
    assert_eq!(bits(after.as_ref()), bits(whole.as_ref()));
}

/// The error is the largest of |x − r| (with a reference) and |v| (without); the measure carries
/// the [limits] and its key; the verdict's watch sees it exceed and come back.
#[test]
fn the_error_measure_judges_the_named_components_against_their_references() {
    let sys = System::new();
    let sections = "[limits]\nof = [\"state.x\", \"state.v\"]\nerror_limit = 0.5\nrecovery_band = 0.1\n\
                    lost_beyond = 3.0\n\n\
                    [[reference]]\ntrack = \"state.x\"\nexpression = \"2*t\"\n";
    let measure = sys.load(sections).unwrap().error_measure();
    assert_eq!(measure.name, "max of |x − reference| m, |v| m/s");
    assert_eq!((measure.limit, measure.recovery_band, measure.limit_key), (0.5, 0.1, "limits.error_limit"));
    assert_eq!(measure.lost_beyond.map(|(v, _)| v), Some(3.0));
    let error = |t: f64, x: &[f64]| (measure.of_state)(t, x);
    assert_eq!(error(1.0, &[2.0, 0.0, 9.0]), 0.0);
    assert_eq!(error(1.0, &[2.25, -0.5, 9.0]), 0.5);
    assert_eq!(error(0.5, &[0.0, 0.125, 9.0]), 1.0);
    assert!(error(0.0, &[f64::NAN, 0.0, 0.0]).is_nan());
    let mut watch = LimitsWatch::default();
    for (t, x) in [(0.0, [0.0, 0.0]), (0.1, [0.2, 0.9]), (0.2, [0.4, 0.0])] {
        watch.observe(t, error(t, &x), measure.limit, None);
    }
    assert_eq!((watch.exceeded_at_s, watch.beyond_since_s, watch.worst), (Some(0.1), None, Some(0.9)));
}

/// With no `of`, the limits judge the components that have a reference; an output lies after
/// the state in the state message.
#[test]
fn the_limits_judge_the_tracked_components_by_default() {
    let sys = System::new();
    let sections = "[limits]\nerror_limit = 1.0\nrecovery_band = 0.1\n\n\
                    [[reference]]\ntrack = \"output.y\"\ntable = [[0.0, 1.0]]\n";
    let measure = sys.load(sections).unwrap().error_measure();
    assert_eq!(measure.name, "|y − reference| N");
    assert_eq!(measure.lost_beyond, None);
    assert_eq!((measure.of_state)(3.0, &[10.0, 10.0, 0.75]), 0.25);
}

/// No [limits]: every state component watched, nothing bounded, and a note that says so; a
/// single [reference] table is one reference.
#[test]
fn without_limits_nothing_is_judged_and_the_notes_say_so() {
    let sys = System::new();
    let measures = sys.load("[limits]\n\n[reference]\ntrack = \"state.v\"\nexpression = \"1\"\n").unwrap();
    let measure = measures.error_measure();
    assert_eq!((measure.limit, measure.recovery_band, measure.lost_beyond), (f64::MAX, f64::MAX, None));
    assert_eq!(measure.name, "|v − reference| m/s");
    let measure = sys.load("").unwrap().error_measure();
    assert_eq!(measure.name, "max of |x| m, |v| m/s");
    assert_eq!((measure.of_state)(0.0, &[-3.0, 2.0, 99.0]), 3.0);
    let mut m = sys.load("").unwrap().metrics();
    feed(m.as_mut(), 10, 0..3, |_| [0.0; 3], |_| 0.0);
    assert!(m.notes().iter().any(|n| n.contains("no [limits]")), "{:?}", m.notes());
}

/// The generic metrics alone, for a system with no [limits] read.
#[test]
fn generic_metrics_need_only_the_names() {
    let sys = System::new();
    let mut m = generic(sys.declared());
    feed(m.as_mut(), 10, 0..10, |_| [1.0, -2.0, 4.0], |_| -1.0);
    let r = m.finish();
    assert_eq!(
        (r["state.x.rms"], r["state.v.max_abs"], r["output.y.final"], r["input.u.final"]),
        (1.0, 2.0, 4.0, -1.0)
    );
}

#[test]
fn bad_limits_and_references_are_one_error_naming_the_key() {
    let sys = System::new();
    let error = |sections: &str| sys.load(sections).err().map(|e| e.to_string()).unwrap_or_default();
    let cases = [
        ("[limits]\nerror_limit = 1.0\nrecovery_band = 0.1\n", "key `limits.of`: name the components"),
        (
            "[limits]\nof = [\"state.q\"]\nerror_limit = 1.0\nrecovery_band = 0.1\n",
            "one of: state.x, state.v, output.y",
        ),
        ("[limits]\nof = [\"state.x\"]\nerror_limit = 1.0\nrecovery_band = 2.0\n", "key `limits.recovery_band`"),
        ("[limits]\nof = [\"state.x\"]\nerror_limit = -1.0\nrecovery_band = 0.1\n", "key `limits.error_limit`"),
        ("[limits]\nof = [\"state.x\"]\nerror_limit = 1.0\nrecovery_band = 0.1\nlost_beyond = 0.5\n", "lost_beyond"),
        (&format!("{LIMITS}[[reference]]\ntrack = \"input.u\"\nexpression = \"t\"\n"), "key `reference[0].track`"),
        (&format!("{LIMITS}[[reference]]\ntrack = \"state.x\"\n"), "key `reference[0]`: give exactly one of"),
        (&format!("{LIMITS}[reference]\ntrack = \"state.x\"\ntable = []\n"), "key `reference.table`: has no rows"),
        (&format!("{LIMITS}[[reference]]\ntrack = \"state.x\"\nexpression = \"q\"\n"), "key `reference[0].expression`"),
        (
            &format!("{LIMITS}[[reference]]\ntrack = \"state.x\"\nexpression = \"t\"\nbetween = \"hold\"\n"),
            "table only",
        ),
        (&format!("{LIMITS}[[reference]]\ntrack = \"state.x\"\ntable = [[1.0, 0.0], [0.5, 1.0]]\n"), "t must increase"),
        (
            &format!("{LIMITS}[[reference]]\ntrack = \"state.x\"\ntable = [[0.0, 0.0]]\nbetween = \"cubic\"\n"),
            "between",
        ),
        (&format!("{LIMITS}[[reference]]\ntrack = \"state.x\"\nexpression = \"t\"\nunit = 1\n"), "unit"),
    ];
    for (sections, want) in cases {
        let e = error(sections);
        assert!(e.contains(want), "{sections}\n→ {e:?}, wanted {want:?}");
    }
}
