//! When the kills and stops of a real-time run really happened: the launcher sends them by
//! signal at wall-clock time, and a launcher that was stopped or starved sends them late. It
//! writes here, at each injection, the loop at which each fault really took effect; the monitor
//! reads it at each checkpoint and at its end, and judges each fault's effect from that loop
//! ([`crate::monitor::fault_effect`]).
//!
//! The file lies in the run's private folder on tmpfs, beside `monitor.state`: no other user can
//! read or forge it. It is rewritten whole under another name and renamed into place, so a
//! reader never sees half of it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, Result};
use serde::{Deserialize, Serialize};

use crate::runtime::storage::private_file;

/// What became of one fault the launcher injects.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Injection {
    /// Injected before this loop's tick, after the one before.
    AtLoop(u64),
    /// Never injected: its process was not running at its time.
    NotInjected,
}

/// By the fault's index in the launch file; a fault not here was not injected yet.
pub type Injections = BTreeMap<usize, Injection>;

/// The injections file of run `run_id`.
pub fn path(run_id: &str) -> Result<PathBuf> {
    let folder = crate::runtime::storage::run_storage::run_folder(run_id);
    crate::runtime::storage::run_storage::check_private(&folder)?;
    Ok(folder.join("injections.json"))
}

/// Writes `injections` to `path`, whole or not at all.
pub fn write(path: &Path, injections: &Injections) -> Result<()> {
    private_file::write(path, &serde_json::to_vec(injections)?)
}

/// What the launcher wrote; nothing if it wrote nothing yet.
pub fn read(path: &Path) -> Result<Injections> {
    let Some(bytes) = private_file::read(path)? else { return Ok(Injections::new()) };
    serde_json::from_slice(&bytes).with_context(|| format!("decode {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn injections_are_read_back_as_written_and_none_before_the_first() {
        let dir = std::env::temp_dir().join(format!("looplab-injections-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("injections.json");
        assert_eq!(read(&path).unwrap(), Injections::new());
        let injections = Injections::from([(0, Injection::AtLoop(3000)), (2, Injection::NotInjected)]);
        write(&path, &injections).unwrap();
        let back = read(&path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(back, injections);
        assert_eq!(text, r#"{"0":{"at-loop":3000},"2":"not-injected"}"#);
    }
}
