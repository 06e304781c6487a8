//! The live view of a run: what the user sees while it goes on (nothing, a status line on
//! stderr, or the full-screen dashboard). It is told what happens; it never reads the loop.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Result;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use crate::config::launch::LaunchConfig;
use crate::contract::protocol::MonitorStatus;
use crate::launcher::dashboard::{self, Dashboard, ProcessRow, Update};
use crate::launcher::summary::TimelineEntry;
use crate::model::layout::VectorLayout;
use crate::model::scenario::Scenario;
use crate::monitor::live::{Truth, key_signals};

/// What the user sees while a run goes on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LiveView {
    Quiet,
    /// A progress bar with the end-to-end p99 on stderr.
    StatusLine,
    /// The full-screen dashboard (stdout must be a terminal).
    Dashboard,
}

/// The view of one run: the status line (a hidden bar unless it was asked for) and the
/// dashboard, if open.
pub(super) struct Live {
    progress: ProgressBar,
    dashboard: Option<Dashboard>,
    /// The processes as last sent to the dashboard.
    shown: Vec<ProcessRow>,
    /// Set by the dashboard's `q`.
    quit: Arc<AtomicBool>,
}

impl Live {
    pub(super) fn open(view: LiveView, config: &LaunchConfig, scenario: &dyn Scenario) -> Result<Self> {
        let progress = match view {
            LiveView::StatusLine => ProgressBar::with_draw_target(Some(config.loops()), ProgressDrawTarget::stderr()),
            LiveView::Quiet | LiveView::Dashboard => ProgressBar::hidden(),
        };
        let quit = Arc::new(AtomicBool::new(false));
        let dashboard = match view {
            LiveView::Dashboard => Some(Dashboard::open(dashboard_header(config, scenario), quit.clone())?),
            LiveView::Quiet | LiveView::StatusLine => None,
        };
        progress.set_style(
            ProgressStyle::with_template("{spinner} {bar:16} {pos}/{len} loops · {msg}").expect("valid template"),
        );
        Ok(Live { progress, dashboard, shown: vec![], quit })
    }

    /// The user pressed `q` on the dashboard.
    pub(super) fn quit_asked(&self) -> bool {
        self.quit.load(Ordering::Relaxed)
    }

    /// The monitor's latest status.
    pub(super) fn status(&self, status: Box<MonitorStatus>) {
        self.progress.set_position(status.loops_recorded);
        // As in the report: the p99 of the loops that got a command, the misses beside it.
        let p99 = match status.end_to_end_p99_ns {
            Some(ns) => format!("{:.0} µs", ns as f64 / 1000.0),
            None => "-".into(),
        };
        let misses = crate::contract::protocol::misses_text(&status);
        self.progress.set_message(format!("end-to-end p99 {p99} (loops with a command) · deadline misses {misses}"));
        if let Some(dashboard) = &self.dashboard {
            dashboard.send(Update::Status(status));
        }
    }

    /// A new entry of the timeline.
    pub(super) fn event(&self, entry: &TimelineEntry) {
        if let Some(dashboard) = &self.dashboard {
            dashboard.send(Update::Event(entry.clone()));
        }
    }

    /// The processes' states, sent when they changed.
    pub(super) fn processes(&mut self, rows: Vec<ProcessRow>) {
        let Some(dashboard) = &self.dashboard else { return };
        if rows != self.shown {
            dashboard.send(Update::Processes(rows.clone()));
            self.shown = rows;
        }
    }

    /// The run is over; its processes are being stopped.
    pub(super) fn stopping(&self) {
        if let Some(dashboard) = &self.dashboard {
            dashboard.send(Update::Stopping);
        }
    }

    /// Clears the status line and gives the terminal back.
    pub(super) fn close(&mut self) {
        self.progress.finish_and_clear();
        if let Some(dashboard) = self.dashboard.take() {
            dashboard.close();
        }
    }
}

/// The dashboard's fixed lines: the run, and the key signals with their units.
fn dashboard_header(config: &LaunchConfig, scenario: &dyn Scenario) -> dashboard::Header {
    let signals = key_signals(&VectorLayout::new(config, scenario))
        .into_iter()
        .map(|s| dashboard::SignalPlot {
            title: format!("{} [{}]", s.name, s.unit),
            curve: match s.truth {
                Truth::State(_) => "true",
                Truth::Command(_) => "command",
            },
            estimated: s.estimate.is_some(),
        })
        .collect();
    dashboard::Header {
        run: format!("{} · {} · {} Hz", config.scenario, config.mode.name(), config.rate_hz),
        loops_planned: config.loops(),
        signals,
    }
}
