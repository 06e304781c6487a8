//! Helpers for the integration tests: run the real `looplab` binary (which starts the real
//! processes over real iceoryx2 shared memory) and read what it wrote.

// Each test file uses a part of these helpers and re-exports.
#![allow(dead_code, unused_imports)]

pub mod netns;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU32, Ordering};

pub use looplab_shared::config::faults::FaultKind;
pub use looplab_shared::config::launch::Mode;
pub use looplab_shared::contract::role::Role;
pub use looplab_shared::launcher::inject::DetectedBy;
pub use looplab_shared::launcher::summary::{FaultReport, Summary};
pub use looplab_shared::launcher::{Exit, StopReason};

pub fn looplab() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_looplab"));
    // Under `cargo test` these are set, and the launcher would ask cargo to build its siblings;
    // cargo has built them already.
    command.env_remove("CARGO").env_remove("CARGO_MANIFEST_DIR");
    command
}

/// The launcher, with the `looplab` Python module that cargo builds importable by the stages and
/// plants it starts ([`python_module_dir`] on its PYTHONPATH).
pub fn python_launcher() -> Command {
    let mut command = looplab();
    command.env("PYTHONPATH", python_module_dir());
    command
}

/// A folder from which python3 imports the `looplab` module cargo builds: the workspace's
/// `liblooplab.so` linked as `looplab.so` into `target/<profile>/python-module`.
pub fn python_module_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let target = built();
        let dir = target.join("python-module");
        std::fs::create_dir_all(&dir).unwrap();
        let module = dir.join("looplab.so");
        let _ = std::fs::remove_file(&module);
        std::os::unix::fs::symlink(target.join("liblooplab.so"), &module).unwrap();
        dir
    })
}

/// Nothing of the run is left: the launcher found its shared memory clean, no file of it is in
/// /dev/shm, and none of its processes is alive.
pub fn assert_nothing_left(s: &Summary) {
    assert!(s.shared_memory.clean, "{:?}", s.shared_memory);
    let left = looplab_shared::runtime::storage::run_storage::files_of_run(&s.run_id);
    assert!(left.is_empty(), "files of run {} left behind: {left:?}", s.run_id);
    for p in &s.processes {
        assert!(!alive(i64::from(p.pid)), "{} (pid {}) is still running", p.name, p.pid);
        assert_ne!(p.exit, Exit::Running, "{}", p.name);
    }
}

/// A fresh, not yet existing folder under the system's temp folder.
/// The built-in pendulum's controller gains, as its defaults give them, and the stiffer ones of
/// [`stiff_pendulum`].
pub const BUILTIN_GAINS: &str = "gains = [-378.0, -55.0, -1.0]";
pub const STIFF_GAINS: &str = "gains = [-420.0, -60.0, -1.0]";

/// A scenario a crate of its own adds (`Catalog::with`): the pendulum's entry as
/// `pendulum-stiff`, its controller's default gains raised.
pub fn stiff_pendulum() -> looplab_shared::model::scenario::ScenarioEntry {
    use looplab_shared::scenarios::pendulum;
    let text = pendulum::ENTRY.text.replace(r#"scenario = "pendulum""#, r#"scenario = "pendulum-stiff""#);
    assert!(text.contains(BUILTIN_GAINS), "the pendulum's defaults no longer hold {BUILTIN_GAINS}");
    looplab_shared::model::scenario::ScenarioEntry {
        name: "pendulum-stiff",
        description: "the pendulum with stiffer default gains",
        file: "tests/common/mod.rs",
        text: text.replace(BUILTIN_GAINS, STIFF_GAINS).leak(),
        ..pendulum::ENTRY
    }
}

pub fn fresh_dir(name: &str) -> PathBuf {
    static COUNTER: AtomicU32 = AtomicU32::new(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("looplab-test-{}-{name}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

pub struct Run {
    pub dir: PathBuf,
    pub output: Output,
    /// summary.json as JSON, for the contract of its keys; `summary()` has it typed.
    pub summary: serde_json::Value,
    typed: Summary,
}

impl Run {
    /// The run in `dir`, finished, whose launcher the test started itself.
    pub fn at(dir: PathBuf) -> Run {
        use std::os::unix::process::ExitStatusExt;
        let output = Output { status: std::process::ExitStatus::from_raw(0), stdout: vec![], stderr: vec![] };
        let (summary, typed) = (read_summary(&dir), load_summary(&dir));
        Run { dir, output, summary, typed }
    }

    /// summary.json, typed.
    pub fn summary(&self) -> &Summary {
        &self.typed
    }

    pub fn metric(&self, name: &str) -> f64 {
        self.summary["metrics"][name]
            .as_f64()
            .unwrap_or_else(|| panic!("no metric {name} in {}", self.summary["metrics"]))
    }

    pub fn trajectory(&self) -> Table {
        Table::read(&self.dir.join("trajectory.csv"))
    }

    pub fn stdout(&self) -> String {
        String::from_utf8_lossy(&self.output.stdout).into_owned()
    }
}

impl Drop for Run {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}

/// Runs `looplab run <args> --out <fresh dir> -q` and expects success.
pub fn run(name: &str, args: &[&str]) -> Run {
    run_from(looplab(), name, args)
}

/// `run` with the launcher started by `launcher` (on a test host, say).
pub fn run_from(mut launcher: Command, name: &str, args: &[&str]) -> Run {
    let dir = fresh_dir(name);
    let output = launcher.arg("run").args(args).arg("--out").arg(&dir).arg("-q").output().expect("start looplab");
    assert!(
        output.status.success(),
        "looplab run {args:?} failed ({}):\n{}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let summary = read_summary(&dir);
    let typed = load_summary(&dir);
    Run { dir, output, summary, typed }
}

/// `run` with `--in-process`: the same plant, sensors, estimator and controller in loop order in
/// one process, byte-identical to the five-process lockstep run (tests/trajectory_hashes.rs
/// proves it); for tests of the models' numbers, which need no transport.
#[allow(dead_code)]
pub fn run_in_process(name: &str, args: &[&str]) -> Run {
    let mut args = args.to_vec();
    args.push("--in-process");
    run(name, &args)
}

/// `f` over `items` on two threads (CI has two cores), the results in the items' order.
pub fn on_two_threads<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let (first, second) = items.split_at(items.len().div_ceil(2));
    std::thread::scope(|scope| {
        let other = scope.spawn(|| second.iter().map(&f).collect::<Vec<_>>());
        let mut results: Vec<R> = first.iter().map(&f).collect();
        results.extend(other.join().expect("the second thread's runs"));
        results
    })
}

pub fn read_summary(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json is JSON")
}

/// summary.json, typed.
pub fn load_summary(dir: &Path) -> Summary {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("summary.json is a Summary: {e}"))
}

/// Every process's last incarnation, by role.
pub fn last_incarnations(s: &Summary) -> BTreeMap<Role, &looplab_shared::launcher::summary::ProcessInfo> {
    s.processes.iter().map(|p| (p.name, p)).collect()
}

/// The loops in the monitor's listed missing ranges.
pub fn listed_missing(s: &Summary) -> u64 {
    s.monitor.missing.ranges.iter().map(|[first, last]| last - first + 1).sum()
}

/// A CSV file by column name.
pub struct Table {
    pub columns: BTreeMap<String, usize>,
    pub rows: Vec<Vec<String>>,
}

impl Table {
    pub fn read(path: &Path) -> Self {
        let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut lines = text.lines();
        let columns = lines.next().expect("header").split(',').enumerate().map(|(i, c)| (c.to_owned(), i)).collect();
        let rows = lines.map(|l| l.split(',').map(str::to_owned).collect()).collect();
        Self { columns, rows }
    }

    /// A numeric column (panics on an empty cell: tests read complete runs). It parses the
    /// whole column on every call: take it once, outside loops.
    pub fn col(&self, name: &str) -> Vec<f64> {
        let i = *self.columns.get(name).unwrap_or_else(|| panic!("no column {name}; have {:?}", self.columns.keys()));
        self.rows
            .iter()
            .map(|r| r[i].parse().unwrap_or_else(|_| panic!("{name}: {:?} is not a number", r[i])))
            .collect()
    }
}

/// Every cell of loops.csv but `t_s` and `cause` is a whole number or empty (a part that did not
/// arrive), so a reader can take the stamps as integers; `t_s` is a number, `cause` words or
/// empty. Returns the number of rows.
pub fn assert_loops_csv_integers(dir: &Path) -> usize {
    let loops = Table::read(&dir.join("loops.csv"));
    let (t, cause) = (loops.columns["t_s"], loops.columns["cause"]);
    for (line, row) in loops.rows.iter().enumerate() {
        assert_eq!(row.len(), loops.columns.len(), "loops.csv line {}", line + 2);
        for (i, cell) in row.iter().enumerate() {
            let ok = if i == t {
                cell.parse::<f64>().is_ok()
            } else if i == cause {
                cell.bytes().all(|b| b.is_ascii_lowercase() || b" :->".contains(&b))
            } else {
                cell.is_empty() || cell.parse::<u64>().is_ok()
            };
            assert!(ok, "loops.csv line {}, column {}: {cell:?}", line + 2, i + 1);
        }
    }
    loops.rows.len()
}

/// True if a process with this pid exists (and is not a zombie of ours).
pub fn alive(pid: i64) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| !stat.contains(") Z "))
}

/// A PNG's width and height from its header (the IHDR chunk follows the signature).
pub fn png_size(path: &Path) -> (u32, u32) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{} is not a PNG", path.display());
    assert_eq!(&bytes[12..16], b"IHDR");
    let number = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
    (number(16), number(20))
}

/// The profile's target folder (target/release under `cargo test --release`), where cargo puts
/// the launcher, the C library, its header and the Rust example.
pub fn profile_dir() -> PathBuf {
    Path::new(env!("CARGO_BIN_EXE_looplab")).parent().expect("the launcher is in a folder").to_owned()
}

/// The C library, its header, the Rust example and the Python module, built (or found fresh)
/// once: they are not dependencies of the tests, so cargo may not have built them since the last
/// change.
pub fn built() -> &'static Path {
    static BUILT: OnceLock<PathBuf> = OnceLock::new();
    BUILT.get_or_init(|| {
        let dir = profile_dir();
        let needed = ["liblooplab_stage.so", "looplab_stage.h", "looplab-example-controller", "liblooplab.so"];
        cargo_build(&dir);
        for file in needed {
            assert!(dir.join(file).exists(), "{} is missing after the build", dir.join(file).display());
        }
        dir
    })
}

/// `cargo build --workspace --all-targets` in the tests' profile: every target `cargo test
/// --workspace` builds, with the same features, so it finds them fresh and only links what the
/// tests do not (the C library, the example, the Python module). A `-p` build would resolve the
/// dependencies' features for those packages alone and compile LoopLab a second time. Where the
/// running `cargo test` holds the build folder's lock, cargo would wait for it for ever: that is
/// a failure that says what to run first.
fn cargo_build(dir: &Path) {
    let release = dir.file_name().is_some_and(|name| name == "release");
    let mut command = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    command.current_dir(env!("CARGO_MANIFEST_DIR")).args(["build", "--workspace", "--all-targets"]);
    if release {
        command.arg("--release");
    }
    let mut child = command.stderr(Stdio::piped()).spawn().expect("start cargo");
    let mut said = Vec::new();
    for line in BufReader::new(child.stderr.take().expect("piped")).lines() {
        let line = line.expect("cargo's stderr");
        if line.contains("Blocking waiting for file lock") {
            child.kill().expect("stop cargo");
            let _ = child.wait();
            panic!(
                "the C library, the Rust example or the Python module is not built, and cargo cannot build it while \
                 this cargo test holds the build folder: run `cargo build{} --workspace --all-targets` first",
                if release { " --release" } else { "" }
            );
        }
        said.push(line);
    }
    let status = child.wait().expect("cargo ends");
    assert!(status.success(), "cargo build failed:\n{}", said.join("\n"));
}
