//! A run's storage in shared memory: its private folder (iceoryx2's root, snapshots, the
//! launcher's lock, the secret of its names), created fresh and owner-only; the cleanup of what a
//! run leaves, and of runs whose launcher was killed.

use std::collections::BTreeSet;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow, bail};
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;

use crate::runtime::signals::StopFlag;
use crate::runtime::storage::shm_secret::{read_secret, write_secret};

/// The public part of a run's file names: every file of the run in `SHM_DIR` starts with it
/// (clean-up matches it, and needs no secret), and so may a file another user made.
pub fn file_prefix(run_id: &str) -> String {
    format!("looplab_{run_id}_")
}

/// The iceoryx2 file prefix of a run: its public part and the run's secret on this host.
pub(crate) fn shm_prefix(run_id: &str, secret: &str) -> String {
    format!("{}{secret}_", file_prefix(run_id))
}

/// The iceoryx2 configuration every process of a run uses: the run's file prefix (with the
/// secret kept in its private folder), and that folder as iceoryx2's root (checked to be private
/// before it is used).
pub fn run_config(run_id: &str) -> Result<Config> {
    let folder = run_folder(run_id);
    check_private(&folder)?;
    let prefix = shm_prefix(run_id, &read_secret(&folder)?);
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes())
        .map_err(|e| anyhow!("run id {run_id:?} does not make a valid file prefix: {e:?}"))?;
    let root = format!("{}/", folder.display());
    config.global.set_root_path(
        &Path::new(root.as_bytes()).map_err(|e| anyhow!("{root} is not a valid iceoryx2 root path: {e:?}"))?,
    );
    Ok(config)
}

/// A node of the run, which handles no signals: each process handles SIGTERM and SIGINT itself
/// (`crate::runtime::signals`), so that iceoryx2 never swallows them.
pub(crate) fn node(name: &str, config: &Config) -> Result<Node<ipc::Service>> {
    quiet_logs();
    NodeBuilder::new()
        .name(&NodeName::new(name).map_err(|e| anyhow!("invalid node name {name}: {e:?}"))?)
        .config(config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| anyhow!("cannot create the iceoryx2 node for {name}: {e:?}"))
}

/// iceoryx2 logs only errors, unless IOX2_LOG_LEVEL says otherwise.
pub(crate) fn quiet_logs() {
    set_log_level_from_env_or(LogLevel::Error);
}

/// iceoryx2's shared-memory folder on Linux (fixed when iceoryx2 is built); a tmpfs.
pub const SHM_DIR: &str = "/dev/shm";

/// The run's private folder, on tmpfs: iceoryx2's node and service files and event sockets (its
/// root path), the processes' snapshots, and the launcher's lock. Mode 0700, created fresh by
/// the run, so nothing of a live run is readable or writable by another user, and nothing in it
/// ever waits for a disk. iceoryx2's shared-memory segments themselves must lie in `SHM_DIR`;
/// their names start with [`file_prefix`] and they are owner-only.
pub fn run_folder(run_id: &str) -> PathBuf {
    PathBuf::from(SHM_DIR).join(format!("looplab_{run_id}"))
}

/// The file the launcher holds an exclusive lock on for as long as it runs the run: a run whose
/// lock is free was abandoned (its launcher was killed) and may be cleaned.
fn owner_lock_path(run_id: &str) -> PathBuf {
    run_folder(run_id).join("launcher.lock")
}

/// Creates the run's private folder with the run's secret and takes its owner lock; refuses a
/// folder that exists already (planted by someone else, or a reused id) instead of trusting it.
/// What it made is removed again if it fails. Drop the returned file to release the lock.
pub fn create_run_storage(run_id: &str) -> Result<std::fs::File> {
    use std::os::unix::fs::DirBuilderExt;
    let folder = run_folder(run_id);
    std::fs::DirBuilder::new().mode(0o700).create(&folder).map_err(|e| {
        if e.kind() == std::io::ErrorKind::AlreadyExists {
            anyhow!("{} exists already; a new run needs a folder of its own, so it refuses to use it", folder.display())
        } else {
            anyhow!("cannot create the run's shared-memory folder {}: {e}", folder.display())
        }
    })?;
    fill_run_storage(run_id).inspect_err(|_| remove_own_files(run_id))
}

/// Longest the run's first iceoryx2 node may take to create the run's node registry.
const REGISTRY_TIMEOUT: Duration = Duration::from_secs(5);

/// The secret, the lock and the node registry in the run's new folder.
fn fill_run_storage(run_id: &str) -> Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    let folder = run_folder(run_id);
    check_private(&folder)?;
    let secret = write_secret(&folder)?;
    let path = owner_lock_path(run_id);
    // Locked under another name, then renamed into place (the lock stays with the file): a
    // lock file that exists is always locked while its launcher lives, so another launcher's
    // `clean_abandoned_runs` never finds it free in the moment between creating and locking it.
    let fresh = path.with_extension("new");
    let lock = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(&fresh)
        .with_context(|| format!("create {}", fresh.display()))?;
    // SAFETY: flock on a file descriptor we own.
    if unsafe { libc::flock(std::os::fd::AsRawFd::as_raw_fd(&lock), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
        return Err(anyhow!("cannot lock {}: {}", fresh.display(), std::io::Error::last_os_error()));
    }
    std::fs::rename(&fresh, &path).with_context(|| format!("rename {} to {}", fresh.display(), path.display()))?;
    // iceoryx2 creates its registry segment world-writable; create it now, before any other
    // process of the run exists, and make it the owner's alone (only ours: a file another user
    // planted under the run's public name is not touched).
    create_registry(run_id)?;
    let ours = shm_prefix(run_id, &secret);
    for path in paths_of_run(run_id).into_iter().filter(|p| is_ours(p)) {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        if name.starts_with(&ours) && name.ends_with(".global_mgmt") {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600))
                .with_context(|| format!("make {} private", path.display()))?;
        }
    }
    Ok(lock)
}

/// Creates the run's node registry through a first node, in a thread, for at most
/// [`REGISTRY_TIMEOUT`] and until a stop request: iceoryx2 waits without end on a registry file
/// that is empty, and this is where it opens one first. The secret in the name means no one else
/// can have made it; the bound holds if that ever fails.
fn create_registry(run_id: &str) -> Result<()> {
    use std::sync::mpsc::RecvTimeoutError;
    let config = run_config(run_id)?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("iceoryx2 registry".into())
        .spawn(move || _ = tx.send(node("looplab", &config).map(drop)))
        .context("start a thread")?;
    let until = Instant::now() + REGISTRY_TIMEOUT;
    loop {
        match rx.recv_timeout(Duration::from_millis(20)) {
            Ok(created) => return created,
            Err(RecvTimeoutError::Disconnected) => bail!("iceoryx2 failed creating the run's node registry"),
            Err(RecvTimeoutError::Timeout) => {}
        }
        if StopFlag::installed().is_some_and(|stop| stop.requested()) {
            return Err(crate::runtime::signals::Interrupted.into());
        }
        if Instant::now() > until {
            bail!(
                "iceoryx2 did not create the run's node registry in {SHM_DIR} within {} s (it waits on a \
                 file with the run's name that is not initialised); giving up",
                REGISTRY_TIMEOUT.as_secs()
            );
        }
    }
}

/// Removes every file of the run this user made, and its folder (a run storage that could not
/// be made whole).
fn remove_own_files(run_id: &str) {
    for path in paths_of_run(run_id).into_iter().filter(|p| is_ours(p)) {
        if path.is_dir() && !path.is_symlink() {
            let _ = std::fs::remove_dir_all(&path);
        } else {
            let _ = std::fs::remove_file(&path);
        }
    }
}

/// The run's storage on another host, for the bridge there: created as the launcher creates its
/// own, or, for a restarted bridge, taken over from the one that died (its lock is free).
pub fn take_run_storage(run_id: &str) -> Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    let folder = run_folder(run_id);
    if std::fs::symlink_metadata(&folder).is_err() {
        return create_run_storage(run_id);
    }
    check_private(&folder)?;
    let path = owner_lock_path(run_id);
    let lock = std::fs::OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(&path)
        .with_context(|| format!("open {}", path.display()))?;
    // SAFETY: flock on a file descriptor we own.
    if unsafe { libc::flock(std::os::fd::AsRawFd::as_raw_fd(&lock), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
        return Err(anyhow!("{} is held by a live process of the run; refusing to share it", path.display()));
    }
    Ok(lock)
}

/// Refuses a run folder that is not a real folder of ours that only we can use: a symbolic
/// link, another user's folder, or one others can read or write.
pub fn check_private(folder: &std::path::Path) -> Result<()> {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let meta = std::fs::symlink_metadata(folder)
        .map_err(|e| anyhow!("the run's folder {} is not usable: {e}", folder.display()))?;
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    if meta.file_type().is_symlink() || !meta.is_dir() {
        return Err(anyhow!("{} is not a folder (a symbolic link or a file); refusing it", folder.display()));
    }
    if meta.uid() != me {
        return Err(anyhow!(
            "{} belongs to user {}, not to this user ({me}); refusing it",
            folder.display(),
            meta.uid()
        ));
    }
    if meta.permissions().mode() & 0o077 != 0 {
        return Err(anyhow!(
            "{} can be used by other users (mode {:o}); refusing it",
            folder.display(),
            meta.permissions().mode() & 0o777
        ));
    }
    Ok(())
}

/// After a run: removes the resources of the run's dead nodes (processes that were killed) and
/// the run's own node registry, then lists every file of the run still there.
pub struct Cleanup {
    pub removed_dead_nodes: u64,
    pub leftover: Vec<String>,
    /// Entries with the run's name that another user made: not the run's, and not ours to
    /// remove (a planted file must not fail the run).
    pub foreign: Vec<String>,
}

/// The run's nodes: alive (pids of their processes) and how many dead ones had their resources
/// removed.
fn sweep_nodes(config: &Config) -> Result<(Vec<i32>, u64)> {
    quiet_logs();
    let mut alive = Vec::new();
    let mut removed_dead_nodes = 0;
    Node::<ipc::Service>::list(config, |state| {
        match state {
            NodeState::Dead(view) => removed_dead_nodes += u64::from(view.try_remove_stale_resources().is_ok()),
            NodeState::Alive(view) => {
                alive.push(view.details().as_ref().map_or(0, |d| d.process_id().value()));
            }
            _ => {}
        }
        CallbackProgression::Continue
    })
    .map_err(|e| anyhow!("cannot list the run's iceoryx2 nodes: {e:?}"))?;
    Ok((alive, removed_dead_nodes))
}

/// Removes the resources of the run's dead nodes (during a run, after a process died); returns
/// how many it removed.
pub fn remove_dead_nodes(run_id: &str) -> Result<u64> {
    Ok(sweep_nodes(&run_config(run_id)?)?.1)
}

/// Removes what the run's dead processes left, and once none of its processes is alive, every
/// file of the run and its folder; returns what could not be removed.
pub fn clean_up_run(run_id: &str) -> Result<Cleanup> {
    let config = run_config(run_id)?;
    let (alive, removed_dead_nodes) = sweep_nodes(&config)?;
    // iceoryx2 keeps one registry segment per prefix for good. The prefix is this run's alone, so
    // once no process of the run is alive, it goes too, with the folder.
    if alive.is_empty() {
        remove_own_files(run_id);
    }
    let foreign = paths_of_run(run_id).into_iter().filter(|p| !is_ours(p)).map(|p| p.display().to_string()).collect();
    Ok(Cleanup { removed_dead_nodes, leftover: files_of_run(run_id), foreign })
}

/// Whether this user made `path` (not following a link).
fn is_ours(path: &std::path::Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    // SAFETY: geteuid has no preconditions.
    std::fs::symlink_metadata(path).is_ok_and(|m| m.uid() == unsafe { libc::geteuid() })
}

/// Every entry of `SHM_DIR` that belongs to the run: its folder and its segments.
fn paths_of_run(run_id: &str) -> Vec<PathBuf> {
    let folder = format!("looplab_{run_id}");
    let prefix = file_prefix(run_id);
    let Ok(entries) = std::fs::read_dir(SHM_DIR) else { return vec![] };
    entries
        .flatten()
        .filter(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name == folder || name.starts_with(&prefix)
        })
        .map(|e| e.path())
        .collect()
}

/// Every file of a run still present (this user's); removes nothing (for checks from outside a
/// run).
pub fn files_of_run(run_id: &str) -> Vec<String> {
    let mut found = vec![];
    for path in paths_of_run(run_id).into_iter().filter(|p| is_ours(p)) {
        found.push(path.display().to_string());
        if let Ok(entries) = std::fs::read_dir(&path) {
            found.extend(entries.flatten().map(|e| e.path().display().to_string()));
        }
    }
    found.sort();
    found
}

/// What [`clean_abandoned_runs`] did.
#[derive(Debug, Default)]
pub struct Abandoned {
    /// Runs whose launcher was gone and whose files were removed.
    pub runs: Vec<String>,
    /// Their processes that were still alive (orphans) and were killed.
    pub killed: usize,
    /// Entries that could not be removed.
    pub leftover: Vec<String>,
}

/// Removes the files of every run of this user whose launcher is gone (killed with SIGKILL, or
/// the machine's power): kills its processes that are still alive, then removes its segments and
/// its folder. A run whose launcher still holds its lock is left alone.
pub fn clean_abandoned_runs() -> Abandoned {
    let mut done = Abandoned::default();
    let Ok(entries) = std::fs::read_dir(SHM_DIR) else { return done };
    let mut ids = BTreeSet::new();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some(rest) = name.strip_prefix("looplab_") {
            ids.insert(rest.split('_').next().unwrap_or(rest).to_owned());
        }
    }
    for id in ids {
        let folder = run_folder(&id);
        if folder.exists() {
            if check_private(&folder).is_err() || launcher_alive(&id) {
                continue;
            }
        } else if !paths_of_run(&id).iter().any(|p| is_ours(p)) {
            continue;
        }
        if folder.exists()
            && let Ok(config) = run_config(&id)
            && let Ok((alive, _)) = sweep_nodes(&config)
        {
            for pid in alive.into_iter().filter(|&pid| pid > 0) {
                // SAFETY: the pid holds a node lock of this run, so it is the run's process.
                unsafe { libc::kill(pid, libc::SIGKILL) };
                done.killed += 1;
            }
            // A killed process's node lock goes when the kernel has torn it down.
            let until = Instant::now() + Duration::from_secs(2);
            while sweep_nodes(&config).is_ok_and(|(alive, _)| !alive.is_empty()) && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        // Without its folder (the run had removed it, or never made it) or its secret (it died
        // making its storage), what is the run's is found by the public part of its names.
        let cleanup = clean_up_run(&id).map(|c| c.leftover).unwrap_or_else(|_| {
            remove_own_files(&id);
            files_of_run(&id)
        });
        done.leftover.extend(cleanup);
        done.runs.push(id);
    }
    done
}

/// Whether the run's launcher still holds its lock.
fn launcher_alive(run_id: &str) -> bool {
    use std::os::unix::fs::OpenOptionsExt;
    let Ok(file) = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(owner_lock_path(run_id))
    else {
        // No lock file: a launcher is between creating the folder and its lock (a moment), or
        // died in it; leave it.
        return true;
    };
    // SAFETY: flock on a file descriptor we own; the lock is dropped with the file.
    unsafe { libc::flock(std::os::fd::AsRawFd::as_raw_fd(&file), libc::LOCK_EX | libc::LOCK_NB) != 0 }
}
