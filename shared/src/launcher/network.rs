//! `network` in summary.json, for a run with a stage on another host: the link's round trip and
//! the other host's clock (from the monitor), and per crossing topic what the bridges carried,
//! lost and missed, with the link's outages.

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::config::launch::LaunchConfig;
use crate::contract::protocol::{BridgeReport, CrossingCounts};
use crate::contract::report::{ClockReport, MonitorReport, Stats};
use crate::contract::role::Role;
use crate::launcher::child::Start;

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Network {
    /// The other host, as the launch file names it, and where its bridge listened.
    pub host: String,
    pub endpoint: String,
    /// The stages that ran there.
    pub stages: Vec<Role>,
    /// The hops of `latency_ns.hops` that crossed the link, corrected for the other host's clock
    /// (each within `clock.uncertainty_ns`).
    pub crossing_hops: Vec<String>,
    /// The link's round trip per loop: (back here − left here) − (left there − arrived there).
    pub round_trip_ns: Stats,
    /// The other host's CLOCK_MONOTONIC against this one's; none if no loop went there and back.
    pub clock: Option<ClockReport>,
    /// Per crossing topic, both bridges' counts added up.
    pub topics: BTreeMap<String, TopicCrossing>,
    /// Bridge starts that ended without a report (killed): what they carried is not counted.
    pub unreported_bridges: u64,
    /// The link as this host's bridge saw it.
    pub link: LinkReport,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct TopicCrossing {
    /// Frames the sending bridge put on the link.
    pub sent: u64,
    /// Frames the receiving bridge published into shared memory.
    pub received: u64,
    /// Sent but never received (dropped on congestion, or lost with the link); none when a
    /// bridge ended without its report (killed), so that its counts are unknown.
    pub lost: Option<u64>,
    /// Frames the link refused at the sender.
    pub send_errors: u64,
    /// Jumps in the loop number of received frames, and the loops missed in them: what the
    /// other host's stage never got, or never sent.
    pub gaps: u64,
    pub missing: u64,
    /// Frames of the wrong size, dropped.
    pub malformed: u64,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct LinkReport {
    /// Times the other bridge was lost, and times it came back after that.
    pub losses: u64,
    pub reconnects: u64,
    pub outages: Vec<LinkOutage>,
}

#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct LinkOutage {
    /// When this host's bridge lost the other (CLOCK_MONOTONIC here, ns).
    pub lost_ns: u64,
    /// When it was back; none if it never came back before the run ended.
    pub back_ns: Option<u64>,
    pub outage_ms: Option<f64>,
}

/// The network section, if a stage ran on another host.
pub fn build(
    config: &LaunchConfig,
    bridges: &BTreeMap<Role, BTreeMap<u32, BridgeReport>>,
    starts: &BTreeMap<Role, Vec<Start>>,
    monitor: &MonitorReport,
) -> Option<Network> {
    let (host, spec) = config.hosts.remote()?;
    let started: usize = Role::BRIDGES.iter().map(|r| starts.get(r).map_or(0, Vec::len)).sum();
    let reported: usize = bridges.values().map(BTreeMap::len).sum();
    let unreported_bridges = started.saturating_sub(reported) as u64;
    let reports = || bridges.values().flat_map(|by_incarnation| by_incarnation.values());
    let mut topics: BTreeMap<String, CrossingCounts> = BTreeMap::new();
    for (topic, counts) in reports().flat_map(|r| &r.topics) {
        *topics.entry(topic.clone()).or_default() += *counts;
    }
    let ours = bridges.get(&Role::Bridge).into_iter().flat_map(|r| r.values());
    let mut link = LinkReport::default();
    for counts in ours.map(|r| &r.link) {
        link.losses += counts.losses;
        link.reconnects += counts.outages.iter().filter(|o| o.back_ns.is_some()).count() as u64;
        link.outages.extend(counts.outages.iter().map(|o| LinkOutage {
            lost_ns: o.lost_ns,
            back_ns: o.back_ns,
            outage_ms: o.back_ns.map(|back| back.saturating_sub(o.lost_ns) as f64 / 1e6),
        }));
    }
    let crossing = monitor.crossing.clone().unwrap_or_default();
    Some(Network {
        host: host.to_owned(),
        endpoint: spec.endpoint(),
        stages: config.hosts.placement.keys().copied().collect(),
        crossing_hops: crossing.hops,
        round_trip_ns: crossing.round_trip,
        clock: crossing.clock,
        topics: topics
            .into_iter()
            .map(|(topic, c)| {
                let crossing = TopicCrossing {
                    sent: c.sent,
                    received: c.received,
                    lost: (unreported_bridges == 0).then(|| c.sent.saturating_sub(c.received)),
                    send_errors: c.send_errors,
                    gaps: c.gaps,
                    missing: c.missing,
                    malformed: c.malformed,
                };
                (topic, crossing)
            })
            .collect(),
        unreported_bridges,
        link,
    })
}
