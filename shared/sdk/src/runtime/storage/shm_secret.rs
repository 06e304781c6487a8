//! The secret part of a run's names in `/dev/shm`.
//!
//! The run id is public (it is on the processes' command lines, and the run's folder
//! `/dev/shm/looplab_<run>` bears it), so a name made from it alone can be created by another
//! user before the run creates it: iceoryx2 then opens that user's file as the run's (junk in it
//! fails the run, an empty one makes iceoryx2 wait forever). Every iceoryx2 file of a run is
//! therefore named `looplab_<run>_<secret>_…`: the secret is drawn by whoever creates the run's
//! storage on a host, before any file of the run exists in `/dev/shm`, and kept in the run's
//! private folder (mode 0700), where every process of the run, and `looplab clean`, read it. It
//! is never on a command line, in the environment, or in a name before its files exist.
//! Clean-up needs no secret: it matches the public `looplab_<run>_`.

use std::io::{Read as _, Write as _};
use std::path::Path;

use anyhow::{Context as _, Result, bail};

/// The file in the run's private folder that holds the secret.
const SECRET_FILE: &str = "shm.secret";
/// Characters of the secret: 7 of 62 (about 42 bits), few enough that iceoryx2's longest path, an
/// event socket `<run folder>/<prefix><id>.event`, stays within the 107 bytes a Unix socket's
/// path may have (it reaches 107 only once a process has made 126 000 iceoryx2 ids).
pub const SECRET_LEN: usize = 7;
const ALPHABET: &[u8; 62] = b"0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz";

/// A new secret from the kernel's random source.
pub fn new_secret() -> String {
    let mut secret = String::with_capacity(SECRET_LEN);
    while secret.len() < SECRET_LEN {
        let mut bytes = [0u8; 16];
        // SAFETY: getrandom writes at most `bytes.len()` bytes into the buffer.
        let n = unsafe { libc::getrandom(bytes.as_mut_ptr().cast(), bytes.len(), 0) };
        assert_eq!(n, bytes.len() as isize, "the kernel's random source failed");
        // 248 = 4 × 62: the bytes above it are skipped, so every character is equally likely.
        for b in bytes.into_iter().filter(|&b| b < 248) {
            if secret.len() < SECRET_LEN {
                secret.push(ALPHABET[usize::from(b % 62)] as char);
            }
        }
    }
    secret
}

/// Draws the run's secret and writes it into its private `folder` (a new file, never through a
/// link); returns it.
pub fn write_secret(folder: &Path) -> Result<String> {
    use std::os::unix::fs::OpenOptionsExt;
    let path = folder.join(SECRET_FILE);
    let secret = new_secret();
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(&path)
        .and_then(|mut file| file.write_all(secret.as_bytes()))
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(secret)
}

/// The run's secret, from its private `folder` (checked private by the caller).
pub fn read_secret(folder: &Path) -> Result<String> {
    use std::os::unix::fs::OpenOptionsExt;
    let path = folder.join(SECRET_FILE);
    let mut secret = String::new();
    std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(&path)
        .and_then(|file| file.take(64).read_to_string(&mut secret))
        .with_context(|| format!("cannot read the run's secret {}", path.display()))?;
    if secret.len() != SECRET_LEN || !secret.bytes().all(|b| b.is_ascii_alphanumeric()) {
        bail!("{} does not hold a run's secret ({SECRET_LEN} letters or digits)", path.display());
    }
    Ok(secret)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn secrets_are_letters_and_digits_and_differ() {
        let a = new_secret();
        assert_eq!(a.len(), SECRET_LEN);
        assert!(a.bytes().all(|b| b.is_ascii_alphanumeric()), "{a}");
        assert_ne!(a, new_secret());
    }

    #[test]
    fn a_secret_is_written_once_and_read_back() {
        let folder = std::env::temp_dir().join(format!("looplab-secret-{}", std::process::id()));
        std::fs::create_dir_all(&folder).unwrap();
        let secret = write_secret(&folder).unwrap();
        assert_eq!(read_secret(&folder).unwrap(), secret);
        assert!(write_secret(&folder).is_err(), "an existing secret is never replaced");
        std::fs::remove_dir_all(&folder).unwrap();
    }
}
