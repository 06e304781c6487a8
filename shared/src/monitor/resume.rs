//! What a restarted monitor goes on from: at each checkpoint the recording's running state (the
//! report so far, every distribution, the fault trackers, the scenario's metrics) is written to
//! one file, so that the next monitor's report covers the whole run and not only its own span.
//!
//! The file lies in the run's private folder on tmpfs ([`crate::runtime::storage::run_storage::run_folder`]):
//! no other user can read or forge it, it never waits for a disk, and the run's clean-up removes
//! it. It is written under another name and renamed into place, so a monitor killed mid-write
//! leaves the previous one whole.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use serde::{Deserialize, Serialize};

use crate::contract::codec;
use crate::contract::msg::PlantCounters;
use crate::monitor::fault_effect::FaultTracker;
use crate::monitor::sinks::FileEnd;
use crate::monitor::stats::LoopStats;
use crate::runtime::storage::private_file;

/// The snapshot file of run `run_id`'s monitor.
pub fn path(run_id: &str) -> Result<PathBuf> {
    let folder = crate::runtime::storage::run_storage::run_folder(run_id);
    crate::runtime::storage::run_storage::check_private(&folder)?;
    Ok(folder.join("monitor.state"))
}

/// The recording's running state after loop `next_k − 1`. Generic over owning or borrowing its
/// large parts: the monitor writes it from references (no copy of its histograms) and reads it
/// back owned; both encode alike.
#[derive(Serialize, Deserialize)]
pub struct Frozen<Stats, Faults> {
    /// Every loop before it is in this state; those from it on went with the monitor.
    pub next_k: u64,
    /// The `MonitorReport` so far, as JSON (its serde form is JSON's).
    pub report: String,
    /// The newest missing loop (`MissingLoops` does not serialise it).
    pub missing_newest: Option<u64>,
    /// The highest loop-record sequence number received (1 is the plant's first).
    pub last_record_sequence: u64,
    pub stats: Stats,
    pub faults: Faults,
    /// The scenario's metrics (`Metrics::freeze`); None: they cannot be carried over.
    pub metrics: Option<Vec<u8>>,
    pub last_counters: PlantCounters,
    /// Each output file's length at this save: the loops before `next_k` and no more.
    pub files: Vec<FileEnd>,
}

pub type FrozenRef<'a> = Frozen<&'a LoopStats, &'a [FaultTracker]>;
pub type Thawed = Frozen<LoopStats, Vec<FaultTracker>>;

/// Writes `frozen` to `path`, whole or not at all.
pub fn write(path: &Path, frozen: &FrozenRef) -> Result<()> {
    private_file::write(path, &codec::to_bytes(frozen)?)
}

/// The last monitor's state, if it wrote one.
pub fn read(path: &Path) -> Result<Option<Thawed>> {
    let Some(bytes) = private_file::read(path)? else { return Ok(None) };
    Ok(Some(codec::decode(&bytes).with_context(|| format!("decode {}", path.display()))?))
}

#[cfg(test)]
mod tests {
    use crate::config::launch::Override;
    use crate::contract::msg::SensorReading;
    use crate::model::layout::VectorLayout;
    use crate::model::scenario::{Metrics, Row};
    use crate::scenarios::{builtin, resolve};

    /// Loop k of a made-up trajectory: every value moving, each differently.
    fn values(k: u64, salt: usize, n: usize) -> Vec<f64> {
        (0..n).map(|i| ((k as f64) * 0.01 * (i + salt + 1) as f64).sin() * (1.0 + i as f64)).collect()
    }

    fn feed(metrics: &mut dyn Metrics, layout: &VectorLayout, rate_hz: f64, loops: std::ops::Range<u64>) {
        for k in loops {
            let t = k as f64 / rate_hz;
            let readings: Vec<SensorReading> = (0..layout.sensors.len())
                .map(|i| {
                    let mut r = SensorReading { sample_time: t, seq: k, fresh: 1, valid: 1, ..Default::default() };
                    for (v, x) in r.value.iter_mut().zip(values(k, 10 + i, 8)) {
                        *v = x;
                    }
                    r
                })
                .collect();
            let (state, estimate) = (values(k, 0, layout.state.len()), values(k, 3, layout.estimate.len()));
            let (command, applied) =
                (values(k, 5, layout.input.len()), values(k.saturating_sub(1), 5, layout.input.len()));
            let row = Row {
                k,
                t,
                state: &state,
                readings: &readings,
                estimate: &estimate,
                command: &command,
                applied: &applied,
            };
            metrics.observe(&row);
        }
    }

    #[test]
    fn every_scenarios_metrics_go_on_after_a_freeze_and_thaw_as_if_never_stopped() {
        for entry in builtin().entries() {
            let overrides = [Override::parse("duration_s=3").unwrap()];
            let (config, scenario) = resolve(entry.name, &overrides).unwrap();
            let layout = VectorLayout::new(&config, scenario.as_ref());
            let loops = config.loops();
            let mut whole = scenario.metrics();
            feed(whole.as_mut(), &layout, config.rate_hz, 0..loops);
            let mut before = scenario.metrics();
            feed(before.as_mut(), &layout, config.rate_hz, 0..loops / 2);
            let frozen = before.freeze().unwrap_or_else(|| panic!("{}: its metrics cannot be frozen", entry.name));
            let mut after = scenario.metrics();
            after.thaw(&frozen).unwrap();
            feed(after.as_mut(), &layout, config.rate_hz, loops / 2..loops);
            let bits = |m: &dyn Metrics| m.finish().into_iter().map(|(n, v)| (n, v.to_bits())).collect::<Vec<_>>();
            assert!(!whole.finish().is_empty(), "{}", entry.name);
            assert_eq!(bits(after.as_ref()), bits(whole.as_ref()), "{}", entry.name);
            assert_eq!(after.notes(), whole.notes(), "{}", entry.name);
        }
    }
}
