//! The FMU archive: read its modelDescription.xml, unpack its binary for this platform (and its
//! resources) into a temporary folder removed when the model is dropped; and build one from C
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
        self.folder
            .path()
            .join("binaries")
            .join(platform)
            .join(format!("{identifier}.{}", std::env::consts::DLL_EXTENSION))
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

/// Reads the description and unpacks what running it needs. Errors name the file and what is
/// wrong (not found, not a zip, no modelDescription.xml, no binary for this platform).
pub fn unpack(fmu: &Path, name: &str) -> Result<Unpacked, String> {
    let file = std::fs::File::open(fmu).map_err(|e| format!("{name}: cannot open the FMU {}: {e}", fmu.display()))?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| format!("{name}: not an FMU (a zip archive): {e}"))?;
    let mut xml = String::new();
    zip.by_name("modelDescription.xml")
        .map_err(|_| format!("{name}: the archive has no modelDescription.xml"))?
        .read_to_string(&mut xml)
        .map_err(|e| format!("{name}: cannot read modelDescription.xml: {e}"))?;
    let description = Description::parse(&xml).map_err(|e| format!("{name}: modelDescription.xml: {e}"))?;
    let platform = platform(description.version);
    let wanted = format!("binaries/{platform}/");
    let names: Vec<String> = zip.file_names().map(str::to_string).collect();
    if !names.iter().any(|n| n.starts_with(&wanted) && n.len() > wanted.len()) {
        let mut offered: Vec<&str> = names
            .iter()
            .filter_map(|n| n.strip_prefix("binaries/")?.split('/').next())
            .filter(|p| !p.is_empty())
            .collect();
        offered.sort();
        offered.dedup();
        let offered = if offered.is_empty() { "none (a source-only FMU)".to_string() } else { offered.join(", ") };
        return Err(format!("{name}: no binary for this platform ({platform}); the FMU has binaries for: {offered}"));
    }
    let folder = tempfile::Builder::new()
        .prefix("looplab-fmu-")
        .tempdir()
        .map_err(|e| format!("{name}: cannot make a folder to unpack into: {e}"))?;
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).map_err(|e| format!("{name}: corrupt archive: {e}"))?;
        let Some(relative) = entry.enclosed_name() else { continue };
        let keep = relative.starts_with(Path::new("binaries").join(&platform)) || relative.starts_with("resources");
        if !keep || entry.is_dir() {
            continue;
        }
        let target = folder.path().join(&relative);
        let unpacked = (|| {
            std::fs::create_dir_all(target.parent().unwrap_or(folder.path()))?;
            let mut out = std::fs::File::create(&target)?;
            std::io::copy(&mut entry, &mut out)?;
            Ok::<_, std::io::Error>(())
        })();
        unpacked.map_err(|e| format!("{name}: cannot unpack {}: {e}", relative.display()))?;
    }
    std::fs::create_dir_all(folder.path().join("resources")).map_err(|e| format!("{name}: {e}"))?;
    Ok(Unpacked { description, folder })
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
