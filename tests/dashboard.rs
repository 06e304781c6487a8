//! `looplab run --dashboard` in a pseudo-terminal: the screen it draws, read back with a terminal
//! emulator (vt100), and `q` stopping the run in order.

use crate::common;

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{FromRawFd, OwnedFd};
use std::os::unix::process::CommandExt;
use std::process::Stdio;

use common::{StopReason, fresh_dir, load_summary, looplab};

const ROWS: u16 = 40;
const COLUMNS: u16 = 120;

/// A pseudo-terminal of ROWS × COLUMNS: (master, slave).
fn open_pty() -> (OwnedFd, OwnedFd) {
    let (mut master, mut slave) = (-1, -1);
    let size = libc::winsize { ws_row: ROWS, ws_col: COLUMNS, ws_xpixel: 0, ws_ypixel: 0 };
    // SAFETY: openpty fills in two new descriptors, which we then own.
    let done = unsafe { libc::openpty(&mut master, &mut slave, std::ptr::null_mut(), std::ptr::null(), &size) };
    assert_eq!(done, 0, "openpty: {}", std::io::Error::last_os_error());
    // SAFETY: both are open descriptors nobody else owns.
    unsafe { (OwnedFd::from_raw_fd(master), OwnedFd::from_raw_fd(slave)) }
}

/// The screen's text once `done` holds for it; None if the terminal closed first.
fn screen_when(output: &mut File, parser: &mut vt100::Parser, done: impl Fn(&str) -> bool) -> Option<String> {
    let mut buffer = [0u8; 4096];
    loop {
        let contents = parser.screen().contents();
        if done(&contents) {
            return Some(contents);
        }
        // Linux answers EIO once the other side of the terminal is closed.
        match output.read(&mut buffer) {
            Ok(0) | Err(_) => return None,
            Ok(n) => parser.process(&buffer[..n]),
        }
    }
}

/// The launcher under test: if an assertion fails before `q` ends the run, Ctrl-C's signal stops
/// it in order, so a failed test leaves no run going.
struct Launcher(std::process::Child);

impl Drop for Launcher {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            // SAFETY: a signal to our own child, which we have not reaped.
            unsafe { libc::kill(self.0.id() as libc::pid_t, libc::SIGINT) };
            let _ = self.0.wait();
        }
    }
}

#[test]
fn the_dashboard_shows_the_loop_live_and_q_stops_the_run_in_order() {
    let out_dir = fresh_dir("dashboard");
    let (master, slave) = open_pty();
    let mut command = looplab();
    command
        .args(["run", "pendulum", "--duration", "60", "--dashboard", "--out"])
        .arg(&out_dir)
        .stdin(Stdio::from(slave.try_clone().unwrap()))
        .stdout(Stdio::from(slave.try_clone().unwrap()))
        .stderr(Stdio::from(slave));
    // SAFETY: between fork and exec only async-signal-safe calls: a new session whose
    // controlling terminal is the pty (stdin), as a shell would give it.
    unsafe {
        command.pre_exec(|| {
            if libc::setsid() < 0 || libc::ioctl(0, libc::TIOCSCTTY, 0) < 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let mut launcher = Launcher(command.spawn().unwrap());
    drop(command); // closes our copies of the slave, so the master sees the end of the output
    let mut input = File::from(master);
    let mut output = input.try_clone().unwrap();
    let mut parser = vt100::Parser::new(ROWS.try_into().unwrap(), COLUMNS.try_into().unwrap(), 0);

    // Every process up and every row of the latency table with a number in it.
    let rows = ["plant → sensors", "sensors → estimator", "estimator → controller", "controller → plant", "end to end"];
    let live = |screen: &str| {
        let has_numbers = |name: &str| {
            screen.lines().any(|l| l.contains(name) && l.split_whitespace().any(|w| w.parse::<f64>().is_ok()))
        };
        rows.iter().all(|r| has_numbers(r)) && screen.matches(" running ").count() == 5
    };
    let screen = screen_when(&mut output, &mut parser, live);
    let screen = screen
        .unwrap_or_else(|| panic!("the dashboard ended before it showed the loop:\n{}", parser.screen().contents()));
    for title in
        ["LoopLab", "pendulum · realtime · 1000 Hz", "Latency, µs", "Processes", "Faults, detections", "q: quit"]
    {
        assert!(screen.contains(title), "no {title:?} on the screen:\n{screen}");
    }
    for header in ["p50", "p99", "max", "run max", "tick period error"] {
        assert!(screen.contains(header), "no {header:?} on the screen:\n{screen}");
    }
    for process in ["plant", "sensors", "estimator", "controller", "monitor"] {
        let row = |l: &str| l.trim_start_matches('│').starts_with(process) && l.contains(" running ");
        assert!(screen.lines().any(row), "{process} is not running:\n{screen}");
    }
    assert!(screen.contains("theta [rad]: true, estimate") && screen.contains("current [A]: command"), "{screen}");

    input.write_all(b"q").unwrap();
    // Drain the terminal until the launcher and its children have closed it.
    screen_when(&mut output, &mut parser, |_| false);
    let status = launcher.0.wait().unwrap();
    let after = parser.screen().contents();
    assert_eq!(status.code(), Some(0), "q ends the run with 0:\n{after}");
    // The report is printed on the restored terminal, after the dashboard.
    assert!(after.contains("shared memory: clean, no file of the run is left"), "{after}");
    let summary = load_summary(&out_dir);
    assert_eq!(summary.stopped_because, Some(StopReason::Quit));
    assert!(summary.shared_memory.clean);
    assert!(summary.loops > 0 && summary.loops < summary.loops_planned);
    std::fs::remove_dir_all(&out_dir).unwrap();
}

#[test]
fn the_dashboard_needs_a_terminal() {
    let out_dir = fresh_dir("dashboard-no-tty");
    let out = looplab().args(["run", "--dashboard", "--out"]).arg(&out_dir).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert_eq!(
        stderr,
        "error: --dashboard: standard output is not a terminal; run it in one, or leave out --dashboard\n"
    );
    assert!(!out_dir.exists());
}
