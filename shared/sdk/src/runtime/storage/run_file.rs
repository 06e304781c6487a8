//! The one way LoopLab creates a file in a run folder (or any output folder of its own): never
//! through a symbolic link (`O_NOFOLLOW`), only a regular file (a FIFO planted there would block
//! the open, a device take the bytes: `O_NONBLOCK`, then checked), and closed in the processes it
//! starts (`O_CLOEXEC`).
//! A link planted where a run's file goes would make the run write wherever it points (a root
//! run would overwrite any file); it is refused instead, with one line naming the file. Files
//! get the user's umask, as other tools' files do.

use std::fs::File;
use std::path::Path;

use anyhow::{Result, anyhow};

/// What to do with a file that is there already.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Existing {
    /// Emptied and written anew.
    Replace,
    /// Written on at its end (a restarted process's log or recording).
    Append,
}

/// Opens `path` for writing, created if missing, never through a symbolic link.
pub fn open(path: &Path, existing: Existing) -> Result<File> {
    open_io(path, existing).map_err(|e| refused(path, e))
}

/// [`open`] with the system's error as it is (ELOOP: a symbolic link; InvalidInput: not a
/// regular file).
pub fn open_io(path: &Path, existing: Existing) -> std::io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .append(existing == Existing::Append)
        .truncate(existing == Existing::Replace)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC | libc::O_NONBLOCK)
        .open(path)?;
    if !file.metadata()?.is_file() {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidInput, NOT_REGULAR));
    }
    Ok(file)
}

/// Why a FIFO, a device or a folder where a file goes is refused.
const NOT_REGULAR: &str = "it is not a regular file (a FIFO, a device or a folder), and LoopLab writes only into one";

/// Writes `contents` into `path`, replacing what is there, never through a symbolic link.
pub fn write(path: &Path, contents: &[u8]) -> Result<()> {
    use std::io::Write as _;
    open(path, Existing::Replace)?.write_all(contents).map_err(|e| anyhow!("cannot write {}: {e}", path.display()))
}

/// Reads a file of a run folder, which may be another user's: only a regular file, never through
/// a symbolic link planted in its place, and without waiting on a FIFO. Errors name the file.
pub fn read(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read as _;
    use std::os::unix::fs::OpenOptionsExt;
    let opened = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC | libc::O_NONBLOCK)
        .open(path);
    let cannot = |why: String| anyhow!("cannot read {}: {why}", path.display());
    let file = match opened {
        Ok(file) => file,
        Err(e) if e.raw_os_error() == Some(libc::ELOOP) => {
            return Err(cannot(
                "it is a symbolic link, and LoopLab reads a run folder's files only as they are".into(),
            ));
        }
        Err(e) => return Err(cannot(e.to_string())),
    };
    if !file.metadata().map_err(|e| cannot(e.to_string()))?.is_file() {
        return Err(cannot("it is not a regular file (a FIFO, a device or a folder)".into()));
    }
    let mut bytes = Vec::new();
    (&file).read_to_end(&mut bytes).map_err(|e| cannot(e.to_string()))?;
    Ok(bytes)
}

/// The error for a file that could not be opened: a symbolic link is named as such.
pub fn refused(path: &Path, e: std::io::Error) -> anyhow::Error {
    if e.raw_os_error() == Some(libc::ELOOP) {
        anyhow!("cannot write {}: it is a symbolic link, and LoopLab does not write through one", path.display())
    } else if e.raw_os_error() == Some(libc::ENXIO) {
        // O_NONBLOCK on a FIFO without a reader.
        anyhow!("cannot write {}: {NOT_REGULAR}", path.display())
    } else {
        anyhow!("cannot write {}: {e}", path.display())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_link_is_refused_and_its_target_untouched() {
        let dir = std::env::temp_dir().join(format!("looplab-run-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let victim = dir.join("victim");
        std::fs::write(&victim, b"precious").unwrap();
        let link = dir.join("trajectory.csv");
        std::os::unix::fs::symlink(&victim, &link).unwrap();
        for existing in [Existing::Replace, Existing::Append] {
            let e = open(&link, existing).unwrap_err().to_string();
            assert!(e.contains("trajectory.csv") && e.contains("symbolic link"), "{e}");
        }
        assert!(write(&link, b"x").is_err());
        assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
        write(&dir.join("plain"), b"a").unwrap();
        use std::io::Write as _;
        open(&dir.join("plain"), Existing::Append).unwrap().write_all(b"b").unwrap();
        assert_eq!(std::fs::read(dir.join("plain")).unwrap(), b"ab");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A FIFO planted where a file goes is refused at once (no reader: the open would block), and
    /// so is a device.
    #[test]
    fn a_fifo_or_a_device_is_refused_without_blocking() {
        let dir = std::env::temp_dir().join(format!("looplab-run-file-fifo-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let fifo = dir.join("estimate.png");
        let name = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(name.as_ptr(), 0o600) }, 0);
        for path in [fifo.as_path(), Path::new("/dev/null")] {
            let e = write(path, b"x").unwrap_err().to_string();
            assert!(
                e.ends_with(
                    "it is not a regular file (a FIFO, a device or a folder), and LoopLab writes only into one"
                ),
                "{e}"
            );
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
