//! Where the loop's stages run: the `[hosts]` section of a launch file.
//!
//! ```toml
//! [hosts]
//! controller = "companion"          # a stage placed on a host; stages not named run here
//!
//! [hosts.companion]
//! address = "10.77.0.2"             # where its bridge listens (the bridge here connects)
//! port = 7447
//! command = "ssh companion"         # how the launcher starts a process there (a prefix)
//! ```
//!
//! A stage on another host talks to the rest of the loop through two bridge processes, one on
//! each side, which carry only the topics that cross. The plant and the monitor stay with the
//! launcher: the plant is the loop's clock and the monitor reads every topic. This version
//! bridges one other host (a star with this machine in the middle would need topics relayed
//! from one remote host to another).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::contract::role::{Role, Topic};

/// The placement value that means "this machine".
pub const LOCAL: &str = "local";
/// The port a remote bridge listens on unless its host says otherwise.
pub const DEFAULT_PORT: u16 = 7447;
/// The stages a launch file may place on another host.
pub const PLACEABLE: [Role; 3] = Role::STAGES;

/// One other host.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct HostSpec {
    /// Its address on the link: its bridge listens there, and ours connects to it.
    pub address: String,
    pub port: u16,
    /// The command prefix that runs a program there, in place (`ip netns exec NAME`,
    /// `nsenter --net=... --mount=...`, `ssh HOST`): the program's path and arguments follow it.
    pub command: Vec<String>,
}

impl HostSpec {
    /// The zenoh endpoint its bridge listens on.
    pub fn endpoint(&self) -> String {
        if self.address.contains(':') {
            format!("tcp/[{}]:{}", self.address, self.port)
        } else {
            format!("tcp/{}:{}", self.address, self.port)
        }
    }
}

/// The `[hosts]` section, checked.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Hosts {
    /// Stages placed on another host, by the host's name.
    pub placement: BTreeMap<Role, String>,
    /// Every host the file describes, placed on or not.
    pub hosts: BTreeMap<String, HostSpec>,
}

/// Which way a topic crosses between this machine and the other host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, strum::IntoStaticStr)]
#[serde(rename_all = "snake_case")]
#[strum(serialize_all = "snake_case")]
pub enum Crossing {
    /// Written here, read there.
    Out,
    /// Written there, read here (by a stage, or by the monitor alone).
    In,
}

impl Hosts {
    /// Reads `[hosts]`; `error(key, message)` makes the error for a dotted key under `hosts`.
    pub fn parse<E>(table: &toml::Table, error: impl Fn(&str, String) -> E) -> Result<Self, E> {
        let mut hosts = Hosts::default();
        let placeable = || PLACEABLE.iter().map(|r| r.name()).collect::<Vec<_>>().join(", ");
        for (name, value) in table {
            let key = format!("hosts.{name}");
            match value {
                toml::Value::Table(spec) => {
                    if name == LOCAL || name.parse::<Role>().is_ok() {
                        return Err(error(&key, format!("\"{name}\" names a stage or this machine, not a host")));
                    }
                    hosts.hosts.insert(name.clone(), host_spec(spec, &key, &error)?);
                }
                toml::Value::String(host) => {
                    let role = name.parse::<Role>().ok().filter(|r| PLACEABLE.contains(r)).ok_or_else(|| {
                        error(
                            &key,
                            format!(
                                "only a stage can be placed on a host; allowed: {} (the plant and the monitor run \
                                 with the launcher)",
                                placeable()
                            ),
                        )
                    })?;
                    if host != LOCAL {
                        hosts.placement.insert(role, host.clone());
                    }
                }
                other => {
                    return Err(error(
                        &key,
                        format!(
                            "expected a host's name for a stage ({}) or a table describing a host, got a {}",
                            placeable(),
                            other.type_str()
                        ),
                    ));
                }
            }
        }
        for (role, host) in &hosts.placement {
            if !hosts.hosts.contains_key(host) {
                let known: Vec<&str> = hosts.hosts.keys().map(String::as_str).chain([LOCAL]).collect();
                return Err(error(
                    &format!("hosts.{role}"),
                    format!("unknown host \"{host}\"; allowed: {}", known.join(", ")),
                ));
            }
        }
        let used: std::collections::BTreeSet<&String> = hosts.placement.values().collect();
        if used.len() > 1 {
            let names: Vec<&str> = used.iter().map(|s| s.as_str()).collect();
            return Err(error(
                "hosts",
                format!(
                    "stages are placed on {} hosts ({}); one other host is supported",
                    used.len(),
                    names.join(", ")
                ),
            ));
        }
        Ok(hosts)
    }

    /// The other host the loop uses, if a stage is placed on one.
    pub fn remote(&self) -> Option<(&str, &HostSpec)> {
        let name = self.placement.values().next()?;
        Some((name, &self.hosts[name]))
    }

    /// Whether `role` runs on the other host.
    pub fn is_remote(&self, role: Role) -> bool {
        role == Role::BridgeRemote || self.placement.contains_key(&role)
    }

    /// The processes of the run in start order: the bridges first when a stage is elsewhere
    /// (the remote one makes the run's folder on its host, so it starts before anything there).
    pub fn processes(&self) -> Vec<Role> {
        let bridges = if self.remote().is_some() { &Role::BRIDGES[..] } else { &[] };
        bridges.iter().copied().chain(Role::START_ORDER).collect()
    }

    /// How `topic` crosses between the hosts, if it does. Every topic written there crosses,
    /// since the monitor here reads them all.
    pub fn crossing(&self, topic: Topic) -> Option<Crossing> {
        let writer = Role::ALL.into_iter().find(|r| r.output() == Some(topic))?;
        let reader_remote = Role::reading(topic).is_some_and(|r| self.is_remote(r));
        match (self.is_remote(writer), reader_remote) {
            (true, _) => Some(Crossing::In),
            (false, true) => Some(Crossing::Out),
            (false, false) => None,
        }
    }

    /// Whether the reader of `topic` on its writer's host is a bridge (which always blocks, so
    /// the writer must wake it), not the stage itself.
    pub fn read_by_bridge(&self, topic: Topic) -> bool {
        let writer = Role::ALL.into_iter().find(|r| r.output() == Some(topic));
        let reader = Role::reading(topic);
        match (writer, reader) {
            (Some(w), Some(r)) => self.is_remote(w) != self.is_remote(r),
            _ => false,
        }
    }
}

fn host_spec<E>(spec: &toml::Table, key: &str, error: &impl Fn(&str, String) -> E) -> Result<HostSpec, E> {
    for name in spec.keys() {
        if !["address", "port", "command"].contains(&name.as_str()) {
            return Err(error(&format!("{key}.{name}"), "unknown key; allowed: address, port, command".into()));
        }
    }
    let address = match spec.get("address") {
        Some(toml::Value::String(a)) if !a.trim().is_empty() => a.trim().to_owned(),
        _ => return Err(error(&format!("{key}.address"), "missing; give the host's address on the link".into())),
    };
    let port = match spec.get("port") {
        None => DEFAULT_PORT,
        Some(toml::Value::Integer(p)) if (1..=65535).contains(p) => *p as u16,
        Some(other) => return Err(error(&format!("{key}.port"), format!("must be a port, 1 to 65535, got {other}"))),
    };
    let command: Vec<String> = match spec.get("command") {
        None => vec![],
        Some(toml::Value::String(c)) => c.split_whitespace().map(str::to_owned).collect(),
        Some(toml::Value::Array(words)) => {
            let words: Option<Vec<String>> = words.iter().map(|w| w.as_str().map(str::to_owned)).collect();
            words.ok_or_else(|| error(&format!("{key}.command"), "must be a string or an array of strings".into()))?
        }
        Some(_) => return Err(error(&format!("{key}.command"), "must be a string or an array of strings".into())),
    };
    Ok(HostSpec { address, port, command })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Hosts, String> {
        let table: toml::Table = toml::from_str(text).unwrap();
        Hosts::parse(&table, |key, message| format!("{key}: {message}"))
    }

    const COMPANION: &str = "controller = \"b\"\n[b]\naddress = \"10.77.0.2\"\ncommand = \"ip netns exec nb\"\n";

    #[test]
    fn a_remote_controller_crosses_estimate_out_and_command_in() {
        let hosts = parse(COMPANION).unwrap();
        let (name, spec) = hosts.remote().unwrap();
        assert_eq!(
            (name, spec.endpoint(), spec.command.join(" ")),
            ("b", "tcp/10.77.0.2:7447".into(), "ip netns exec nb".into())
        );
        let crossings: Vec<_> = Topic::ALL.into_iter().map(|t| hosts.crossing(t)).collect();
        assert_eq!(crossings, [None, None, Some(Crossing::Out), Some(Crossing::In), None]);
        assert!(hosts.read_by_bridge(Topic::Estimate) && hosts.read_by_bridge(Topic::Command));
        assert!(!hosts.read_by_bridge(Topic::State) && !hosts.read_by_bridge(Topic::Measurements));
        assert_eq!(hosts.processes()[..3], [Role::BridgeRemote, Role::Bridge, Role::Monitor]);
    }

    #[test]
    fn a_remote_estimator_and_controller_send_their_link_topic_in_for_the_monitor() {
        let hosts = parse(&format!("estimator = \"b\"\n{COMPANION}")).unwrap();
        let crossings: Vec<_> = Topic::ALL.into_iter().map(|t| hosts.crossing(t)).collect();
        assert_eq!(crossings, [None, Some(Crossing::Out), Some(Crossing::In), Some(Crossing::In), None]);
        assert!(!hosts.read_by_bridge(Topic::Estimate), "the controller reads it on its own host");
    }

    #[test]
    fn no_placement_means_no_bridges() {
        let hosts = parse("controller = \"local\"\n[b]\naddress = \"10.77.0.2\"\n").unwrap();
        assert!(hosts.remote().is_none());
        assert_eq!(hosts.processes(), Role::START_ORDER);
        assert!(Topic::ALL.into_iter().all(|t| hosts.crossing(t).is_none()));
    }

    #[test]
    fn bad_placements_name_the_key_and_what_is_allowed() {
        assert_eq!(
            parse("controller = \"c\"\n[b]\naddress = \"x\"").unwrap_err(),
            "hosts.controller: unknown host \"c\"; allowed: b, local"
        );
        assert!(
            parse("plant = \"b\"\n[b]\naddress = \"x\"").unwrap_err().starts_with(
                "hosts.plant: only a stage can be placed on a host; allowed: sensors, estimator, controller"
            )
        );
        assert_eq!(
            parse("[b]\nport = 1").unwrap_err(),
            "hosts.b.address: missing; give the host's address on the link"
        );
        assert_eq!(
            parse("[b]\naddress = \"x\"\nport = 70000").unwrap_err(),
            "hosts.b.port: must be a port, 1 to 65535, got 70000"
        );
        assert_eq!(
            parse("[b]\naddress = \"x\"\nuser = 1").unwrap_err(),
            "hosts.b.user: unknown key; allowed: address, port, command"
        );
        assert!(parse("controller = 3").unwrap_err().starts_with("hosts.controller: expected a host's name"));
        assert_eq!(
            parse("controller = \"b\"\nsensors = \"c\"\n[b]\naddress = \"x\"\n[c]\naddress = \"y\"").unwrap_err(),
            "hosts: stages are placed on 2 hosts (b, c); one other host is supported"
        );
        assert!(
            parse("[controller]\naddress = \"x\"")
                .unwrap_err()
                .starts_with("hosts.controller: \"controller\" names a stage")
        );
    }
}
