//! `looplab bench --restarts N`: how long a restart takes, step by step, over N real-time kills
//! of the loop's processes, on the idle machine and again with two CPU hogs and a disk writer
//! that fsyncs without pause (what CI's machine looks like while the test suite runs).

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Result, anyhow};
use serde::Serialize;

use crate::config::launch::Override;
use crate::contract::role::Role;
use crate::launcher::summary::RestartSteps;
use crate::launcher::{Binaries, Outcome};
use crate::model::catalog::Catalog;
use crate::runtime::signals::Interrupted;

/// The processes killed in turn; one kill every `KILL_INTERVAL_S`.
const TARGETS: [Role; 5] = Role::ALL;
const KILL_INTERVAL_S: f64 = 0.25;

/// A distribution of one step, ms.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Millis {
    pub n: usize,
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Millis {
    fn of(mut values: Vec<f64>) -> Self {
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values.get(((values.len().max(1) - 1) as f64 * q).round() as usize).copied().unwrap_or(0.0);
        Self { n: values.len(), p50: at(0.5), p99: at(0.99), max: at(1.0) }
    }
}

/// One condition's restarts, each step in ms: from SIGKILL to the death seen, and from the
/// death seen to the clean-up done, the new process started, and its ports up; `total` is
/// SIGKILL to ports up.
#[derive(Debug, Clone, Serialize)]
pub struct RestartBench {
    pub condition: String,
    pub kills: usize,
    pub restarted: usize,
    pub detected: Millis,
    pub cleaned: Millis,
    pub spawned: Millis,
    pub ready: Millis,
    pub total: Millis,
    pub run_dir: String,
}

/// CPU hogs and a disk writer that fsyncs without pause, stopped when dropped: a busy machine
/// like CI's while the test suite runs.
pub struct Load {
    hogs: Vec<std::process::Child>,
    writing: Arc<AtomicBool>,
    writer: Option<std::thread::JoinHandle<()>>,
}

impl Load {
    /// Starts `hogs` CPU hogs and the disk writer, whose file goes in `scratch`.
    pub fn start(scratch: &Path, hogs: usize) -> Result<Self> {
        let hogs = (0..hogs)
            .map(|_| std::process::Command::new("sh").args(["-c", "while :; do :; done"]).spawn())
            .collect::<std::io::Result<Vec<_>>>()?;
        let writing = Arc::new(AtomicBool::new(true));
        let flag = writing.clone();
        let path = scratch.join("disk-writer.bin");
        let writer = std::thread::spawn(move || {
            let block = vec![0u8; 1 << 20];
            while flag.load(Ordering::Relaxed) {
                let Ok(mut file) = std::fs::File::create(&path) else { return };
                for _ in 0..8 {
                    let _ = file.write_all(&block);
                }
                let _ = file.sync_all();
            }
            let _ = std::fs::remove_file(&path);
        });
        Ok(Self { hogs, writing, writer: Some(writer) })
    }
}

impl Drop for Load {
    fn drop(&mut self) {
        for hog in &mut self.hogs {
            let _ = hog.kill();
            let _ = hog.wait();
        }
        self.writing.store(false, Ordering::Relaxed);
        if let Some(writer) = self.writer.take() {
            let _ = writer.join();
        }
    }
}

fn measure(
    condition: &str,
    kills: usize,
    out: &Path,
    binaries: &Binaries,
    catalog: &Catalog,
) -> Result<Vec<RestartBench>> {
    let duration = kills as f64 * KILL_INTERVAL_S + 1.0;
    let mut overrides = vec![
        Override::parse(&format!("duration_s={duration:?}"))?,
        Override::parse(&format!("supervision.max_restarts={kills}"))?,
    ];
    for i in 0..kills {
        let at = 0.5 + i as f64 * KILL_INTERVAL_S;
        overrides.push(Override::fault(&format!("kill {} at {at}s", TARGETS[i % TARGETS.len()]))?);
    }
    let (config, scenario) = catalog.resolve("pendulum", &overrides)?;
    let dir = crate::launcher::create_run_dir(Some(&out.join(condition)), "pendulum")?;
    let (summary, outcome) = crate::launcher::run_once(&config, scenario.as_ref(), binaries, &dir, true)?;
    match outcome {
        Outcome::Interrupted | Outcome::Quit => return Err(Interrupted.into()),
        Outcome::Failed(why) => return Err(anyhow!("the {condition} run failed: {why}")),
        Outcome::Completed => {}
    }
    // The n-th kill of a process goes with its n-th restart (deaths can be seen out of order).
    let mut kills_of: BTreeMap<Role, Vec<Option<f64>>> = BTreeMap::new();
    for f in &summary.faults {
        kills_of.entry(f.process).or_default().push(f.detected_after_ms);
    }
    let mut restarts_of: BTreeMap<Role, Vec<&RestartSteps>> = BTreeMap::new();
    for r in &summary.restart_steps {
        restarts_of.entry(r.process).or_default().push(r);
    }
    let mut groups: BTreeMap<&str, Steps> = BTreeMap::new();
    for (process, kills) in &kills_of {
        let group = groups.entry(if *process == Role::Monitor { "monitor" } else { "loop" }).or_default();
        let restarts = restarts_of.get(process).map_or(&[][..], Vec::as_slice);
        for (i, detected) in kills.iter().enumerate() {
            group.kills += 1;
            group.detected.extend(*detected);
            let Some(r) = restarts.get(i) else { continue };
            group.restarted += usize::from(r.ready_after_ms.is_some());
            group.cleaned.extend(r.cleaned_after_ms);
            group.spawned.extend(r.spawned_after_ms);
            group.ready.extend(r.ready_after_ms);
            group.total.extend(detected.zip(r.ready_after_ms).map(|(d, r)| d + r));
        }
    }
    Ok(groups
        .into_iter()
        .map(|(group, steps)| RestartBench {
            condition: format!("{condition}, {group}"),
            kills: steps.kills,
            restarted: steps.restarted,
            detected: Millis::of(steps.detected),
            cleaned: Millis::of(steps.cleaned),
            spawned: Millis::of(steps.spawned),
            ready: Millis::of(steps.ready),
            total: Millis::of(steps.total),
            run_dir: dir.display().to_string(),
        })
        .collect())
}

/// One group's steps, ms.
#[derive(Default)]
struct Steps {
    kills: usize,
    restarted: usize,
    detected: Vec<f64>,
    cleaned: Vec<f64>,
    spawned: Vec<f64>,
    ready: Vec<f64>,
    total: Vec<f64>,
}

/// Measures restarts idle and under load, prints a table and writes `restarts.json`. The monitor
/// is apart: it runs at nice 19 (it never takes a CPU from the loop), so under load it is slow
/// to die and to start.
pub fn run(kills: usize, out: &Path, binaries: &Binaries, catalog: &Catalog) -> Result<()> {
    if kills == 0 {
        return Err(anyhow!("--restarts needs at least one kill"));
    }
    let idle = measure("idle", kills, out, binaries, catalog)?;
    let loaded = {
        let _load = Load::start(out, 2)?;
        measure("loaded", kills, out, binaries, catalog)?
    };
    let mut text = String::from(
        "\nrestarts (ms; detected: SIGKILL → death seen; the others from the death seen; total: SIGKILL → ports up)\n",
    );
    text += &format!(
        "  {:<16} {:>9}  {:>22}  {:>22}  {:>22}  {:>22}  {:>22}\n",
        "", "restarted", "detected p50/p99/max", "cleaned", "started", "ready", "total"
    );
    let all: Vec<RestartBench> = idle.into_iter().chain(loaded).collect();
    for b in &all {
        let cell = |m: &Millis| format!("{:.1} / {:.1} / {:.1}", m.p50, m.p99, m.max);
        text += &format!(
            "  {:<16} {:>9}  {:>22}  {:>22}  {:>22}  {:>22}  {:>22}\n",
            b.condition,
            format!("{}/{}", b.restarted, b.kills),
            cell(&b.detected),
            cell(&b.cleaned),
            cell(&b.spawned),
            cell(&b.ready),
            cell(&b.total)
        );
    }
    say_raw!("{text}");
    let path = out.join("restarts.json");
    crate::launcher::write_atomically(&path, &(serde_json::to_string_pretty(&all)? + "\n"))?;
    tell!("wrote {}", path.display());
    Ok(())
}
