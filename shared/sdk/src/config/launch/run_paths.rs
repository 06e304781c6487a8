//! The user's files as a run's `launch.toml` refers to them: each stage's `dir` and a declared
//! plant's `folder` relative to the run folder, so that a run folder moves with the files beside
//! it (a golden run in a repository, checked out elsewhere by CI). A relative path in a launch
//! file is relative to that file's folder, so the run's file reads back to the same folders.

use std::path::{Component, Path, PathBuf};

/// `target` as a path from `base` (`..` where it must climb); both made absolute and canonical
/// where they exist. None where they share no root.
pub fn relative_to(base: &Path, target: &Path) -> Option<PathBuf> {
    let canonical = |p: &Path| p.canonicalize().ok().or_else(|| std::path::absolute(p).ok());
    let (base, target) = (canonical(base)?, canonical(target)?);
    let (base, target): (Vec<Component>, Vec<Component>) = (base.components().collect(), target.components().collect());
    let common = base.iter().zip(&target).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return None;
    }
    let mut path: PathBuf = base[common..].iter().map(|_| Component::ParentDir).collect();
    path.extend(&target[common..]);
    Some(if path.as_os_str().is_empty() { PathBuf::from(".") } else { path })
}

/// Rewrites the folders `document` names (`[stages.<role>] dir`, `[plant] folder`), absolute
/// once resolved, relative to `run_dir`.
pub(super) fn make_relative(document: &mut toml::Table, run_dir: &Path) {
    let relative = |folder: &mut toml::Value| {
        if let toml::Value::String(path) = folder
            && let Some(relative) = relative_to(run_dir, Path::new(path.as_str()))
        {
            *path = relative.display().to_string();
        }
    };
    if let Some(toml::Value::Table(stages)) = document.get_mut("stages") {
        stages.iter_mut().filter_map(|(_, stage)| stage.get_mut("dir")).for_each(relative);
    }
    if let Some(folder) = document.get_mut("plant").and_then(|plant| plant.get_mut("folder")) {
        relative(folder);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_folder_is_written_from_the_run_folder_and_reads_back_to_itself() {
        let root = std::env::temp_dir().join(format!("looplab-run-paths-{}", std::process::id()));
        let (run, scripts) = (root.join("golden/run1"), root.join("controllers"));
        std::fs::create_dir_all(&run).unwrap();
        std::fs::create_dir_all(&scripts).unwrap();
        assert_eq!(relative_to(&run, &scripts).unwrap(), Path::new("../../controllers"));
        assert_eq!(relative_to(&run, &run).unwrap(), Path::new("."));
        assert_eq!(relative_to(&run, &run.join("x")).unwrap(), Path::new("x"));
        let mut document: toml::Table = toml::from_str(&format!(
            "[stages.controller]\ncommand = [\"python3\", \"c.py\"]\ndir = \"{}\"\n[plant]\nfolder = \"{}\"\n",
            scripts.display(),
            root.display()
        ))
        .unwrap();
        make_relative(&mut document, &run);
        assert_eq!(document["stages"]["controller"]["dir"].as_str(), Some("../../controllers"));
        assert_eq!(document["plant"]["folder"].as_str(), Some("../.."));
        assert_eq!(run.join("../../controllers").canonicalize().unwrap(), scripts.canonicalize().unwrap());
        assert_eq!(crate::config::stages::joined(&run, Path::new("../../controllers")), root.join("controllers"));
        std::fs::remove_dir_all(&root).unwrap();
    }
}
