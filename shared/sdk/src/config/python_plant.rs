//! A plant in Python: `[plant] python = "my_plant.py:Pendulum"` in a declared system's launch
//! file.
//!
//! ```toml
//! [plant]
//! python = "pendulum_plant.py:Pendulum"   # the file (in the launch file's folder) and its class
//! ```
//!
//! The launcher starts the plant role as `python3` running `looplab.run_plant` (the `looplab`
//! Python module, `services/python`) in the launch file's folder, as it starts a `[stages]`
//! command; the module builds the model over an instance of the class and runs LoopLab's own plant
//! process with it (`runtime::stage::user_plant`). Before anything starts, the launcher checks that the
//! file imports and that its class has `derivative`: a plant that cannot start is bad input.

use std::path::PathBuf;

use crate::config::stages::StageCommand;

/// What the plant's python3 runs: the module's runner, given `file.py:Class`.
pub const RUN_PLANT: &str = "import sys, looplab; looplab.run_plant(sys.argv[1])";
/// What the launcher runs to check the plant before anything starts: exits 2 with one line on
/// stderr if the file does not import or its class is missing or lacks `derivative`.
pub const CHECK_PLANT: &str = "import sys, looplab; sys.exit(looplab.check_plant(sys.argv[1]))";

/// The dotted key of a Python plant in a launch file.
pub const KEY: &str = "plant.python";

/// `[plant] python` of `document`, if it has one: the command the launcher starts as the plant,
/// in `dir` (the folder the file is found in, the launch file's). Err: what is wrong with its
/// form, in words.
pub fn parse(document: &toml::Table, dir: PathBuf) -> Result<Option<StageCommand>, String> {
    let Some(value) = document.get("plant").and_then(|plant| plant.get("python")) else { return Ok(None) };
    let spec = value.as_str().ok_or_else(|| {
        format!("must be a string, the file and its class: \"my_plant.py:Pendulum\", got a {}", value.type_str())
    })?;
    let (file, class) = spec
        .rsplit_once(':')
        .ok_or_else(|| format!("\"{spec}\" names no class; write the file and its class: \"my_plant.py:Pendulum\""))?;
    if !file.ends_with(".py") || file.len() == 3 {
        return Err(format!("\"{spec}\": {file:?} is not a Python file (.py)"));
    }
    let identifier = class.chars().next().is_some_and(|c| c.is_alphabetic() || c == '_')
        && class.chars().all(|c| c.is_alphanumeric() || c == '_');
    if !identifier {
        return Err(format!("\"{spec}\": {class:?} is not a Python class name"));
    }
    let command = ["python3", "-c", RUN_PLANT, spec].map(str::to_owned).to_vec();
    Ok(Some(StageCommand { command, build_dir: dir.clone(), dir, build: Vec::new(), with_reference: false }))
}

/// `file.py:Class` of a Python plant's command (what [`parse`] made).
pub fn spec(plant: &StageCommand) -> &str {
    plant.command.last().map_or("", String::as_str)
}

/// Checks, before anything starts, that the plant `parse` made can start: the file exists,
/// python3 imports LoopLab's module, and the file's class has `derivative`. Err: what is wrong,
/// one line.
pub fn check(plant: &StageCommand, limit: std::time::Duration) -> Result<(), String> {
    let (spec, dir) = (spec(plant), &plant.dir);
    let file = spec.rsplit_once(':').map_or(spec, |(file, _)| file);
    if !dir.join(file).is_file() {
        return Err(format!("{file} is not found in {}", dir.display()));
    }
    plant.check(limit)?;
    let program = plant.program()?;
    let mut command = std::process::Command::new(&program);
    command.args(["-c", CHECK_PLANT, spec]).current_dir(dir);
    let checked = crate::config::stages::output_within(command, limit).map_err(|e| format!("checking {spec}: {e}"))?;
    if checked.status.success() {
        return Ok(());
    }
    let why = String::from_utf8_lossy(&checked.stderr);
    Err(why.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("its check failed").trim().to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Option<StageCommand>, String> {
        super::parse(&toml::from_str(text).unwrap(), PathBuf::from("/launch"))
    }

    #[test]
    fn a_python_plant_is_its_file_and_class_run_by_the_module_in_the_launch_folder() {
        let plant = parse("[plant]\npython = \"sub/my_plant.py:Pendulum\"\n").unwrap().unwrap();
        assert_eq!(spec(&plant), "sub/my_plant.py:Pendulum");
        assert_eq!(plant.command, ["python3", "-c", RUN_PLANT, "sub/my_plant.py:Pendulum"]);
        assert_eq!(plant.dir, PathBuf::from("/launch"));
        assert_eq!(parse("[plant]\nlinear = {}\n").unwrap(), None);
        assert_eq!(parse("x = 1\n").unwrap(), None);
    }

    #[test]
    fn a_bad_python_plant_is_one_line_saying_what_to_write() {
        let cases = [
            ("python = 3", "must be a string, the file and its class: \"my_plant.py:Pendulum\", got a integer"),
            ("python = \"p.py\"", "\"p.py\" names no class; write the file and its class: \"my_plant.py:Pendulum\""),
            ("python = \"p.txt:P\"", "\"p.txt:P\": \"p.txt\" is not a Python file (.py)"),
            ("python = \"p.py:1P\"", "\"p.py:1P\": \"1P\" is not a Python class name"),
            ("python = \"p.py:\"", "\"p.py:\": \"\" is not a Python class name"),
        ];
        for (line, expected) in cases {
            assert_eq!(parse(&format!("[plant]\n{line}\n")).unwrap_err(), expected, "{line}");
        }
    }
}
