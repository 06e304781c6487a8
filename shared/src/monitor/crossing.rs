//! The hops of the loop that cross to another host. Each side stamps with its own
//! CLOCK_MONOTONIC, so such a hop is only a difference of stamps once the other host's clock is
//! known: every loop that goes there and back is an NTP exchange, the fit (`clock_fit`) follows
//! the clock, and a window's crossing hops are corrected once the fit has that window's best
//! exchange. The link's round trip needs no clock at all.

use crate::config::launch::LaunchConfig;
use crate::contract::msg::{LoopTrace, Stamp};
use crate::contract::report::{ClockReport, CrossingReport, HOPS};
use crate::monitor::clock_fit::{ClockFit, ClockFitter, DEFAULT_WINDOW_NS, ntp_samples};
use crate::monitor::distribution::Distribution;

#[derive(serde::Serialize, serde::Deserialize)]
pub struct Crossing {
    /// Per stamp: 1 if it is the other host's clock, 0 if ours.
    hosts: [u8; 8],
    /// Indices into `HOPS` of the hops whose ends are on different hosts.
    hops: Vec<usize>,
    fitter: ClockFitter,
    round_trip: Distribution,
    /// The current window's loops' stamps, corrected when the window closes.
    pending: Vec<[u64; 8]>,
    window_end_ns: Option<u64>,
}

impl Crossing {
    /// None when the whole loop runs here.
    pub fn new(config: &LaunchConfig) -> Option<Self> {
        config.hosts.remote()?;
        let hosts = Stamp::ALL.map(|stamp| u8::from(config.hosts.is_remote(stamp.role())));
        let hops = (0..HOPS.len()).filter(|&i| hosts[HOPS[i].1] != hosts[HOPS[i].2]).collect();
        Some(Self {
            hosts,
            hops,
            fitter: ClockFitter::new(DEFAULT_WINDOW_NS),
            round_trip: Distribution::default(),
            pending: vec![],
            window_end_ns: None,
        })
    }

    /// Whether hop `i` of `HOPS` crosses (it is recorded here, not from the raw stamps).
    pub fn crosses(&self, i: usize) -> bool {
        self.hops.contains(&i)
    }

    /// Takes one loop's trace; records the crossing hops of each window into `hops` once the
    /// window is over.
    pub fn observe(&mut self, trace: &LoopTrace, hops: &mut [Distribution]) {
        let stamps = trace.stamps();
        for (_, sample) in ntp_samples(&stamps, &self.hosts) {
            self.fitter.push(sample);
            self.round_trip.record(sample.round_trip_ns().max(0) as u64);
        }
        let now = trace.get(Stamp::PlantPublish);
        if self.window_end_ns.is_some_and(|end| now >= end) {
            self.correct_pending(hops);
        }
        if self.pending.is_empty() {
            self.window_end_ns = Some(now.saturating_add(DEFAULT_WINDOW_NS));
        }
        self.pending.push(stamps);
    }

    fn correct_pending(&mut self, hops: &mut [Distribution]) {
        let fit = self.fitter.fit();
        for stamps in self.pending.drain(..) {
            let Some(fit) = &fit else { continue };
            for &i in &self.hops {
                let (_, from, to) = HOPS[i];
                let ns = local_ns(fit, &self.hosts, &stamps, to) - local_ns(fit, &self.hosts, &stamps, from);
                hops[i].record(ns.round().max(0.0) as u64);
            }
        }
    }

    /// Corrects the last window and reports the clock and the round trip.
    pub fn finish(&mut self, hops: &mut [Distribution]) -> CrossingReport {
        self.correct_pending(hops);
        let clock = self.fitter.fit().map(|fit| ClockReport {
            offset_ns: fit.offset_ns,
            drift_ppm: fit.drift_ppm,
            uncertainty_ns: fit.uncertainty_ns,
            at_ns: fit.t_ref_ns,
            windows: fit.windows as u64,
            min_round_trip_ns: fit.min_round_trip_ns,
        });
        CrossingReport {
            hops: self.hops.iter().map(|&i| HOPS[i].0.to_owned()).collect(),
            round_trip: self.round_trip.stats(),
            clock,
        }
    }
}

/// Stamp `i` on this host's clock.
fn local_ns(fit: &ClockFit, hosts: &[u8; 8], stamps: &[u64; 8], i: usize) -> f64 {
    if hosts[i] == 0 { stamps[i] as f64 } else { fit.to_local_ns(stamps[i]) }
}
