//! The FMU archive: read its modelDescription.xml, unpack its binary for this platform (and its
//! resources) into a private temporary folder removed when the model is dropped (or, after a
//! crash, by the launcher at the run's end and by `looplab clean`); and build one from C
//! source with `cc` (the project's own pendulum, services/fmu/pendulum/).

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::Command;

use super::description::{Description, Version};

/// An opened FMU: its description and the folder it was unpacked into.
pub struct Unpacked {
    pub description: Description,
    /// Holds binaries/<platform>/ and resources/; removed on drop.
    pub folder: tempfile::TempDir,
}

impl Unpacked {
    pub fn binary(&self, identifier: &str) -> PathBuf {
        let platform = platform(self.description.version);
        self.folder.path().join("binaries").join(platform).join(binary_file(identifier))
    }

    pub fn resources(&self) -> PathBuf {
        self.folder.path().join("resources")
    }

    /// Whether the archive holds resources/ files the FMU may read while it runs.
    pub fn has_resources(&self) -> bool {
        std::fs::read_dir(self.resources()).is_ok_and(|mut d| d.next().is_some())
    }
}

/// The binaries/ folder name for this machine, in each FMI version's naming.
pub fn platform(version: Version) -> String {
    use std::env::consts::{ARCH, OS};
    match version {
        Version::Fmi2 => {
            let os = match OS {
                "macos" => "darwin",
                "windows" => "win",
                other => other,
            };
            format!("{os}{}", if cfg!(target_pointer_width = "64") { "64" } else { "32" })
        }
        Version::Fmi3 => {
            let arch = if ARCH == "x86" { "x86" } else { ARCH };
            format!("{arch}-{}", if OS == "macos" { "darwin" } else { OS })
        }
    }
}

/// The longest modelDescription.xml read: a modelling tool's largest are a few MiB.
const MAX_DESCRIPTION_BYTES: u64 = 64 << 20;
/// The most an FMU may unpack to (its binary and resources).
const MAX_UNPACKED_BYTES: u64 = 1 << 30;
/// Each unpack folder's name: this prefix, the pid of the process that unpacked it, a dash.
const UNPACK_PREFIX: &str = "looplab-fmu-";

/// An FMU's archive, read but not unpacked: its description, and its entries.
pub struct Archive {
    pub description: Description,
    zip: zip::ZipArchive<std::fs::File>,
}

/// Reads the description and checks that the archive has a binary for this platform. No code of
/// the FMU runs, and nothing is unpacked. Errors name the file and what is wrong (not found, not
/// a regular file, not a zip, no modelDescription.xml, too large, no binary for this platform).
pub fn open(fmu: &Path, name: &str) -> Result<Archive, String> {
    use std::os::unix::fs::OpenOptionsExt;
    let cannot = |e: std::io::Error| format!("{name}: cannot open the FMU {}: {e}", fmu.display());
    // Non-blocking, so that a FIFO in its place is refused rather than waited on.
    let file = std::fs::OpenOptions::new().read(true).custom_flags(libc::O_NONBLOCK).open(fmu).map_err(cannot)?;
    if !file.metadata().map_err(cannot)?.is_file() {
        return Err(format!("{name}: the FMU {} is not a regular file", fmu.display()));
    }
    let mut zip = zip::ZipArchive::new(file).map_err(|e| format!("{name}: not an FMU (a zip archive): {e}"))?;
    let mut xml = String::new();
    let entry =
        zip.by_name("modelDescription.xml").map_err(|_| format!("{name}: the archive has no modelDescription.xml"))?;
    let too_large = || format!("{name}: modelDescription.xml is larger than {} MiB", MAX_DESCRIPTION_BYTES >> 20);
    if entry.size() > MAX_DESCRIPTION_BYTES {
        return Err(too_large());
    }
    entry
        .take(MAX_DESCRIPTION_BYTES + 1)
        .read_to_string(&mut xml)
        .map_err(|e| format!("{name}: cannot read modelDescription.xml: {e}"))?;
    if xml.len() as u64 > MAX_DESCRIPTION_BYTES {
        return Err(too_large());
    }
    let description = Description::parse(&xml).map_err(|e| format!("{name}: modelDescription.xml: {e}"))?;
    let platform = platform(description.version);
    let wanted = format!("binaries/{platform}/");
    if !zip.file_names().any(|n| n.starts_with(&wanted) && n.len() > wanted.len()) {
        let mut offered: Vec<&str> = zip
            .file_names()
            .filter_map(|n| n.strip_prefix("binaries/")?.split('/').next())
            .filter(|p| !p.is_empty())
            .collect();
        offered.sort();
        offered.dedup();
        let offered = if offered.is_empty() { "none (a source-only FMU)".to_string() } else { offered.join(", ") };
        return Err(format!("{name}: no binary for this platform ({platform}); the FMU has binaries for: {offered}"));
    }
    Ok(Archive { description, zip })
}

impl Archive {
    /// Whether it holds the binary of the interface `identifier` for this platform.
    pub fn has_binary(&self, identifier: &str) -> bool {
        let binary = Path::new("binaries").join(platform(self.description.version)).join(binary_file(identifier));
        self.zip.file_names().any(|n| Path::new(n) == binary)
    }

    /// Unpacks its binary for this platform and its resources into a folder of this process's
    /// own (0700, named after its pid so that `remove_abandoned_unpack_folders` finds it if the
    /// process dies before it removes it), each file created new, never through a link.
    pub fn unpack(mut self, name: &str) -> Result<Unpacked, String> {
        use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt, PermissionsExt};
        let folder = tempfile::Builder::new()
            .prefix(&format!("{UNPACK_PREFIX}{}-", std::process::id()))
            .permissions(std::fs::Permissions::from_mode(0o700))
            .tempdir()
            .map_err(|e| format!("{name}: cannot make a folder to unpack into: {e}"))?;
        let platform = platform(self.description.version);
        let mut left = MAX_UNPACKED_BYTES;
        for i in 0..self.zip.len() {
            let mut entry = self.zip.by_index(i).map_err(|e| format!("{name}: corrupt archive: {e}"))?;
            let Some(relative) = entry.enclosed_name() else { continue };
            let keep = relative.starts_with(Path::new("binaries").join(&platform)) || relative.starts_with("resources");
            if !keep || entry.is_dir() {
                continue;
            }
            let target = folder.path().join(&relative);
            let unpacked = (|| {
                let parent = target.parent().unwrap_or(folder.path());
                std::fs::DirBuilder::new().recursive(true).mode(0o700).create(parent)?;
                let mut out = std::fs::OpenOptions::new()
                    .write(true)
                    .create_new(true)
                    .mode(0o600)
                    .custom_flags(libc::O_NOFOLLOW)
                    .open(&target)?;
                std::io::copy(&mut (&mut entry).take(left + 1), &mut out)
            })();
            let written = unpacked.map_err(|e| format!("{name}: cannot unpack {}: {e}", relative.display()))?;
            if written > left {
                return Err(format!("{name}: unpacks to more than {} MiB", MAX_UNPACKED_BYTES >> 20));
            }
            left -= written;
        }
        std::fs::create_dir_all(folder.path().join("resources")).map_err(|e| format!("{name}: {e}"))?;
        Ok(Unpacked { description: self.description, folder })
    }
}

/// The binary's file name for the interface `identifier` (`<identifier>.so`).
fn binary_file(identifier: &str) -> String {
    format!("{identifier}.{}", std::env::consts::DLL_EXTENSION)
}

/// Removes the FMU unpack folders of this user's processes that are gone (a plant killed or
/// crashed while its FMU was unpacked), from the temporary folder. Returns the folders removed
/// and those that could not be.
pub fn remove_abandoned_unpack_folders() -> (Vec<PathBuf>, Vec<PathBuf>) {
    use std::os::unix::fs::MetadataExt;
    let (mut removed, mut left) = (vec![], vec![]);
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else { return (removed, left) };
    // SAFETY: geteuid cannot fail.
    let me = unsafe { libc::geteuid() };
    for entry in entries.flatten() {
        let name = entry.file_name();
        let Some(pid) =
            name.to_str().and_then(|n| n.strip_prefix(UNPACK_PREFIX)?.split('-').next()?.parse::<i32>().ok())
        else {
            continue;
        };
        // Never through a link, only this user's own folders.
        let ours = entry.metadata().is_ok_and(|m| m.is_dir() && m.uid() == me);
        // SAFETY: signal 0 only asks whether the process exists.
        let gone =
            unsafe { libc::kill(pid, 0) } != 0 && std::io::Error::last_os_error().raw_os_error() == Some(libc::ESRCH);
        if !ours || !gone || pid <= 0 {
            continue;
        }
        let path = entry.path();
        match std::fs::remove_dir_all(&path) {
            Ok(()) => removed.push(path),
            Err(_) => left.push(path),
        }
    }
    (removed, left)
}

/// The project's own pendulum FMU's source folder.
pub fn pendulum_source() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../services/fmu/pendulum")
}

/// Builds an FMU from C source with `cc` and zips it to `out`: `<source>/fmi2.c` or `fmi3.c`
/// compiled against `<source>/headers/fmi2|fmi3/` into binaries/<platform>/<modelIdentifier>.so,
/// with `<source>/modelDescription2.xml` or `modelDescription3.xml` as its modelDescription.xml.
/// `-ffp-contract=off`: no fused multiply-adds, so the arithmetic is the one the source writes.
pub fn build_fmu(source: &Path, version: Version, out: &Path) -> Result<(), String> {
    let n = if version == Version::Fmi2 { 2 } else { 3 };
    let xml_path = source.join(format!("modelDescription{n}.xml"));
    let xml = std::fs::read_to_string(&xml_path).map_err(|e| format!("{}: {e}", xml_path.display()))?;
    let description = Description::parse(&xml).map_err(|e| format!("{}: {e}", xml_path.display()))?;
    let identifier = description
        .model_exchange
        .as_ref()
        .or(description.co_simulation.as_ref())
        .map(|i| i.identifier.clone())
        .ok_or_else(|| format!("{}: neither ModelExchange nor CoSimulation", xml_path.display()))?;
    let work = tempfile::tempdir().map_err(|e| e.to_string())?;
    let library = work.path().join("model.so");
    let status = Command::new("cc")
        .args(["-std=c99", "-O2", "-ffp-contract=off", "-fPIC", "-shared", "-fvisibility=default"])
        .arg(format!("-I{}", source.join("headers").join(format!("fmi{n}")).display()))
        .arg(format!("-I{}", source.display()))
        .arg(source.join(format!("fmi{n}.c")))
        .arg("-o")
        .arg(&library)
        .arg("-lm")
        .status()
        .map_err(|e| format!("cannot run cc: {e}"))?;
    if !status.success() {
        return Err(format!("cc failed on {} ({status})", source.join(format!("fmi{n}.c")).display()));
    }
    let binary = std::fs::read(&library).map_err(|e| e.to_string())?;
    let zip_err = |e: zip::result::ZipError| format!("{}: {e}", out.display());
    let file = std::fs::File::create(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut zip = zip::ZipWriter::new(file);
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("modelDescription.xml", options).map_err(zip_err)?;
    zip.write_all(xml.as_bytes()).map_err(|e| e.to_string())?;
    let so = format!("binaries/{}/{identifier}.{}", platform(version), std::env::consts::DLL_EXTENSION);
    zip.start_file(so, options).map_err(zip_err)?;
    zip.write_all(&binary).map_err(|e| e.to_string())?;
    zip.finish().map_err(zip_err)?;
    Ok(())
}
