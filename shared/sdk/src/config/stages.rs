//! Stages of the user's own: the `[stages]` section of a launch file.
//!
//! ```toml
//! [stages.controller]
//! command = ["python3", "my_controller.py"]   # the program and its arguments
//! # dir = "../loop"                           # where it starts, relative to the launch file's
//!                                             # folder (default: that folder)
//! # build = ["cc", "-O2", "c.c", "-o", "c"]   # run first, in `dir`, when what it names changed
//! # with_reference = true                     # the controller only: a declared system's
//!                                             # [reference] at t after the estimate in its input
//! ```
//!
//! The launcher starts the command in place of the built-in stage, with the run's arguments in
//! its environment (`contract::protocol::stage_env`); the program hands its computation to
//! LoopLab's runner (`runtime::stage::user_stage`: the `looplab` Python module, the `looplab_stage` C
//! library, or the Rust library), so it is stamped, supervised and faulted as a built-in stage is.

use std::collections::BTreeMap;
use std::path::{Component, Path, PathBuf};
use std::time::Duration;

use crate::config::stage_build;
use crate::contract::role::Role;

/// The stages a launch file may replace.
pub const REPLACEABLE: [Role; 3] = Role::STAGES;

/// One stage's command.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StageCommand {
    /// The program, then its arguments.
    pub command: Vec<String>,
    /// The folder it starts in: relative paths in the command are relative to it.
    pub dir: PathBuf,
    /// The command that builds it, run before the run (`config::stage_build`); empty: none.
    pub build: Vec<String>,
    /// The folder the build runs in: `dir` where the table gives one, else the folder of the
    /// file (or the command line) that gave `build`, which may differ from the command's (a
    /// `--set` command on a launch file's build).
    pub build_dir: PathBuf,
    /// The controller's input carries a declared system's references at t after the estimate
    /// (`reference.<track>`).
    pub with_reference: bool,
}

/// The `[stages]` section, checked.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Stages {
    pub commands: BTreeMap<Role, StageCommand>,
    /// `[plant] python`: the plant as a Python class, started as the plant's command
    /// (`config::python_plant`).
    pub plant: Option<StageCommand>,
}

impl Stages {
    /// Reads `[stages]`. `default_dir(key)` is the folder a command given at dotted `key` starts
    /// in when its table has no `dir`; `error(key, message)` makes the error for a dotted key.
    pub fn parse<E>(
        table: &toml::Table,
        default_dir: impl Fn(&str) -> PathBuf,
        error: impl Fn(&str, String) -> E,
    ) -> Result<Self, E> {
        let allowed = || REPLACEABLE.iter().map(|r| r.name()).collect::<Vec<_>>().join(", ");
        let mut stages = Stages::default();
        for (name, value) in table {
            let key = format!("stages.{name}");
            let role = name
                .parse::<Role>()
                .ok()
                .filter(|r| REPLACEABLE.contains(r))
                .ok_or_else(|| error(&key, format!("unknown stage; allowed: {}", allowed())))?;
            let toml::Value::Table(spec) = value else {
                return Err(error(&key, format!("expected a table with `command`, got a {}", value.type_str())));
            };
            const KEYS: [&str; 4] = ["command", "dir", "build", "with_reference"];
            if let Some(unknown) = spec.keys().find(|k| !KEYS.contains(&k.as_str())) {
                return Err(error(&format!("{key}.{unknown}"), format!("unknown key; allowed: {}", KEYS.join(", "))));
            }
            let with_reference = match spec.get("with_reference") {
                None => false,
                Some(toml::Value::Boolean(on)) if !*on || role == Role::Controller => *on,
                Some(toml::Value::Boolean(_)) => {
                    return Err(error(
                        &format!("{key}.with_reference"),
                        "only [stages.controller] takes it: the reference goes to the controller".into(),
                    ));
                }
                Some(other) => {
                    return Err(error(
                        &format!("{key}.with_reference"),
                        format!("true or false, got a {}", other.type_str()),
                    ));
                }
            };
            let command_key = format!("{key}.command");
            let command = match spec.get("command") {
                Some(value) => program_and_arguments(value, &command_key, &error)?,
                None => return Err(error(&command_key, "missing: the program and its arguments, as a list".into())),
            };
            let build_key = format!("{key}.build");
            let build = match spec.get("build") {
                Some(value) => program_and_arguments(value, &build_key, &error)?,
                None => Vec::new(),
            };
            if build.first().is_some_and(String::is_empty) {
                return Err(error(&build_key, "must name a program: [\"make\"]".into()));
            }
            if command.first().is_none_or(|program| program.is_empty()) {
                return Err(error(&command_key, "must name a program: [\"python3\", \"my_stage.py\"]".into()));
            }
            let dir = match spec.get("dir") {
                // Relative: to the file that gives it (a run's launch.toml: to the run folder).
                Some(toml::Value::String(dir)) => joined(&default_dir(&format!("{key}.dir")), Path::new(dir)),
                Some(other) => {
                    return Err(error(
                        &format!("{key}.dir"),
                        format!("must be a folder's path, got a {}", other.type_str()),
                    ));
                }
                None => default_dir(&command_key),
            };
            let build_dir = if spec.contains_key("dir") { dir.clone() } else { default_dir(&build_key) };
            stages.commands.insert(role, StageCommand { command, dir, build, build_dir, with_reference });
        }
        Ok(stages)
    }

    /// The command `role` starts as, if the launch file gives one (a Python plant's for the plant).
    pub fn command(&self, role: Role) -> Option<&StageCommand> {
        match role {
            Role::Plant => self.plant.as_ref(),
            _ => self.commands.get(&role),
        }
    }

    /// Writes each stage's folder into `table` (the document's `[stages]`), so that the resolved
    /// launch file in the run folder starts each stage where this one does; its `build` is left
    /// out, done before the run (a replay of the run runs the program the run ran).
    pub fn write_dirs(&self, table: &mut toml::Table) {
        for (role, stage) in &self.commands {
            if let Some(toml::Value::Table(spec)) = table.get_mut(role.name()) {
                spec.insert("dir".into(), toml::Value::String(stage.dir.display().to_string()));
                spec.remove("build");
            }
        }
    }
}

/// `path` with each `..` taking off the folder before it and each `.` left out, as written (no
/// link followed): what a folder relative to another reads as.
pub fn joined(base: &Path, relative: &Path) -> PathBuf {
    let mut path = PathBuf::new();
    for part in base.join(relative).components() {
        match part {
            Component::CurDir => {}
            Component::ParentDir => match path.components().next_back() {
                Some(Component::Normal(_)) => {
                    path.pop();
                }
                // Above the root is the root.
                Some(Component::RootDir) => {}
                _ => path.push(".."),
            },
            other => path.push(other),
        }
    }
    path
}

#[cfg(test)]
#[test]
fn a_joined_path_takes_off_a_folder_for_each_parent_and_leaves_out_each_current() {
    assert_eq!(joined(Path::new("/a/b"), Path::new("./c/../d")), Path::new("/a/b/d"));
    assert_eq!(joined(Path::new("/a/b"), Path::new("../../../x")), Path::new("/x"));
    assert_eq!(joined(Path::new("/a"), Path::new("/x/./y")), Path::new("/x/y"));
}

/// A list of strings, the program and its arguments, at dotted `key`.
fn program_and_arguments<E>(
    value: &toml::Value,
    key: &str,
    error: impl Fn(&str, String) -> E,
) -> Result<Vec<String>, E> {
    match value {
        toml::Value::Array(items) => items
            .iter()
            .map(|item| item.as_str().map(str::to_owned))
            .collect::<Option<_>>()
            .ok_or_else(|| error(key, "must be a list of strings: the program, then its arguments".into())),
        other => Err(error(
            key,
            format!("must be a list of strings (the program, then its arguments), got a {}", other.type_str()),
        )),
    }
}

/// Runs `command` to its end, its stderr kept, in a process group of its own that is killed
/// whole past `limit`: a check that runs the user's code (an import that never returns) is an
/// error, never a hang. Err: why it did not finish, in words.
pub fn output_within(mut command: std::process::Command, limit: Duration) -> Result<std::process::Output, String> {
    use std::os::unix::process::CommandExt;
    let mut child = command
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .process_group(0)
        .spawn()
        .map_err(|e| format!("cannot be run: {e}"))?;
    let mut stderr = child.stderr.take().expect("stderr is piped");
    let reader = std::thread::spawn(move || {
        let mut text = Vec::new();
        let _ = std::io::Read::read_to_end(&mut stderr, &mut text);
        text
    });
    let until = std::time::Instant::now() + limit;
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| format!("cannot be waited for: {e}"))? {
            break status;
        }
        if std::time::Instant::now() >= until {
            // SAFETY: killpg of the group our unreaped child leads.
            unsafe { libc::killpg(child.id() as libc::pid_t, libc::SIGKILL) };
            let _ = child.wait();
            return Err(format!(
                "did not finish within {} s (supervision.ready_timeout_s); killed it",
                limit.as_secs_f64()
            ));
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Ok(std::process::Output { status, stdout: vec![], stderr: reader.join().unwrap_or_default() })
}

impl StageCommand {
    /// The program as it will be run: a path with a `/` is taken from the stage's folder, a bare
    /// name from PATH. Err: what is wrong, in words.
    pub fn program(&self) -> Result<PathBuf, String> {
        let program = &self.command[0];
        if program.contains('/') {
            let path = self.dir.join(program);
            return if is_executable(&path) {
                Ok(path)
            } else {
                Err(format!("program {program} is not an executable file in {}", self.dir.display()))
            };
        }
        let path = std::env::var_os("PATH").unwrap_or_default();
        std::env::split_paths(&path)
            .map(|folder| folder.join(program))
            .find(|candidate| is_executable(candidate))
            .ok_or_else(|| format!("program {program} is not found on PATH"))
    }

    /// Checks, before anything starts, that the command can run: its program exists, every
    /// script it names (`.py`) exists, and a Python interpreter can import LoopLab's module
    /// within `limit`.
    pub fn check(&self, limit: Duration) -> Result<(), String> {
        let program = self.program()?;
        for script in self.command[1..].iter().filter(|a| a.ends_with(".py")) {
            if !self.dir.join(script).is_file() {
                return Err(format!("script {script} is not found in {}", self.dir.display()));
            }
        }
        let is_python =
            Path::new(&self.command[0]).file_name().is_some_and(|n| n.to_string_lossy().starts_with("python"));
        if is_python {
            let mut import = std::process::Command::new(&program);
            import.args(["-c", "import looplab"]).current_dir(&self.dir);
            let imported = output_within(import, limit)
                .map_err(|e| format!("{} -c \"import looplab\" (in {}) {e}", self.command[0], self.dir.display()))?;
            if !imported.status.success() {
                let why = String::from_utf8_lossy(&imported.stderr);
                let last = why.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("it failed");
                return Err(format!(
                    "{} cannot import LoopLab's Python module ({last}); install it: pip install ./services/python",
                    self.command[0]
                ));
            }
        }
        Ok(())
    }

    /// Runs its `build`, if it has one, unless nothing it names changed since it last succeeded
    /// (`config::stage_build`). Err: the build failed, in one line.
    pub fn build(&self) -> Result<Option<stage_build::Built>, String> {
        if self.build.is_empty() {
            return Ok(None);
        }
        let program = self.command[0].contains('/').then(|| self.dir.join(&self.command[0]));
        stage_build::build(&self.build, &self.build_dir, program.as_deref()).map(Some)
    }

    /// The command as one line for messages: `python3 my_controller.py`.
    pub fn text(&self) -> String {
        self.command.join(" ")
    }
}

fn is_executable(path: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    path.metadata().is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Stages, String> {
        let table: toml::Table = toml::from_str(text).unwrap();
        Stages::parse(&table, |_| PathBuf::from("/launch"), |key, message| format!("{key}: {message}"))
    }

    #[test]
    fn a_stage_command_is_a_program_and_its_arguments_started_in_the_launch_folder() {
        let stages = parse("[controller]\ncommand = [\"python3\", \"c.py\"]\n").unwrap();
        let c = stages.command(Role::Controller).unwrap();
        assert_eq!((c.command.clone(), c.dir.clone()), (vec!["python3".into(), "c.py".into()], "/launch".into()));
        assert_eq!(
            parse("[sensors]\ncommand = [\"./s\"]\ndir = \"/x\"\n").unwrap().commands[&Role::Sensors].dir,
            Path::new("/x")
        );
    }

    #[test]
    fn a_bad_stages_section_is_one_line_naming_the_key_and_what_is_allowed() {
        let cases = [
            ("[plant]\ncommand = [\"x\"]\n", "stages.plant: unknown stage; allowed: sensors, estimator, controller"),
            ("[controller]\n", "stages.controller.command: missing: the program and its arguments, as a list"),
            (
                "[controller]\ncommand = \"python3 c.py\"\n",
                "stages.controller.command: must be a list of strings (the program, then its arguments), got a string",
            ),
            (
                "[controller]\ncommand = []\n",
                "stages.controller.command: must name a program: [\"python3\", \"my_stage.py\"]",
            ),
            (
                "[controller]\ncommand = [\"x\"]\nargs = 1\n",
                "stages.controller.args: unknown key; allowed: command, dir, build, with_reference",
            ),
            ("controller = 3\n", "stages.controller: expected a table with `command`, got a integer"),
            (
                "estimator = { command = [\"e\"], with_reference = true }\n",
                "stages.estimator.with_reference: only [stages.controller] takes it: the reference goes to the controller",
            ),
        ];
        for (text, expected) in cases {
            assert_eq!(parse(text).unwrap_err(), expected, "{text}");
        }
    }

    #[test]
    fn a_missing_program_or_script_is_found_before_anything_starts() {
        const LIMIT: Duration = Duration::from_secs(20);
        let stage = |command: &[&str]| StageCommand {
            command: command.iter().map(|s| s.to_string()).collect(),
            dir: std::env::temp_dir(),
            build: Vec::new(),
            build_dir: std::env::temp_dir(),
            with_reference: false,
        };
        assert_eq!(
            stage(&["no-such-program-ll"]).check(LIMIT).unwrap_err(),
            "program no-such-program-ll is not found on PATH"
        );
        assert!(stage(&["sh", "-c", "true"]).check(LIMIT).is_ok());
        let missing = stage(&["sh", "no-such-script-ll.py"]).check(LIMIT).unwrap_err();
        assert!(missing.starts_with("script no-such-script-ll.py is not found in "), "{missing}");
        let relative = stage(&["./no-such-binary-ll"]).check(LIMIT).unwrap_err();
        assert!(relative.starts_with("program ./no-such-binary-ll is not an executable file in "), "{relative}");
    }
}
