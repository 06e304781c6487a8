//! The scenario interface: what a scenario gives the loop (a plant, an estimator, a controller,
//! metrics, an error measure) and the catalog entry that names it. A scenario's code implements
//! [`ScenarioParts`]; its entry states its vectors; the five processes and the monitor see the
//! two together as a [`Scenario`].

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use crate::config::launch::{LaunchConfig, LaunchError};
use crate::config::schema::{ScenarioSchema, names};
use crate::config::validate;
use crate::contract::msg::SensorReading;
use crate::model::figure::PaperFigures;
use crate::model::reference::Reference;
use crate::model::vectors::Vectors;

/// A scenario the launcher knows by name, with its default launch file compiled in (an entry of
/// a [`crate::model::catalog::Catalog`]).
#[derive(Clone)]
pub struct ScenarioEntry {
    pub name: &'static str,
    pub description: &'static str,
    /// The launch file in the repository that holds the defaults.
    pub file: &'static str,
    /// The defaults: a whole launch file whose `scenario` is this entry's name.
    pub text: &'static str,
    /// Its vectors, stated here only: the built scenario carries them ([`Scenario::vectors`]).
    pub vectors: &'static Vectors,
    /// The scenario's code, configured by a launch file checked against [`Self::schema`].
    pub build: fn(&LaunchConfig) -> Result<Box<dyn ScenarioParts>, LaunchError>,
    /// The figures of the paper behind it, reproduced (`looplab plot --paper`), if it has any.
    pub paper: Option<&'static PaperFigures>,
}

impl std::fmt::Debug for ScenarioEntry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name)
    }
}

impl ScenarioEntry {
    /// What a launch file for this scenario is checked against.
    pub fn schema(&self) -> ScenarioSchema {
        let v = self.vectors;
        ScenarioSchema {
            name: self.name,
            file: self.file,
            text: self.text,
            state: v.state,
            input: v.input,
            estimate: v.estimate,
            signals: v.signals.iter().map(|s| s.layout()).collect(),
        }
    }

    pub fn defaults(&self) -> toml::Table {
        self.schema().defaults()
    }

    /// The scenario `config` describes (checked against [`Self::schema`]), with this entry's
    /// vectors.
    pub fn build(&self, config: &LaunchConfig) -> Result<Box<dyn Scenario>, LaunchError> {
        let parts = (self.build)(config)?;
        Ok(Box::new(Configured { vectors: self.vectors, parts }))
    }
}

/// The most integration steps per loop period: more would only make a loop slower than its
/// period (and a huge count hangs the plant).
pub const MAX_SUBSTEPS: u32 = 1000;

/// An error unless `substeps` (at dotted `key`) is 1 to [`MAX_SUBSTEPS`].
pub fn check_substeps(c: &LaunchConfig, key: &str, substeps: u32) -> Result<(), LaunchError> {
    validate::in_range(c, key, substeps, 1..=MAX_SUBSTEPS, "integration steps per loop")
}

/// What a scenario's code builds from a launch file: its title, limits and the factories of its
/// loop stages. Its vectors are its entry's ([`ScenarioEntry::build`] pairs the two).
pub trait ScenarioParts: Send + Sync {
    /// One line for reports, for example "reaction-wheel pendulum, bias-observer".
    fn title(&self) -> String;
    /// The closed range of each input the actuator accepts; the plant rejects anything else.
    fn input_limits(&self) -> Vec<(f64, f64)>;
    fn plant(&self) -> Box<dyn Plant>;
    fn estimator(&self) -> Box<dyn Estimator>;
    fn controller(&self) -> Box<dyn Controller>;
    fn metrics(&self) -> Box<dyn Metrics>;
    /// How fault reports judge the physical system.
    fn error_measure(&self) -> ErrorMeasure;
    /// The loop's delay margin from the linearised model: the smallest extra controller delay,
    /// in ticks, at which the sampled loop is unstable. None if the scenario has no such model.
    fn delay_margin(&self, _config: &LaunchConfig) -> Option<TheoreticalMargin> {
        None
    }
}

/// A configured scenario as the loop sees it: its parts and its entry's vectors (made by
/// [`ScenarioEntry::build`]).
pub trait Scenario: ScenarioParts {
    /// Names, units and sizes of its vectors: its entry's.
    fn vectors(&self) -> &'static Vectors;
    fn state_names(&self) -> Vec<&'static str> {
        names(self.vectors().state)
    }
    fn input_names(&self) -> Vec<&'static str> {
        names(self.vectors().input)
    }
    fn estimate_names(&self) -> Vec<&'static str> {
        names(self.vectors().estimate)
    }
}

/// A scenario's parts with its entry's vectors.
struct Configured {
    vectors: &'static Vectors,
    parts: Box<dyn ScenarioParts>,
}

impl Scenario for Configured {
    fn vectors(&self) -> &'static Vectors {
        self.vectors
    }
}

/// Every method forwards, the provided ones too: a default here would hide the scenario's own.
impl ScenarioParts for Configured {
    fn title(&self) -> String {
        self.parts.title()
    }
    fn input_limits(&self) -> Vec<(f64, f64)> {
        self.parts.input_limits()
    }
    fn plant(&self) -> Box<dyn Plant> {
        self.parts.plant()
    }
    fn estimator(&self) -> Box<dyn Estimator> {
        self.parts.estimator()
    }
    fn controller(&self) -> Box<dyn Controller> {
        self.parts.controller()
    }
    fn metrics(&self) -> Box<dyn Metrics> {
        self.parts.metrics()
    }
    fn error_measure(&self) -> ErrorMeasure {
        self.parts.error_measure()
    }
    fn delay_margin(&self, config: &LaunchConfig) -> Option<TheoreticalMargin> {
        self.parts.delay_margin(config)
    }
}

/// A delay margin from theory, for `looplab sweep` to print next to the measured one.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct TheoreticalMargin {
    /// Exact, from the spectral radius of the linearised sampled loop.
    pub ticks: u32,
    /// Continuous-time estimate: phase margin over crossover frequency, in ticks (NaN for a
    /// declared linear loop, whose margin comes from its sampled loop gain).
    pub continuous_ticks: f64,
    /// The same with the delays that sampling adds on each path (command hold, sensor holds); a
    /// declared linear loop's: the sampled loop gain's phase margin over its crossover, exact.
    pub lagged_ticks: f64,
    pub crossover_rad_s: f64,
    pub phase_margin_deg: f64,
    /// Per-tick spectral radius one tick below the margin and at it.
    pub radius_before: f64,
    pub radius_at_margin: f64,
}

/// The error at simulation time t in true state x.
pub type ErrorOfState = Arc<dyn Fn(f64, &[f64]) -> f64 + Send + Sync>;

/// How far the physical system is from where it should be, for fault reports and the run's
/// verdict: the worst value during and after a fault, the band it must come back within
/// (recovery), the limit it must never pass (for the pendulum: the angle at which it has
/// fallen), and where it has one, the point of no return past which the run is lost.
#[derive(Clone)]
pub struct ErrorMeasure {
    pub name: &'static str,
    pub of_state: ErrorOfState,
    pub recovery_band: f64,
    pub limit: f64,
    /// The launch-file key of `limit`, for the verdict ("limits.fall_angle_rad").
    pub limit_key: &'static str,
    /// An error at or beyond which the system cannot come back, and what that means in words.
    /// None: the scenario has no such point (the run is lost only if it ends beyond the limit).
    pub lost_beyond: Option<(f64, &'static str)>,
    /// The verdict judges loops from this simulation time on, s (a step's transient before it
    /// is not a limit's concern); 0: every loop.
    pub judged_from_s: f64,
}

impl ErrorMeasure {
    /// Whether `error` is beyond the limit ([`crate::contract::limits::beyond`]: NaN is).
    pub fn beyond(&self, error: f64) -> bool {
        crate::contract::limits::beyond(error, self.limit)
    }

    /// Whether `error` is outside the band it must come back within (NaN is).
    pub fn outside_band(&self, error: f64) -> bool {
        crate::contract::limits::beyond(error, self.recovery_band)
    }

    /// The error of the scenario's reference ([`Reference::error`]), so that fault reports
    /// judge against what the controller tracks.
    pub fn of_reference<R: Reference + 'static>(
        name: &'static str,
        reference: R,
        recovery_band: f64,
        limit: f64,
    ) -> Self {
        let reference = Mutex::new(reference);
        ErrorMeasure {
            name,
            of_state: Arc::new(move |t, x| reference.lock().expect("reference lock").error(t, x)),
            recovery_band,
            limit,
            limit_key: "limits",
            lost_beyond: None,
            judged_from_s: 0.0,
        }
    }

    /// With `limit` named by its launch-file key.
    pub fn keyed(mut self, limit_key: &'static str) -> Self {
        self.limit_key = limit_key;
        self
    }

    /// With a point of no return: an error of `value` or more, which `meaning` explains.
    pub fn lost_beyond(mut self, value: f64, meaning: &'static str) -> Self {
        self.lost_beyond = Some((value, meaning));
        self
    }

    pub fn describe(&self) -> ErrorMeasureInfo {
        ErrorMeasureInfo {
            name: self.name.into(),
            recovery_band: self.recovery_band,
            limit: self.limit,
            limit_key: self.limit_key.into(),
            lost_beyond: self.lost_beyond.map(|(value, _)| value),
            lost_means: self.lost_beyond.map(|(_, meaning)| meaning.into()),
            judged_from_s: self.judged_from_s,
        }
    }
}

/// An [`ErrorMeasure`] as `summary.json` writes it.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize, PartialEq, schemars::JsonSchema)]
pub struct ErrorMeasureInfo {
    pub name: String,
    pub recovery_band: f64,
    pub limit: f64,
    /// The launch-file key of `limit`.
    #[serde(default)]
    pub limit_key: String,
    /// The point of no return, if the scenario has one: an error this large loses the run.
    #[serde(default)]
    pub lost_beyond: Option<f64>,
    /// What passing it means, in words.
    #[serde(default)]
    pub lost_means: Option<String>,
    /// The verdict judged loops from this simulation time on, s (`[limits] judge_from_s`).
    #[serde(default)]
    pub judged_from_s: f64,
}

/// `[limits]` of a vehicle's launch file: how fault reports judge its flight by the distance
/// from the reference (see [`ErrorMeasure`]).
#[derive(Debug, Clone, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PositionLimits {
    /// The distance beyond which the vehicle counts as lost, m.
    pub position_error_limit_m: f64,
    /// The distance within which it counts as recovered, m.
    pub recovery_band_m: f64,
}

impl PositionLimits {
    /// The `[limits]` section, both distances positive.
    pub fn load(c: &LaunchConfig) -> Result<Self, LaunchError> {
        let limits: PositionLimits = c.section("limits")?;
        validate::positive(c, "limits.position_error_limit_m", limits.position_error_limit_m)?;
        validate::positive(c, "limits.recovery_band_m", limits.recovery_band_m)?;
        Ok(limits)
    }

    /// The error measure of `reference`, named `name`, judged by these limits.
    pub fn error_measure<R: Reference + 'static>(&self, name: &'static str, reference: R) -> ErrorMeasure {
        ErrorMeasure::of_reference(name, reference, self.recovery_band_m, self.position_error_limit_m)
            .keyed("limits.position_error_limit_m")
    }
}

/// The physical model: the truth.
pub trait Plant {
    fn state(&self) -> &[f64];
    /// Advances one loop period from simulation time `t` with the input held constant
    /// (zero-order hold). An error (a plant model of the user's own that failed) ends the
    /// plant's incarnation with its one line.
    fn step(&mut self, t: f64, u: &[f64], dt: f64) -> anyhow::Result<()>;
    /// Sets the state, for a restarted plant going on from its snapshot.
    fn restore(&mut self, state: &[f64]);
    /// The model's own whole state beyond the state vector (an FMU's serialisation), frozen
    /// beside the snapshot after every tick; None: the state vector is all there is to keep.
    fn freeze(&mut self) -> anyhow::Result<Option<Vec<u8>>> {
        Ok(None)
    }
    /// After [`Plant::restore`]: goes on from what [`Plant::freeze`] returned.
    fn thaw(&mut self, _frozen: &[u8]) -> anyhow::Result<()> {
        Ok(())
    }
    /// What the actuator applied over the last step, where it differs from the command (a
    /// command link that samples the commands): the estimator predicts with it.
    fn applied_input(&self) -> Option<&[f64]> {
        None
    }
    /// What the actuator holds before the first command arrives, for a system that starts in
    /// motion (a vehicle in flight keeps its motors running). None: zero.
    fn initial_input(&self) -> Option<&[f64]> {
        None
    }
    /// Whether the state of tick k goes out marked lost (a replay's recorded plant, for a tick
    /// its recording has no state of), so that the stages skip it.
    fn withheld(&self, _k: u64) -> bool {
        false
    }
}

pub trait Estimator {
    /// Takes every sensor's held reading at simulation time `t` and the input the actuator
    /// applied over the last interval; writes the estimate.
    fn update(&mut self, t: f64, readings: &[SensorReading], u_applied: &[f64], estimate: &mut [f64]);
    /// States worth keeping across a restart, such as a calibrated sensor bias (the fast ones
    /// may start again from the current measurements), frozen after each update with
    /// [`freeze_value`]. None: nothing to keep (yet).
    fn freeze(&self) -> Option<Vec<u8>> {
        None
    }
    /// A restarted estimator gets its predecessor's frozen state before its first update
    /// ([`thaw_value`] decodes it).
    fn thaw(&mut self, _frozen: &[u8]) -> anyhow::Result<()> {
        Ok(())
    }
}

pub trait Controller {
    fn update(&mut self, t: f64, estimate: &[f64], command: &mut [f64]);
    /// Its state between updates (integrators, filters, the previous time), frozen after each
    /// update with [`freeze_value`] so that a restarted controller goes on where this one
    /// stopped. None: a static law, nothing to keep.
    fn freeze(&self) -> Option<Vec<u8>> {
        None
    }
    /// A restarted controller gets its predecessor's frozen state before its first update.
    fn thaw(&mut self, _frozen: &[u8]) -> anyhow::Result<()> {
        Ok(())
    }
}

/// One loop as the monitor joined it, for the scenario's metrics.
pub struct Row<'a> {
    pub k: u64,
    pub t: f64,
    pub state: &'a [f64],
    pub readings: &'a [SensorReading],
    pub estimate: &'a [f64],
    pub command: &'a [f64],
    /// What the actuator applied over the period that ended at tick k.
    pub applied: &'a [f64],
}

/// The scenario's control metrics, fed every loop in order.
pub trait Metrics: Send {
    fn observe(&mut self, row: &Row);
    fn finish(&self) -> BTreeMap<String, f64>;
    /// Findings the numbers alone do not say.
    fn notes(&self) -> Vec<String> {
        Vec::new()
    }
    /// What has been observed so far, for a restarted monitor to go on from ([`Metrics::thaw`]).
    /// None (the default): these metrics cannot be carried over, and a restarted monitor's
    /// cover only the loops it saw. [`freeze_value`] and [`thaw_value`] do the encoding.
    fn freeze(&self) -> Option<Vec<u8>> {
        None
    }
    /// Goes on from what [`Metrics::freeze`] returned (into metrics made fresh for the same run).
    fn thaw(&mut self, _frozen: &[u8]) -> anyhow::Result<()> {
        Err(anyhow::anyhow!("these metrics cannot be carried over a monitor restart"))
    }
}

/// `freeze` and `thaw` of [`Metrics`] for the listed fields (what `observe` changes; the rest
/// comes from the launch file): each field encoded on its own, so any number of them, and
/// every f64 exactly, NaN included.
#[macro_export]
macro_rules! frozen_fields {
    ($($field:ident),+ $(,)?) => {
        fn freeze(&self) -> Option<Vec<u8>> {
            let fields: Vec<Vec<u8>> = vec![$($crate::model::scenario::freeze_value(&self.$field)),+];
            Some($crate::model::scenario::freeze_value(&fields))
        }
        fn thaw(&mut self, frozen: &[u8]) -> anyhow::Result<()> {
            let fields: Vec<Vec<u8>> = $crate::model::scenario::thaw_value(frozen)?;
            let mut fields = fields.iter();
            $(self.$field = $crate::model::scenario::thaw_value(
                fields.next().ok_or_else(|| anyhow::anyhow!("frozen metrics: too few fields"))?,
            )?;)+
            Ok(())
        }
    };
}

/// One value as bytes: the one encoding of frozen state (an estimator's, a controller's, the
/// metrics'), exact for every f64, NaN included.
pub fn freeze_value<T: serde::Serialize>(value: &T) -> Vec<u8> {
    crate::contract::codec::to_bytes(value).expect("plain data encodes")
}

/// A value from [`freeze_value`]'s bytes; an error where they are not one.
pub fn thaw_value<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> anyhow::Result<T> {
    crate::contract::codec::decode(bytes)
}
