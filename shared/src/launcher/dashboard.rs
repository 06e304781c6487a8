//! `looplab run --dashboard`: the run live in the terminal. It shows what the supervisor already
//! has (the monitor's statuses, the processes, the timeline) and never reads the loop itself, so
//! it cannot slow it: it draws on its own thread, from updates the supervisor sends it.
//!
//! `q` asks the supervisor to stop the run in order; Ctrl-C (a key in raw mode) raises SIGINT, as
//! it would without the dashboard. The terminal is restored when the dashboard closes, is
//! dropped, or anything panics (ratatui's panic hook).

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Result;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use ratatui::Frame;
use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Style, Stylize};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Cell, Chart, Dataset, GraphType, Paragraph, Row, Sparkline, Table};

use crate::contract::protocol::{LiveLatency, MonitorStatus};
use crate::contract::report::HOPS;
use crate::contract::role::Role;
use crate::launcher::summary::TimelineEntry;

/// How often the screen is drawn.
const FRAME: Duration = Duration::from_millis(100);
/// How long the drawing thread waits for an update before it looks at `quit` and the clock.
const UPDATE_WAIT: Duration = Duration::from_millis(20);
/// Simulated seconds the signal plots show.
const PLOT_SECONDS: f64 = 10.0;
/// Statuses each sparkline keeps (wider than any terminal's sparkline column).
const HISTORY: usize = 200;
/// Timeline entries kept for the fault panel.
const EVENTS_KEPT: usize = 100;

/// A process as the dashboard shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::Display)]
#[strum(serialize_all = "lowercase")]
pub enum ProcessState {
    /// Started, its ports not up yet.
    Starting,
    Running,
    /// SIGSTOPped by a fault.
    Stopped,
    /// Dead, waiting for its clean-up and backoff before its next incarnation.
    Restarting,
    /// Dead and not restarted.
    Dead,
    /// Ended (the run is stopping).
    Exited,
}

#[derive(Debug, Clone, PartialEq)]
pub struct ProcessRow {
    pub role: Role,
    pub state: ProcessState,
    pub restarts: u32,
    /// The running incarnation's process id.
    pub pid: Option<u32>,
}

/// What the supervisor tells the dashboard.
#[derive(Debug, Clone)]
pub enum Update {
    Status(Box<MonitorStatus>),
    Processes(Vec<ProcessRow>),
    Event(TimelineEntry),
    /// The run is over; the processes are being stopped.
    Stopping,
}

/// What does not change during a run.
#[derive(Debug, Clone)]
pub struct Header {
    /// "pendulum · realtime · 1000 Hz"
    pub run: String,
    pub loops_planned: u64,
    /// The key signals, in the order of the statuses' points.
    pub signals: Vec<SignalPlot>,
}

/// One key signal's plot.
#[derive(Debug, Clone)]
pub struct SignalPlot {
    /// "theta [rad]"
    pub title: String,
    /// What the signal's own curve is: "true" (a state) or "command".
    pub curve: &'static str,
    /// The estimator has an estimate of it, drawn beside.
    pub estimated: bool,
}

/// The open dashboard: the terminal is in raw mode on the alternate screen until it closes.
pub struct Dashboard {
    updates: Option<Sender<Update>>,
    thread: Option<JoinHandle<std::io::Result<()>>>,
}

impl Dashboard {
    /// Takes over the terminal; `quit` is set when the user presses `q`.
    pub fn open(header: Header, quit: Arc<AtomicBool>) -> Result<Self> {
        let terminal = ratatui::try_init()?;
        let (updates, received) = crossbeam_channel::unbounded();
        // Keys are read on a thread of their own that nobody joins: a read from a terminal that
        // went away (its window closed) may block for good, and must not hold up the run's end.
        let keys_quit = quit.clone();
        std::thread::Builder::new().name("dashboard keys".into()).spawn(move || read_keys(&keys_quit))?;
        let thread = std::thread::Builder::new()
            .name("dashboard".into())
            .spawn(move || draw_until_closed(terminal, View::new(header), &received, &quit))?;
        Ok(Self { updates: Some(updates), thread: Some(thread) })
    }

    pub fn send(&self, update: Update) {
        if let Some(updates) = &self.updates {
            // A dashboard whose thread ended (a terminal error) only stops drawing.
            let _ = updates.send(update);
        }
    }

    /// Draws the last frame and gives the terminal back.
    pub fn close(mut self) {
        self.finish();
    }

    fn finish(&mut self) {
        self.updates = None;
        if let Some(thread) = self.thread.take()
            && let Ok(Err(e)) = thread.join()
        {
            tell!("looplab: the dashboard stopped drawing: {e}");
        }
        ratatui::restore();
    }
}

impl Drop for Dashboard {
    fn drop(&mut self) {
        if self.thread.is_some() {
            self.finish();
        }
    }
}

fn draw_until_closed(
    mut terminal: ratatui::DefaultTerminal,
    mut view: View,
    updates: &Receiver<Update>,
    quit: &AtomicBool,
) -> std::io::Result<()> {
    let mut cpu = CpuMeter::default();
    let mut last_draw: Option<Instant> = None;
    loop {
        let closed = match updates.recv_timeout(UPDATE_WAIT) {
            Ok(update) => {
                view.apply(update);
                updates.try_iter().for_each(|u| view.apply(u));
                false
            }
            Err(RecvTimeoutError::Timeout) => false,
            Err(RecvTimeoutError::Disconnected) => true,
        };
        view.stopping |= quit.load(Ordering::Relaxed);
        if closed || last_draw.is_none_or(|t| t.elapsed() >= FRAME) {
            last_draw = Some(Instant::now());
            view.cpu = cpu.sample(&view.processes);
            terminal.draw(|frame| render(frame, &view))?;
        }
        if closed {
            return Ok(());
        }
    }
}

/// Reads keys until the terminal fails: `q` sets `quit`; Ctrl-C, which raw mode turns into a
/// key, becomes the signal it would have been.
fn read_keys(quit: &AtomicBool) {
    while let Ok(event) = event::read() {
        let Event::Key(key) = event else { continue };
        if key.kind != KeyEventKind::Press {
            continue;
        }
        match key.code {
            KeyCode::Char('q') => quit.store(true, Ordering::Relaxed),
            // SAFETY: raise only sends a signal to this process.
            KeyCode::Char('c') if key.modifiers.contains(KeyModifiers::CONTROL) => unsafe {
                libc::raise(libc::SIGINT);
            },
            _ => {}
        }
    }
}

/// Everything the screen shows, kept from the updates.
#[derive(Debug, Clone)]
pub struct View {
    header: Header,
    status: MonitorStatus,
    /// Per latency row (the hops, end to end, the tick period error): its latest numbers and the
    /// largest value of each status, newest last.
    latencies: Vec<(LiveLatency, VecDeque<u64>)>,
    /// Per key signal: (t, true value, estimate), newest last.
    points: Vec<SignalTrace>,
    processes: Vec<ProcessRow>,
    /// CPU % per process, in the order of `processes`.
    cpu: Vec<Option<f64>>,
    events: VecDeque<TimelineEntry>,
    stopping: bool,
}

/// One key signal's (t, true value, estimate), newest last.
type SignalTrace = VecDeque<(f64, Option<f64>, Option<f64>)>;

/// The latency rows: the hops, end to end, then the tick period error.
const LATENCY_ROWS: usize = HOPS.len() + 2;

impl View {
    pub fn new(header: Header) -> Self {
        let signals = header.signals.len();
        Self {
            header,
            status: MonitorStatus::default(),
            latencies: vec![(LiveLatency::default(), VecDeque::new()); LATENCY_ROWS],
            points: vec![VecDeque::new(); signals],
            processes: vec![],
            cpu: vec![],
            events: VecDeque::new(),
            stopping: false,
        }
    }

    pub fn apply(&mut self, update: Update) {
        match update {
            Update::Status(status) => {
                let mut status = *status;
                if let Some(live) = status.live.take() {
                    let rows = live.hops.into_iter().chain([live.end_to_end, live.tick_period_error]);
                    for ((latest, history), latency) in self.latencies.iter_mut().zip(rows) {
                        if latency.count > 0 {
                            history.push_back(latency.latest_max.unwrap_or(0));
                            if history.len() > HISTORY {
                                history.pop_front();
                            }
                        }
                        *latest = latency;
                    }
                    for point in live.points {
                        for (kept, [truth, estimate]) in self.points.iter_mut().zip(point.values) {
                            kept.push_back((point.t, truth, estimate));
                            while kept.front().is_some_and(|(t, ..)| *t < point.t - PLOT_SECONDS) {
                                kept.pop_front();
                            }
                        }
                    }
                }
                self.status = status;
            }
            Update::Processes(rows) => self.processes = rows,
            Update::Event(entry) => {
                self.events.push_back(entry);
                if self.events.len() > EVENTS_KEPT {
                    self.events.pop_front();
                }
            }
            Update::Stopping => self.stopping = true,
        }
    }
}

/// CPU % of each process from /proc/<pid>/stat, over the last [`CPU_PERIOD`].
#[derive(Default)]
struct CpuMeter {
    /// pid → (user + system clock ticks, when read)
    last: HashMap<u32, (u64, Instant)>,
    /// pid → its CPU % over the last period.
    percent: HashMap<u32, f64>,
}

/// /proc counts CPU time in clock ticks (usually 10 ms): a period much shorter reads as 0 or 100 %.
const CPU_PERIOD: Duration = Duration::from_secs(1);

impl CpuMeter {
    fn sample(&mut self, processes: &[ProcessRow]) -> Vec<Option<f64>> {
        // SAFETY: sysconf reads a constant of the system.
        let ticks_per_s = unsafe { libc::sysconf(libc::_SC_CLK_TCK) }.max(1) as f64;
        let now = Instant::now();
        processes
            .iter()
            .map(|p| {
                let pid = p.pid?;
                let due = self.last.get(&pid).is_none_or(|(_, then)| now.duration_since(*then) >= CPU_PERIOD);
                if due {
                    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok();
                    let ticks = stat.as_deref().and_then(cpu_ticks)?;
                    if let Some((before, then)) = self.last.insert(pid, (ticks, now)) {
                        let wall_s = now.duration_since(then).as_secs_f64();
                        self.percent.insert(pid, ticks.saturating_sub(before) as f64 / ticks_per_s / wall_s * 100.0);
                    }
                }
                self.percent.get(&pid).copied()
            })
            .collect()
    }
}

/// utime + stime (clock ticks) from a /proc/<pid>/stat line. The command name in parentheses may
/// hold spaces, so the fields are counted after its closing parenthesis.
fn cpu_ticks(stat: &str) -> Option<u64> {
    let mut fields = stat.get(stat.rfind(')')? + 1..)?.split_whitespace();
    // After the name: state is field 3, utime 14, stime 15.
    let utime: u64 = fields.nth(11)?.parse().ok()?;
    let stime: u64 = fields.next()?.parse().ok()?;
    Some(utime + stime)
}

/// `text` in lines of at most `width` characters, broken between words where it can be.
fn wrap(text: &str, width: usize) -> Vec<String> {
    let chars = |s: &str| s.chars().count();
    let mut lines: Vec<String> = vec![];
    let mut line = String::new();
    for word in text.split(' ') {
        if !line.is_empty() && chars(&line) + 1 + chars(word) > width {
            lines.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
        while chars(&line) > width {
            let cut = line.char_indices().nth(width).map_or(line.len(), |(i, _)| i);
            let rest = line.split_off(cut);
            lines.push(std::mem::replace(&mut line, rest));
        }
    }
    lines.push(line);
    lines
}

/// A hop's name as the screen shows it: "plant_to_sensors" → "plant → sensors".
fn hop_title(name: &str) -> String {
    name.replace("_to_", " → ").replace('_', " ")
}

/// Nanoseconds as microseconds, to a tenth below a millisecond.
fn micros(ns: Option<u64>) -> String {
    match ns {
        Some(ns) if ns < 1_000_000 => format!("{:.1}", ns as f64 / 1e3),
        Some(ns) => format!("{:.0}", ns as f64 / 1e3),
        None => "-".into(),
    }
}

pub fn render(frame: &mut Frame, view: &View) {
    let [title, latency, middle, signals] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Length(LATENCY_ROWS as u16 + 3),
        Constraint::Length(10),
        Constraint::Min(6),
    ])
    .areas(frame.area());
    render_title(frame, title, view);
    render_latency(frame, latency, view);
    let [processes, events] = Layout::horizontal([Constraint::Length(50), Constraint::Min(20)]).areas(middle);
    render_processes(frame, processes, view);
    render_events(frame, events, view);
    render_signals(frame, signals, view);
}

fn render_title(frame: &mut Frame, area: Rect, view: &View) {
    let status = &view.status;
    let planned = view.header.loops_planned.max(1);
    let state = if view.stopping { " · stopping" } else { "" };
    let line = Line::from(vec![
        Span::from(" LoopLab ").bold().reversed(),
        Span::from(format!(" {}{state} ", view.header.run)).bold(),
        Span::from(format!(
            "· loop {} / {} ({:.0} %) · deadline misses {}",
            status.loops_recorded,
            view.header.loops_planned,
            status.loops_recorded as f64 * 100.0 / planned as f64,
            crate::contract::protocol::misses_text(status)
        )),
    ]);
    let [left, right] = Layout::horizontal([Constraint::Min(0), Constraint::Length(10)]).areas(area);
    frame.render_widget(Paragraph::new(line), left);
    frame.render_widget(Paragraph::new(Line::from("q: quit ").right_aligned()).dim(), right);
}

fn render_latency(frame: &mut Frame, area: Rect, view: &View) {
    let block = Block::bordered().title(" Latency, µs, of loops with a command: the last second, the run's max ");
    let inner = block.inner(area);
    frame.render_widget(block, area);
    let names = HOPS.iter().map(|(name, ..)| hop_title(name)).chain(["end to end".into(), "tick period error".into()]);
    let rows = names.zip(&view.latencies).enumerate().map(|(i, (name, (latest, _)))| {
        let cells = [micros(latest.p50), micros(latest.p99), micros(latest.max), micros(latest.run_max)];
        let style = if i == HOPS.len() { Style::new().bold() } else { Style::new() };
        Row::new([Cell::from(name)].into_iter().chain(cells.map(|c| Cell::from(Line::from(c).right_aligned()))))
            .style(style)
    });
    let header = Row::new(["", "p50", "p99", "max", "run max"].map(|h| Cell::from(Line::from(h).right_aligned())))
        .style(Style::new().dim());
    let numbers = [Constraint::Length(9); 4];
    let widths = [Constraint::Length(24)].into_iter().chain(numbers);
    let [table, spark] = Layout::horizontal([Constraint::Length(24 + 4 * 10 + 1), Constraint::Min(0)]).areas(inner);
    frame.render_widget(Table::new(rows, widths).header(header), table);
    let spark_header = Rect { height: 1, ..spark };
    frame.render_widget(Paragraph::new(" max of each 0.1 s, newest right").dim(), spark_header);
    for (i, (_, history)) in view.latencies.iter().enumerate() {
        let row = Rect { y: spark.y + 1 + i as u16, height: 1, ..spark };
        if row.bottom() > spark.bottom() {
            break;
        }
        // The newest that fit.
        let shown: Vec<u64> = history.iter().rev().take(row.width as usize).rev().copied().collect();
        let color = if i == HOPS.len() { Color::Yellow } else { Color::Cyan };
        frame.render_widget(Sparkline::default().data(&shown).style(color), row);
    }
}

fn render_processes(frame: &mut Frame, area: Rect, view: &View) {
    let right = |h: &'static str| Cell::from(Line::from(h).right_aligned());
    let header = Row::new([Cell::from("process"), Cell::from("state"), right("restarts"), right("pid"), right("CPU")])
        .style(Style::new().dim());
    let rows = view.processes.iter().zip(view.cpu.iter().chain(std::iter::repeat(&None))).map(|(p, cpu)| {
        let color = match p.state {
            ProcessState::Running => Color::Green,
            ProcessState::Starting | ProcessState::Exited => Color::Reset,
            ProcessState::Stopped | ProcessState::Restarting => Color::Yellow,
            ProcessState::Dead => Color::Red,
        };
        Row::new([
            Cell::from(p.role.to_string()),
            Cell::from(p.state.to_string()).style(color),
            Cell::from(Line::from(p.restarts.to_string()).right_aligned()),
            Cell::from(Line::from(p.pid.map_or("-".into(), |pid| pid.to_string())).right_aligned()),
            Cell::from(Line::from(cpu.map_or("-".into(), |c| format!("{c:.0} %"))).right_aligned()),
        ])
    });
    let widths = [10, 10, 8, 8, 6].map(Constraint::Length);
    frame.render_widget(Table::new(rows, widths).header(header).block(Block::bordered().title(" Processes ")), area);
}

fn render_events(frame: &mut Frame, area: Rect, view: &View) {
    let block = Block::bordered().title(" Faults, detections, restarts (s since tick 0) ");
    let inner = block.inner(area);
    // The time takes 10 columns; a long event goes on under its text.
    let width = (inner.width as usize).saturating_sub(10).max(10);
    let mut lines: Vec<Line> = view
        .events
        .iter()
        .flat_map(|e| {
            let color = if e.event.starts_with("inject") {
                Color::Red
            } else if e.event.contains("stalled") || e.event.contains("exited") || e.event.contains("killed") {
                Color::Yellow
            } else if e.event.contains("again") || e.event.contains("restarted") {
                Color::Green
            } else {
                Color::Reset
            };
            wrap(&e.event, width).into_iter().enumerate().map(move |(i, part)| {
                let time = if i == 0 { format!("{:>8.3}  ", e.at_ms / 1e3) } else { " ".repeat(10) };
                Line::from(vec![Span::from(time).dim(), Span::from(part).fg(color)])
            })
        })
        .collect();
    lines.drain(..lines.len().saturating_sub(inner.height as usize));
    let text = if lines.is_empty() { vec![Line::from("none yet").dim()] } else { lines };
    frame.render_widget(Paragraph::new(text).block(block), area);
}

fn render_signals(frame: &mut Frame, area: Rect, view: &View) {
    let n = view.header.signals.len().max(1) as u32;
    let areas = Layout::horizontal((0..n).map(|_| Constraint::Ratio(1, n))).split(area);
    for (i, (SignalPlot { title, curve, estimated }, points)) in
        view.header.signals.iter().zip(&view.points).enumerate()
    {
        let truth: Vec<(f64, f64)> = points.iter().filter_map(|&(t, v, _)| Some((t, v?))).collect();
        let estimate: Vec<(f64, f64)> = points.iter().filter_map(|&(t, _, e)| Some((t, e?))).collect();
        let t_end = points.back().map_or(PLOT_SECONDS, |(t, ..)| t.max(PLOT_SECONDS));
        let (low, high) = truth
            .iter()
            .chain(&estimate)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(_, v)| (lo.min(v), hi.max(v)));
        let (low, high) = if low.is_finite() {
            let margin = ((high - low) * 0.05).max(1e-9);
            (low - margin, high + margin)
        } else {
            (-1.0, 1.0)
        };
        let mut datasets = vec![
            Dataset::default()
                .name(*curve)
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Color::Cyan)
                .data(&truth),
        ];
        if *estimated {
            datasets.push(
                Dataset::default()
                    .name("estimate")
                    .marker(Marker::Braille)
                    .graph_type(GraphType::Line)
                    .style(Color::Yellow)
                    .data(&estimate),
            );
        }
        let x_axis = Axis::default()
            .title("t [s]")
            .bounds([t_end - PLOT_SECONDS, t_end])
            .labels([format!("{:.0}", t_end - PLOT_SECONDS), format!("{t_end:.0}")]);
        let y_axis = Axis::default().bounds([low, high]).labels([format!("{low:.3}"), format!("{high:.3}")]);
        // The legend in the title, where it hides no data.
        let mut legend = vec![Span::from(format!(" {title}: ")), Span::from(*curve).fg(Color::Cyan)];
        if *estimated {
            legend.extend([Span::from(", "), Span::from("estimate").fg(Color::Yellow)]);
        }
        legend.push(Span::from(" "));
        let chart = Chart::new(datasets)
            .block(Block::bordered().title(Line::from(legend)))
            .x_axis(x_axis)
            .y_axis(y_axis)
            .legend_position(None);
        frame.render_widget(chart, areas[i]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::protocol::{LiveStatus, SignalPoint};
    use ratatui::Terminal;
    use ratatui::backend::TestBackend;

    fn latency(p50: u64, p99: u64, max: u64, run_max: u64) -> LiveLatency {
        let (p50, p99, max, run_max) = (Some(p50), Some(p99), Some(max), Some(run_max));
        LiveLatency { count: 100, latest_max: p99, p50, p99, max, run_max }
    }

    fn view() -> View {
        let mut view = View::new(Header {
            run: "pendulum · realtime · 1000 Hz".into(),
            loops_planned: 2000,
            signals: vec![
                SignalPlot { title: "theta [rad]".into(), curve: "true", estimated: true },
                SignalPlot { title: "current [A]".into(), curve: "command", estimated: false },
            ],
        });
        for (i, p99) in [3_000, 6_000, 12_000].into_iter().enumerate() {
            view.apply(Update::Status(Box::new(MonitorStatus {
                loops_recorded: 100 * (i as u64 + 1),
                loops_written: 100 * (i as u64 + 1),
                end_to_end_p99_ns: Some(p99),
                deadline_misses: 1,
                live: Some(LiveStatus {
                    end_to_end: latency(40_000, p99 * 10, 1_500_000, 2_000_000),
                    hops: vec![latency(2_000, p99, 20_000, 25_000); HOPS.len()],
                    tick_period_error: latency(1_000, 2_000, 3_000, 50_000),
                    points: vec![SignalPoint { t: 0.1 * i as f64, values: vec![[Some(0.1), Some(0.2)], [None, None]] }],
                }),
            })));
        }
        view.apply(Update::Processes(vec![
            ProcessRow { role: Role::Monitor, state: ProcessState::Running, restarts: 0, pid: Some(41) },
            ProcessRow { role: Role::Estimator, state: ProcessState::Restarting, restarts: 1, pid: None },
        ]));
        view.cpu = vec![Some(12.4), None];
        view.apply(Update::Event(TimelineEntry { at_ms: 3000.25, event: "inject: kill estimator at 3s".into() }));
        view
    }

    fn screen(width: u16, height: u16, draw: impl FnOnce(&mut Frame)) -> Vec<String> {
        let mut terminal = Terminal::new(TestBackend::new(width, height)).unwrap();
        terminal.draw(draw).unwrap();
        let buffer = terminal.backend().buffer();
        buffer
            .content()
            .chunks(width as usize)
            .map(|row| row.iter().map(|cell| cell.symbol()).collect::<String>().trim_end().to_string())
            .collect()
    }

    #[test]
    fn the_latency_panel_shows_microseconds_and_each_rows_history() {
        let view = view();
        let lines = screen(80, 12, |f| render_latency(f, f.area(), &view));
        assert_eq!(
            lines,
            [
                "┌ Latency, µs, of loops with a command: the last second, the run's max ────────┐",
                "│                               p50       p99       max   run max  max of each │",
                "│plant → sensors                2.0      12.0      20.0      25.0 ▂▄█          │",
                "│sensors compute                2.0      12.0      20.0      25.0 ▂▄█          │",
                "│sensors → estimator            2.0      12.0      20.0      25.0 ▂▄█          │",
                "│estimator compute              2.0      12.0      20.0      25.0 ▂▄█          │",
                "│estimator → controller         2.0      12.0      20.0      25.0 ▂▄█          │",
                "│controller compute             2.0      12.0      20.0      25.0 ▂▄█          │",
                "│controller → plant             2.0      12.0      20.0      25.0 ▂▄█          │",
                "│end to end                    40.0     120.0      1500      2000 ▂▄█          │",
                "│tick period error              1.0       2.0       3.0      50.0 ███          │",
                "└──────────────────────────────────────────────────────────────────────────────┘",
            ]
        );
    }

    #[test]
    fn the_process_and_event_panels_show_states_restarts_and_cpu() {
        let view = view();
        let lines = screen(100, 5, |f| {
            let [processes, events] = Layout::horizontal([Constraint::Length(50), Constraint::Min(20)]).areas(f.area());
            render_processes(f, processes, &view);
            render_events(f, events, &view);
        });
        assert_eq!(
            lines,
            [
                "┌ Processes ─────────────────────────────────────┐┌ Faults, detections, restarts (s since tick 0) ─┐",
                "│process    state      restarts      pid    CPU  ││   3.000  inject: kill estimator at 3s          │",
                "│monitor    running           0       41   12 %  ││                                                │",
                "│estimator  restarting        1        -      -  ││                                                │",
                "└────────────────────────────────────────────────┘└────────────────────────────────────────────────┘",
            ]
        );
    }

    #[test]
    fn long_events_wrap_between_words() {
        assert_eq!(wrap("estimator exited with status signal 9", 16), ["estimator exited", "with status", "signal 9"]);
        assert_eq!(wrap("abcdefghij", 4), ["abcd", "efgh", "ij"]);
    }

    #[test]
    fn cpu_ticks_are_counted_after_the_command_name() {
        let stat = "4242 (looplab plant) S 1 2 3 0 -1 4194304 100 0 0 0 250 17 0 0 20 0 3 0 5 1000 100";
        assert_eq!(cpu_ticks(stat), Some(267));
        assert_eq!(cpu_ticks("garbage"), None);
    }

    #[test]
    fn the_whole_screen_fits_120_by_40() {
        let view = view();
        let lines = screen(120, 40, |f| render(f, &view));
        assert!(
            lines[0].contains("pendulum · realtime · 1000 Hz · loop 300 / 2000 (15 %) · deadline misses 1 (0.3 %)")
        );
        assert!(lines[0].ends_with("q: quit"));
        assert!(lines.iter().any(|l| l.contains("┌ theta [rad]: true, estimate ")));
        assert!(lines.iter().any(|l| l.contains("┌ current [A]: command ")));
    }
}
