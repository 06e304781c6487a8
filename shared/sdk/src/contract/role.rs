//! The processes of a loop and the topics between them, named once.
//!
//! Everything that used to be kept in parallel string tables (start and stop order, which
//! topics a process reads and writes, its slot in `Header::incarnations`, which faults may
//! target it) is a property of [`Role`] or [`Topic`]. Their text comes from the derives, so the
//! launch file, the CLI, `summary.json` and the logs all spell a role the same way.

use serde::{Deserialize, Serialize};

/// One process of the loop.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Hash,
    PartialOrd,
    Ord,
    Serialize,
    Deserialize,
    strum::IntoStaticStr,
    strum::Display,
    strum::EnumString,
    schemars::JsonSchema,
)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
#[strum(serialize_all = "kebab-case")]
pub enum Role {
    Plant,
    Sensors,
    Estimator,
    Controller,
    Monitor,
    /// Carries the topics that cross to another host, on this host (runs only when a launch
    /// file places a stage on another host).
    Bridge,
    /// Its counterpart on the other host.
    BridgeRemote,
}

impl Role {
    /// Every process, in the order data flows (the monitor last). Also the stop order: the
    /// source of the data goes first, so that nothing downstream waits for input in vain.
    pub const ALL: [Role; 5] = [Role::Plant, Role::Sensors, Role::Estimator, Role::Controller, Role::Monitor];
    /// The processes of the loop itself, which stamp the trace and carry an incarnation.
    pub const LOOP: [Role; 4] = [Role::Plant, Role::Sensors, Role::Estimator, Role::Controller];
    /// The stages between the plant and the plant, which handle one input per loop.
    pub const STAGES: [Role; 3] = [Role::Sensors, Role::Estimator, Role::Controller];
    /// Readers before writers, so that no sample is sent before its reader exists.
    pub const START_ORDER: [Role; 5] = [Role::Monitor, Role::Controller, Role::Estimator, Role::Sensors, Role::Plant];
    pub const STOP_ORDER: [Role; 5] = Role::ALL;
    /// The bridges, in start order: the remote one listens, this host's connects to it.
    pub const BRIDGES: [Role; 2] = [Role::BridgeRemote, Role::Bridge];

    /// The name of the process, its binary and its log file.
    pub fn name(self) -> &'static str {
        self.into()
    }

    /// Its slot in `Header::incarnations`; the monitor and the bridges handle no loop data of
    /// their own and have none.
    pub fn slot(self) -> Option<usize> {
        match self {
            Role::Monitor | Role::Bridge | Role::BridgeRemote => None,
            stage => Some(stage as usize),
        }
    }

    /// The loop processes that stamp the trace and carry an incarnation.
    pub fn in_loop(self) -> bool {
        self.slot().is_some()
    }

    /// The topic it waits on (the monitor reads them all and waits on none).
    pub fn input(self) -> Option<Topic> {
        match self {
            Role::Plant => Some(Topic::Command),
            Role::Sensors => Some(Topic::State),
            Role::Estimator => Some(Topic::Measurements),
            Role::Controller => Some(Topic::Estimate),
            Role::Monitor | Role::Bridge | Role::BridgeRemote => None,
        }
    }

    /// The loop process that waits on `topic` (none waits on the loop records).
    pub fn reading(topic: Topic) -> Option<Role> {
        Role::ALL.into_iter().find(|r| r.input() == Some(topic))
    }

    /// The loop topic it publishes.
    pub fn output(self) -> Option<Topic> {
        match self {
            Role::Plant => Some(Topic::State),
            Role::Sensors => Some(Topic::Measurements),
            Role::Estimator => Some(Topic::Estimate),
            Role::Controller => Some(Topic::Command),
            Role::Monitor | Role::Bridge | Role::BridgeRemote => None,
        }
    }
}

/// One iceoryx2 publish–subscribe service of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, strum::IntoStaticStr, strum::Display)]
#[strum(serialize_all = "lowercase")]
pub enum Topic {
    /// plant → sensors, monitor
    State,
    /// sensors → estimator, monitor
    Measurements,
    /// estimator → controller, monitor
    Estimate,
    /// controller → plant, monitor
    Command,
    /// plant → monitor: finished loop records
    Loop,
}

impl Topic {
    /// Every topic, in the order data flows; the monitor reads them all.
    pub const ALL: [Topic; 5] = [Topic::State, Topic::Measurements, Topic::Estimate, Topic::Command, Topic::Loop];

    pub fn name(self) -> &'static str {
        self.into()
    }

    /// The loop process that writes it.
    pub fn writer(self) -> Role {
        match self {
            Topic::State | Topic::Loop => Role::Plant,
            Topic::Measurements => Role::Sensors,
            Topic::Estimate => Role::Estimator,
            Topic::Command => Role::Controller,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_the_same_everywhere() {
        for role in Role::ALL.into_iter().chain(Role::BRIDGES) {
            let serde = serde_json::to_value(role).unwrap();
            assert_eq!(serde.as_str(), Some(role.name()));
            assert_eq!(role.to_string(), role.name());
            assert_eq!(role.name().parse::<Role>().unwrap(), role);
            #[cfg(feature = "cli")]
            assert_eq!(clap::ValueEnum::to_possible_value(&role).unwrap().get_name(), role.name());
        }
        assert_eq!(Topic::Measurements.name(), "measurements");
        assert_eq!(Role::BridgeRemote.name(), "bridge-remote");
    }

    #[test]
    fn each_topic_has_one_writer_and_one_loop_reader() {
        for topic in [Topic::State, Topic::Measurements, Topic::Estimate, Topic::Command] {
            assert_eq!(Role::ALL.iter().filter(|r| r.output() == Some(topic)).count(), 1, "{topic}");
            assert_eq!(Role::ALL.iter().filter(|r| r.input() == Some(topic)).count(), 1, "{topic}");
            assert_eq!(topic.writer().output(), Some(topic));
        }
        let slots: Vec<_> = Role::ALL.iter().filter_map(|r| r.slot()).collect();
        assert_eq!(slots, [0, 1, 2, 3]);
        let mut start = Role::START_ORDER;
        start.reverse();
        assert_eq!(start, Role::STOP_ORDER);
    }
}
