//! The messages of the loop: fixed-size `#[repr(C)]` iceoryx2 payloads, with no heap inside.
//!
//! Every message starts with a [`Header`]: the loop index k (the plant tick the data derives
//! from), the simulation time of that tick, and the [`LoopTrace`] of CLOCK_MONOTONIC stamps
//! that travels with the data. Each stage copies the header of its input into its output and
//! adds its own receive and publish stamps; the plant adds the time the command reached it and
//! publishes the finished [`LoopRecord`], so one record holds the whole loop.
//!
//! Dimensions are upper bounds: every process reads the real ones from the launch file.

use iceoryx2::prelude::*;

use crate::contract::role::{Role, Topic};

/// Largest true-state vector a scenario may have.
pub const MAX_STATE: usize = 32;
/// Largest command vector.
pub const MAX_INPUT: usize = 8;
/// Largest number of sensors in one launch file.
pub const MAX_SENSORS: usize = 8;
/// Largest number of components one sensor may measure (paper 004's attitude sensor has 14).
pub const MAX_SENSOR_DIM: usize = 16;
/// Largest estimate vector.
pub const MAX_ESTIMATE: usize = 48;

/// Samples the monitor's reader of each topic holds: how far the monitor can fall behind
/// before it loses any (real-time mode); at 1 kHz that is a second of slack. The transport sizes
/// its buffers by it and the recorder its join window.
pub const MONITOR_BUFFER: usize = 1024;

/// CLOCK_MONOTONIC stamps (ns) of one loop, in the order the data passes. Zero means "not yet".
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("looplab::LoopTrace")]
#[repr(C)]
pub struct LoopTrace {
    pub plant_publish: u64,
    pub sensors_receive: u64,
    pub sensors_publish: u64,
    pub estimator_receive: u64,
    pub estimator_publish: u64,
    pub controller_receive: u64,
    pub controller_publish: u64,
    /// When the command of this loop reached the plant.
    pub plant_receive: u64,
}

/// One stamp of a [`LoopTrace`], in the order the data passes; its discriminant is its index in
/// [`LoopTrace::stamps`]. This is the one place that says which role sets which stamp.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stamp {
    /// The plant publishes the state of tick k.
    PlantPublish,
    SensorsReceive,
    SensorsPublish,
    EstimatorReceive,
    EstimatorPublish,
    ControllerReceive,
    ControllerPublish,
    /// The command of loop k reaches the plant.
    PlantReceive,
}

impl Stamp {
    /// Every stamp, in the order the data passes.
    pub const ALL: [Stamp; 8] = [
        Stamp::PlantPublish,
        Stamp::SensorsReceive,
        Stamp::SensorsPublish,
        Stamp::EstimatorReceive,
        Stamp::EstimatorPublish,
        Stamp::ControllerReceive,
        Stamp::ControllerPublish,
        Stamp::PlantReceive,
    ];

    /// Its index in [`LoopTrace::stamps`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Its name in `loops.csv` (without the `_ns` unit).
    pub fn name(self) -> &'static str {
        LoopTrace::STAMP_NAMES[self.index()]
    }

    /// The role that sets it.
    pub fn role(self) -> Role {
        match self {
            Stamp::PlantPublish | Stamp::PlantReceive => Role::Plant,
            Stamp::SensorsReceive | Stamp::SensorsPublish => Role::Sensors,
            Stamp::EstimatorReceive | Stamp::EstimatorPublish => Role::Estimator,
            Stamp::ControllerReceive | Stamp::ControllerPublish => Role::Controller,
        }
    }

    /// The stamp `role` sets when its input reaches it (for the plant: the command); None for
    /// the processes outside the loop.
    pub fn received_by(role: Role) -> Option<Stamp> {
        match role {
            Role::Plant => Some(Stamp::PlantReceive),
            Role::Sensors => Some(Stamp::SensorsReceive),
            Role::Estimator => Some(Stamp::EstimatorReceive),
            Role::Controller => Some(Stamp::ControllerReceive),
            Role::Monitor | Role::Bridge | Role::BridgeRemote => None,
        }
    }

    /// The stamp `role` sets when its output goes out (for the plant: the state).
    pub fn published_by(role: Role) -> Option<Stamp> {
        match role {
            Role::Plant => Some(Stamp::PlantPublish),
            Role::Sensors => Some(Stamp::SensorsPublish),
            Role::Estimator => Some(Stamp::EstimatorPublish),
            Role::Controller => Some(Stamp::ControllerPublish),
            Role::Monitor | Role::Bridge | Role::BridgeRemote => None,
        }
    }

    /// When a message on `topic` went out: its writer's publish stamp. A loop record "goes out"
    /// when the plant takes the command it records.
    pub fn sent_on(topic: Topic) -> Stamp {
        match topic {
            Topic::Loop => Stamp::PlantReceive,
            Topic::State => Stamp::PlantPublish,
            Topic::Measurements => Stamp::SensorsPublish,
            Topic::Estimate => Stamp::EstimatorPublish,
            Topic::Command => Stamp::ControllerPublish,
        }
    }
}

impl LoopTrace {
    /// The stamps in the order the data passes, named as in `loops.csv`.
    pub const STAMP_NAMES: [&'static str; 8] = [
        "plant_publish",
        "sensors_receive",
        "sensors_publish",
        "estimator_receive",
        "estimator_publish",
        "controller_receive",
        "controller_publish",
        "plant_receive",
    ];

    /// The value of one stamp (0: not yet).
    pub fn get(&self, stamp: Stamp) -> u64 {
        *self.slot(stamp)
    }

    fn slot(&self, stamp: Stamp) -> &u64 {
        match stamp {
            Stamp::PlantPublish => &self.plant_publish,
            Stamp::SensorsReceive => &self.sensors_receive,
            Stamp::SensorsPublish => &self.sensors_publish,
            Stamp::EstimatorReceive => &self.estimator_receive,
            Stamp::EstimatorPublish => &self.estimator_publish,
            Stamp::ControllerReceive => &self.controller_receive,
            Stamp::ControllerPublish => &self.controller_publish,
            Stamp::PlantReceive => &self.plant_receive,
        }
    }

    fn slot_mut(&mut self, stamp: Stamp) -> &mut u64 {
        match stamp {
            Stamp::PlantPublish => &mut self.plant_publish,
            Stamp::SensorsReceive => &mut self.sensors_receive,
            Stamp::SensorsPublish => &mut self.sensors_publish,
            Stamp::EstimatorReceive => &mut self.estimator_receive,
            Stamp::EstimatorPublish => &mut self.estimator_publish,
            Stamp::ControllerReceive => &mut self.controller_receive,
            Stamp::ControllerPublish => &mut self.controller_publish,
            Stamp::PlantReceive => &mut self.plant_receive,
        }
    }

    /// Sets the stamp `role` takes when its input reaches it, at `ns`.
    pub fn stamp_received(&mut self, role: Role, ns: u64) {
        let stamp = Stamp::received_by(role).expect("only the loop's processes stamp the trace");
        *self.slot_mut(stamp) = ns;
    }

    /// Sets the stamp `role` takes when its output goes out, at `ns`.
    pub fn stamp_published(&mut self, role: Role, ns: u64) {
        let stamp = Stamp::published_by(role).expect("only the loop's processes stamp the trace");
        *self.slot_mut(stamp) = ns;
    }

    /// Sets the receive and publish stamps of a stage, which has both on one message (the
    /// plant's two are on different messages: it sets each where it happens).
    pub fn stamp(&mut self, role: Role, received: u64, published: u64) {
        self.stamp_received(role, received);
        self.stamp_published(role, published);
    }

    /// From `from` to `to`, ns (0 if `to` is not later, or either is not stamped yet: a
    /// stamp of 0 is earlier than any other).
    pub fn between_ns(&self, from: Stamp, to: Stamp) -> u64 {
        self.get(to).saturating_sub(self.get(from))
    }

    /// The whole loop: the plant publishes the state, and the command derived from it reaches
    /// the plant.
    pub fn end_to_end_ns(&self) -> u64 {
        self.between_ns(Stamp::PlantPublish, Stamp::PlantReceive)
    }

    /// The stamps in [`Stamp`] order.
    pub fn stamps(&self) -> [u64; 8] {
        Stamp::ALL.map(|s| self.get(s))
    }

    /// The inverse of [`LoopTrace::stamps`] (a trace read back from loops.csv).
    pub fn from_stamps(s: [u64; 8]) -> Self {
        let mut trace = LoopTrace::default();
        for (stamp, ns) in Stamp::ALL.into_iter().zip(s) {
            *trace.slot_mut(stamp) = ns;
        }
        trace
    }
}

/// What the writer of a message knows of its own scheduling for this loop (`runtime::stage::sched`):
/// how long its thread sat on the run queue, runnable while another task had its CPU. Each loop
/// process sets its own on what it sends (the plant: on the state, for the tick's wake-up, and on
/// the loop record, for the command's), so the monitor reads each role's from that role's message.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("looplab::SchedStamp")]
#[repr(C)]
pub struct SchedStamp {
    /// Run-queue time from its last read to its input's arrival (a stage: the wait before it got
    /// the CPU for this input; the plant: before it woke for this tick or this command), ns.
    pub queued_ns: u32,
    /// Run-queue time while it computed this loop's output, ns: read only when the computation
    /// took over `runtime::stage::sched::COMPUTE_READ_NS`, else 0 (it then counts in the next wait).
    pub compute_queued_ns: u32,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("looplab::Header")]
#[repr(C)]
pub struct Header {
    /// Loop index: the plant tick this data derives from.
    pub k: u64,
    /// Simulation time of tick k, in seconds.
    pub t: f64,
    pub trace: LoopTrace,
    /// Which incarnation of the plant, sensors, estimator and controller (0 before the first
    /// restart) handled this loop, so that downstream stages and the monitor see a restart in
    /// the data itself.
    pub incarnations: [u32; 4],
    /// 1 if an upstream stage dropped this loop's output (a `drop` fault in lockstep mode): the
    /// message only carries the loop on; stages pass it through and the plant holds its command.
    pub lost: u32,
    pub _reserved: u32,
    /// The writer's own scheduling in this loop.
    pub sched: SchedStamp,
}

impl Header {
    /// Marks this loop as handled by `incarnation` of `role`, in the role's slot of
    /// `incarnations`.
    pub fn set_incarnation(&mut self, role: Role, incarnation: u32) {
        let slot = role.slot().expect("only the loop's processes carry an incarnation");
        self.incarnations[slot] = incarnation;
    }
}

/// How the plant's clock behaved at the tick that produced a state (real-time mode only;
/// all zero in lockstep mode).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("looplab::TickTiming")]
#[repr(C)]
pub struct TickTiming {
    /// When the tick was due: start + k·dt.
    pub scheduled_ns: u64,
    /// When the plant woke for it.
    pub wake_ns: u64,
    /// Time since the previous tick's wake-up (0 for the first tick).
    pub period_ns: u64,
}

/// Running totals kept by the plant, sent with every state so that the last state seen tells
/// the monitor where the run stands.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend, serde::Serialize, serde::Deserialize)]
#[type_name("looplab::PlantCounters")]
#[repr(C)]
pub struct PlantCounters {
    /// Loops whose command had not reached the plant when tick k+1 was due (real-time mode).
    pub deadline_misses: u64,
    /// Commands rejected as non-finite or out of range (the last valid one is held).
    pub rejected_commands: u64,
    /// Timer periods that passed with no wake-up at all (the plant process was held up, or
    /// dead: the ticks it missed are integrated when it comes back).
    pub skipped_ticks: u64,
    /// Ticks integrated with `on_stale` applied: the newest command was older than the
    /// command timeout (real-time mode).
    pub stale_ticks: u64,
    /// Commands that arrived marked lost (lockstep `drop` faults); the last command was held.
    pub lost_commands: u64,
}

/// The true state of the plant at tick k, published once per tick.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("looplab::PlantState")]
#[repr(C)]
pub struct PlantState {
    pub header: Header,
    pub x: [f64; MAX_STATE],
    /// The command the actuator actually applied over the last interval, as a motor
    /// controller reports it; the estimator uses it to predict.
    pub u_applied: [f64; MAX_INPUT],
    pub timing: TickTiming,
    pub counters: PlantCounters,
}

/// One sensor's current (held) value.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("looplab::SensorReading")]
#[repr(C)]
pub struct SensorReading {
    pub value: [f64; MAX_SENSOR_DIM],
    /// Simulation time at which the truth behind this value was sampled.
    pub sample_time: f64,
    /// Number of samples this sensor has delivered before this one (0 for the first).
    pub seq: u64,
    /// 1 if this value was delivered at this tick, 0 if it is held from an earlier tick.
    pub fresh: u32,
    /// 0 until the sensor's first sample has arrived (transport delay).
    pub valid: u32,
}

/// Every sensor's held value at tick k, in the launch file's sensor order (sorted by name).
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("looplab::Measurements")]
#[repr(C)]
pub struct Measurements {
    pub header: Header,
    pub readings: [SensorReading; MAX_SENSORS],
    /// The actuator's report of the command applied over the last interval.
    pub u_applied: [f64; MAX_INPUT],
}

#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("looplab::Estimate")]
#[repr(C)]
pub struct Estimate {
    pub header: Header,
    pub x: [f64; MAX_ESTIMATE],
}

#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("looplab::Command")]
#[repr(C)]
pub struct Command {
    pub header: Header,
    pub u: [f64; MAX_INPUT],
}

/// A finished loop, published by the plant when the command of loop k reaches it.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("looplab::LoopRecord")]
#[repr(C)]
pub struct LoopRecord {
    pub header: Header,
    /// 1 if the command reached the plant after tick k+1 was due (real-time mode); it then
    /// takes effect one period later, if it is still the newest.
    pub deadline_miss: u32,
    /// 1 if the plant rejected the command (non-finite or out of range).
    pub rejected: u32,
    /// 1 if the command arrived marked lost (lockstep `drop` fault); the plant held its last.
    pub lost: u32,
    pub _reserved: u32,
    /// 1 for the plant's first loop record of the run, then one more per record: a restarted
    /// monitor knows from its first record how many it never had the chance to receive.
    pub sequence: u64,
}

/// Every message of the loop carries the loop header.
pub trait Message: Copy + Default + std::fmt::Debug + ZeroCopySend + 'static {
    fn header(&self) -> &Header;
    fn header_mut(&mut self) -> &mut Header;
}

macro_rules! impl_message {
    ($($t:ty),*) => {$(
        impl Message for $t {
            fn header(&self) -> &Header { &self.header }
            fn header_mut(&mut self) -> &mut Header { &mut self.header }
        }
    )*};
}
impl_message!(PlantState, Measurements, Estimate, Command, LoopRecord);

/// Any message of a loop, for whoever records them all (the monitor).
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy)]
pub enum LoopMessage {
    State(PlantState),
    Measurements(Measurements),
    Estimate(Estimate),
    Command(Command),
    Loop(LoopRecord),
}

impl LoopMessage {
    /// The loop it belongs to, and its topic.
    pub fn key(&self) -> (u64, Topic) {
        (self.header().k, self.topic())
    }

    /// The topic it came on.
    pub fn topic(&self) -> Topic {
        match self {
            LoopMessage::State(_) => Topic::State,
            LoopMessage::Measurements(_) => Topic::Measurements,
            LoopMessage::Estimate(_) => Topic::Estimate,
            LoopMessage::Command(_) => Topic::Command,
            LoopMessage::Loop(_) => Topic::Loop,
        }
    }

    pub fn header(&self) -> &Header {
        match self {
            LoopMessage::State(m) => &m.header,
            LoopMessage::Measurements(m) => &m.header,
            LoopMessage::Estimate(m) => &m.header,
            LoopMessage::Command(m) => &m.header,
            LoopMessage::Loop(m) => &m.header,
        }
    }

    /// When its sender published it (CLOCK_MONOTONIC, ns; 0 if not stamped): see
    /// [`Stamp::sent_on`].
    pub fn published_ns(&self) -> u64 {
        self.header().trace.get(Stamp::sent_on(self.topic()))
    }
}

/// All-zero values: every message is plain numbers, so zero is a valid starting point.
macro_rules! zeroed_default {
    ($($t:ty),*) => {$(
        impl Default for $t {
            fn default() -> Self {
                // SAFETY: the type is `repr(C)` and made only of integers and floats, for
                // which the all-zero bit pattern is a valid value.
                unsafe { std::mem::zeroed() }
            }
        }
    )*};
}
zeroed_default!(PlantState, Measurements, Estimate, Command, LoopRecord);

/// What a process built with message layouts `ours` says when the run's are `theirs`.
pub fn layout_mismatch(what: &str, theirs: &str, ours: &str) -> String {
    format!(
        "{what} layout fingerprint {theirs}, this process was built with {ours}: build it from the same LoopLab as \
         the launcher (the Python package: pip install ./services/python)"
    )
}

/// The fingerprint of the message layouts: every message's size, alignment and field offsets,
/// the message limits and LoopLab's version, hashed. iceoryx2 0.10 checks a payload's type name,
/// size and alignment only, so two builds whose layouts differ inside the same size would
/// exchange garbage; every port requires this value as a service attribute (`runtime::transport::ipc`), and
/// a process from another build is refused when it connects.
pub fn layout_fingerprint() -> &'static str {
    static FINGERPRINT: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    FINGERPRINT.get_or_init(|| {
        use sha2::Digest;
        use std::fmt::Write;
        let mut layout = format!(
            "looplab {} limits state {MAX_STATE} input {MAX_INPUT} sensors {MAX_SENSORS} sensor_dim {MAX_SENSOR_DIM} \
             estimate {MAX_ESTIMATE}",
            env!("CARGO_PKG_VERSION")
        );
        macro_rules! describe {
            ($($t:ident { $($field:ident),* })*) => {$(
                let _ = write!(layout, "; {} {}/{}", stringify!($t), size_of::<$t>(), align_of::<$t>());
                $(let _ = write!(layout, " {}@{}", stringify!($field), std::mem::offset_of!($t, $field));)*
            )*};
        }
        describe! {
            LoopTrace { plant_publish, sensors_receive, sensors_publish, estimator_receive, estimator_publish,
                controller_receive, controller_publish, plant_receive }
            SchedStamp { queued_ns, compute_queued_ns }
            Header { k, t, trace, incarnations, lost, _reserved, sched }
            TickTiming { scheduled_ns, wake_ns, period_ns }
            PlantCounters { deadline_misses, rejected_commands, skipped_ticks, stale_ticks, lost_commands }
            PlantState { header, x, u_applied, timing, counters }
            SensorReading { value, sample_time, seq, fresh, valid }
            Measurements { header, readings, u_applied }
            Estimate { header, x }
            Command { header, u }
            LoopRecord { header, deadline_miss, rejected, lost, _reserved, sequence }
        }
        let digest = sha2::Sha256::digest(layout.as_bytes());
        digest[..8].iter().map(|b| format!("{b:02x}")).collect()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_are_fixed_size_and_small() {
        // Sizes are part of the contract between processes; a change here changes the wire
        // format (iceoryx2 also refuses mismatched layouts at connect time).
        assert_eq!(std::mem::size_of::<Header>(), 112);
        assert_eq!(std::mem::size_of::<PlantState>(), 112 + 8 * (MAX_STATE + MAX_INPUT) + 64);
        assert_eq!(std::mem::size_of::<SensorReading>(), 8 * MAX_SENSOR_DIM + 24);
        assert_eq!(std::mem::size_of::<Command>(), 112 + 8 * MAX_INPUT);
        assert_eq!(std::mem::size_of::<Measurements>(), 112 + MAX_SENSORS * (8 * MAX_SENSOR_DIM + 24) + 8 * MAX_INPUT);
        assert_eq!(std::mem::size_of::<Measurements>(), 1392);
    }

    #[test]
    fn trace_stamps_follow_the_data() {
        let trace = LoopTrace {
            plant_publish: 1,
            sensors_receive: 2,
            sensors_publish: 3,
            estimator_receive: 4,
            estimator_publish: 5,
            controller_receive: 6,
            controller_publish: 7,
            plant_receive: 8,
        };
        assert_eq!(trace.stamps(), [1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(LoopTrace::from_stamps(trace.stamps()), trace);
        for (i, stamp) in Stamp::ALL.into_iter().enumerate() {
            assert_eq!(stamp.index(), i);
            assert_eq!(trace.get(stamp), i as u64 + 1, "{stamp:?}");
        }
        assert_eq!(trace.end_to_end_ns(), 7);
        assert_eq!(trace.between_ns(Stamp::SensorsPublish, Stamp::EstimatorReceive), 1);
        assert_eq!(trace.between_ns(Stamp::PlantReceive, Stamp::PlantPublish), 0, "never negative");
    }

    #[test]
    fn each_loop_role_sets_its_own_receive_and_publish_stamps() {
        for role in Role::LOOP {
            let (received, published) = (Stamp::received_by(role).unwrap(), Stamp::published_by(role).unwrap());
            assert_eq!((received.role(), published.role()), (role, role));
            let mut trace = LoopTrace::default();
            trace.stamp_received(role, 10);
            trace.stamp_published(role, 20);
            let set: Vec<_> = Stamp::ALL.into_iter().filter(|&s| trace.get(s) != 0).collect();
            assert_eq!(set.len(), 2, "{role}: {set:?}");
            assert_eq!((trace.get(received), trace.get(published)), (10, 20), "{role}");
        }
        // Every stamp is set by exactly one loop role, and the stages stamp in flow order.
        for stamp in Stamp::ALL {
            let setters = Role::LOOP
                .iter()
                .filter(|&&r| Stamp::received_by(r) == Some(stamp) || Stamp::published_by(r) == Some(stamp))
                .count();
            assert_eq!(setters, 1, "{stamp:?}");
        }
        for role in Role::STAGES {
            assert!(Stamp::received_by(role) < Stamp::published_by(role), "{role}");
        }
        assert_eq!(Stamp::received_by(Role::Monitor), None);
        assert_eq!(Stamp::published_by(Role::Bridge), None);
        assert_eq!(Stamp::PlantReceive.name(), "plant_receive");
    }

    #[test]
    fn a_message_is_sent_when_its_writer_stamps_its_publish() {
        for role in Role::LOOP {
            let topic = role.output().unwrap();
            assert_eq!(Some(Stamp::sent_on(topic)), Stamp::published_by(role), "{topic}");
        }
        assert_eq!(Stamp::sent_on(Topic::Loop), Stamp::PlantReceive);
    }

    #[test]
    fn each_loop_role_writes_its_own_incarnation_slot() {
        let mut header = Header::default();
        for (n, role) in Role::LOOP.into_iter().enumerate() {
            header.set_incarnation(role, n as u32 + 1);
        }
        assert_eq!(header.incarnations, [1, 2, 3, 4]);
    }
}
