//! The one reader of a finished run folder for the tools (export, compare, plot, the latency
//! chart): its resolved launch file, its summary and its CSV files, read by column name with the
//! `csv` crate. Every failure is one bad-input error that names the folder, the file and, where
//! it is one, the column it lacks or the line that does not parse.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::config::launch::LaunchConfig;
use crate::contract::msg::LoopTrace;
use crate::contract::run_format::files;
use crate::launcher::report::read_summary;
use crate::launcher::summary::Summary;
use crate::model::catalog::Catalog;
use crate::model::scenario::Scenario;
use crate::tools::ToolError;

/// A folder checked to hold the files a tool reads.
#[derive(Debug, Clone)]
pub struct RunFolder {
    dir: PathBuf,
}

impl RunFolder {
    /// `dir`, once it is a folder holding each of `files`; else one bad-input error saying which
    /// file it lacks. (Each is read as a regular file only, which its reader checks.)
    pub fn open(dir: &Path, files: &[&str]) -> Result<Self, ToolError> {
        let bad = |why: String| Err(ToolError::BadInput(format!("{}: {why}", dir.display())));
        if !dir.is_dir() {
            return bad(if dir.exists() { "not a folder".into() } else { "no such run folder".into() });
        }
        match files.iter().find(|name| std::fs::symlink_metadata(dir.join(name)).is_err()) {
            Some(missing) => bad(format!("not a run folder (it has no {missing})")),
            None => Ok(RunFolder { dir: dir.to_path_buf() }),
        }
    }

    pub fn path(&self) -> &Path {
        &self.dir
    }

    fn bad(&self, why: impl std::fmt::Display) -> ToolError {
        ToolError::BadInput(format!("{}: {why}", self.dir.display()))
    }

    /// The run's launch.toml (resolved at the run's start) and its scenario, built from `catalog`.
    pub fn launch(&self, catalog: &Catalog) -> Result<(LaunchConfig, Box<dyn Scenario>), ToolError> {
        catalog.load_resolved(&self.dir.join(files::LAUNCH)).map_err(|e| self.bad(e))
    }

    /// The run's summary.json.
    pub fn summary(&self) -> Result<Summary, ToolError> {
        read_summary(&self.dir).map_err(|e| ToolError::BadInput(format!("{e:#}")))
    }

    /// A file of the folder as text.
    pub fn text(&self, file: &str) -> Result<String, ToolError> {
        let path = self.dir.join(file);
        if std::fs::symlink_metadata(&path).is_err() {
            return Err(self.bad(format!("no {file}")));
        }
        let bytes =
            crate::runtime::storage::run_file::read(&path).map_err(|e| ToolError::BadInput(format!("{e:#}")))?;
        String::from_utf8(bytes).map_err(|_| ToolError::BadInput(format!("{}: not UTF-8 text", path.display())))
    }

    /// A CSV file of the folder (trajectory.csv, loops.csv), its header and rows.
    pub fn table(&self, file: &str) -> Result<Table, ToolError> {
        Table::parse(&format!("{}: {file}", self.dir.display()), &self.text(file)?)
    }
}

/// A CSV file's rows, read by column name. A cell left empty (a part of the loop that did not
/// arrive) reads as `None`, or NaN as a float.
#[derive(Debug)]
pub struct Table {
    /// "<folder>: <file>", how errors name it.
    place: String,
    header: csv::StringRecord,
    rows: Vec<csv::StringRecord>,
}

impl Table {
    /// The CSV text `text`, named `place` in errors ("runs/x: loops.csv"); every row must have
    /// the header's width.
    pub fn parse(place: &str, text: &str) -> Result<Self, ToolError> {
        let bad = |e: csv::Error| {
            let line = e.position().map_or(String::new(), |p| format!(" line {}", p.line()));
            let why = match e.kind() {
                csv::ErrorKind::UnequalLengths { expected_len, len, .. } => {
                    format!("{len} cells, the header has {expected_len}")
                }
                _ => e.to_string(),
            };
            ToolError::BadInput(format!("{place}{line}: {why}"))
        };
        let mut reader = csv::ReaderBuilder::new().from_reader(text.as_bytes());
        let header = reader.headers().map_err(bad)?.clone();
        let rows = reader.records().collect::<Result<Vec<_>, _>>().map_err(bad)?;
        Ok(Table { place: place.to_string(), header, rows })
    }

    /// The column names, in the file's order.
    pub fn header(&self) -> impl Iterator<Item = &str> {
        self.header.iter()
    }

    /// The number of rows (the header not counted).
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// A bad-input error at row `row` (0 is the first after the header).
    pub fn error_at(&self, row: usize, why: impl std::fmt::Display) -> ToolError {
        ToolError::BadInput(format!("{} line {}: {why}", self.place, self.line(row)))
    }

    fn line(&self, row: usize) -> u64 {
        self.rows[row].position().map_or(row as u64 + 2, |p| p.line())
    }

    /// Where the column of this name lies; an error naming the file and the column if it has none.
    pub fn index(&self, name: &str) -> Result<usize, ToolError> {
        self.header
            .iter()
            .position(|h| h == name)
            .ok_or_else(|| ToolError::BadInput(format!("{} has no column {name:?}", self.place)))
    }

    /// The column of this name, each cell parsed as a `T`; None where a cell is empty.
    pub fn column<T: FromStr>(&self, name: &str) -> Result<Vec<Option<T>>, ToolError>
    where
        T::Err: std::fmt::Display,
    {
        let i = self.index(name)?;
        let cell = |(row, record): (usize, &csv::StringRecord)| match &record[i] {
            "" => Ok(None),
            text => text
                .parse()
                .map(Some)
                .map_err(|e| self.error_at(row, format_args!("column {name:?}: {text:?} is not a number ({e})"))),
        };
        self.rows.iter().enumerate().map(cell).collect()
    }

    /// The eight stamps of loops.csv, a column each in [`LoopTrace::STAMP_NAMES`]' order; None
    /// where a loop has no record.
    pub fn stamps(&self) -> Result<Vec<Vec<Option<u64>>>, ToolError> {
        LoopTrace::STAMP_NAMES.iter().map(|name| self.column::<u64>(&format!("{name}_ns"))).collect()
    }

    /// The column of this name as floats, NaN where a cell is empty.
    pub fn floats(&self, name: &str) -> Result<Vec<f64>, ToolError> {
        Ok(self.column::<f64>(name)?.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder holding `files` (name, text).
    fn folder(name: &str, files: &[(&str, &str)]) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("looplab-run-folder-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (file, text) in files {
            std::fs::write(dir.join(file), text).unwrap();
        }
        dir
    }

    fn bad_input(e: ToolError) -> String {
        match e {
            ToolError::BadInput(why) => why,
            ToolError::Failed(e) => panic!("not bad input: {e:#}"),
        }
    }

    const LOOPS: &str = "k,t_s,end_to_end_ns\n0,0,8000\n1,0.001,\n";

    #[test]
    fn a_good_folder_is_read_by_column_name() {
        let dir = folder("good", &[("loops.csv", LOOPS)]);
        let table = RunFolder::open(&dir, &["loops.csv"]).unwrap().table("loops.csv").unwrap();
        assert_eq!(table.len(), 2);
        assert_eq!(table.column::<u64>("end_to_end_ns").unwrap(), [Some(8000), None]);
        assert_eq!(table.column::<u64>("k").unwrap(), [Some(0), Some(1)]);
        let t = table.floats("t_s").unwrap();
        assert_eq!(t, [0.0, 0.001]);
        assert!(table.floats("end_to_end_ns").unwrap()[1].is_nan());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_column_names_the_file_and_the_column() {
        let dir = folder("column", &[("loops.csv", LOOPS)]);
        let table = RunFolder::open(&dir, &["loops.csv"]).unwrap().table("loops.csv").unwrap();
        let why = bad_input(table.floats("tick_period_ns").unwrap_err());
        assert_eq!(why, format!("{}: loops.csv has no column \"tick_period_ns\"", dir.display()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_file_is_named() {
        let dir = folder("file", &[("loops.csv", LOOPS)]);
        let why = bad_input(RunFolder::open(&dir, &["loops.csv", "trajectory.csv"]).unwrap_err());
        assert_eq!(why, format!("{}: not a run folder (it has no trajectory.csv)", dir.display()));
        let why = bad_input(RunFolder::open(&dir, &[]).unwrap().table("trajectory.csv").unwrap_err());
        assert_eq!(why, format!("{}: no trajectory.csv", dir.display()));
        std::fs::remove_dir_all(&dir).unwrap();
        let why = bad_input(RunFolder::open(&dir, &[]).unwrap_err());
        assert_eq!(why, format!("{}: no such run folder", dir.display()));
    }

    #[test]
    fn a_malformed_number_names_the_line_and_the_column() {
        let table = Table::parse("run: loops.csv", "k,t_s\n0,0\n1,0.0O1\n").unwrap();
        let why = bad_input(table.floats("t_s").unwrap_err());
        assert_eq!(why, "run: loops.csv line 3: column \"t_s\": \"0.0O1\" is not a number (invalid float literal)");
        let why = bad_input(Table::parse("run: loops.csv", "k,t_s\n0,0\n1\n").unwrap_err());
        assert_eq!(why, "run: loops.csv line 3: 1 cells, the header has 2");
    }
}
