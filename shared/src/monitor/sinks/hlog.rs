//! `latency.hlog`: an HdrHistogram interval log, one histogram per hop and end to end per second
//! of wall-clock time, readable by the standard HdrHistogram tools.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{Context as _, Result, anyhow};
use hdrhistogram::Histogram;
use hdrhistogram::serialization::V2DeflateSerializer;
use hdrhistogram::serialization::interval_log::{IntervalLogIterator, IntervalLogWriterBuilder, LogEntry, Tag};

use crate::contract::clock::now_ns;
use crate::contract::report::{HOPS, MonitorReport};
use crate::contract::run_format::files;
use crate::monitor::sinks::{FileEnd, JoinedLoop, RunSink, SinkSetup, create, flush};
use crate::monitor::stats::histogram;

/// The end-to-end histogram's tag; it is also written untagged.
const END_TO_END: &str = "end_to_end";

/// Length of one interval histogram, in wall-clock time.
const INTERVAL_NS: u64 = 1_000_000_000;

pub struct LatencyLog {
    log: IntervalLog,
    run_dir: PathBuf,
    /// The current interval's histograms: end to end, then one per hop of [`HOPS`].
    end_to_end: Histogram<u64>,
    hops: [Histogram<u64>; HOPS.len()],
    /// Start of the current interval (CLOCK_MONOTONIC).
    interval_start: Option<u64>,
}

impl LatencyLog {
    pub fn open(setup: &SinkSetup) -> Result<Self> {
        Ok(Self {
            log: IntervalLog::open(setup.run_dir, setup.restarted)?,
            run_dir: setup.run_dir.to_path_buf(),
            end_to_end: histogram(),
            hops: std::array::from_fn(|_| histogram()),
            interval_start: None,
        })
    }

    fn flush_interval(&mut self, start: u64, end: u64) -> Result<()> {
        let length = Duration::from_nanos(end.saturating_sub(start).max(1));
        let histograms = std::iter::once((END_TO_END, &mut self.end_to_end))
            .chain(HOPS.iter().map(|h| h.0).zip(self.hops.iter_mut()));
        self.log.write(wall_time(start), length, histograms)
    }
}

impl RunSink for LatencyLog {
    fn loop_joined(&mut self, joined: &JoinedLoop) -> Result<()> {
        let (Some(record), Some(e2e), Some(hops)) =
            (&joined.parts.record, joined.parts.end_to_end_ns(), joined.parts.hops_ns())
        else {
            return Ok(());
        };
        self.end_to_end.saturating_record(e2e);
        for (histogram, ns) in self.hops.iter_mut().zip(hops) {
            histogram.saturating_record(ns);
        }
        // The interval ends at the first record published past its end (that record included).
        let publish_ns = record.header.trace.plant_publish;
        let Some(start) = self.interval_start else {
            // The first record of this monitor: the log's time base, unless an earlier monitor
            // of the run set it.
            self.log.begin(wall_time(publish_ns))?;
            self.interval_start = Some(publish_ns);
            return Ok(());
        };
        if publish_ns >= start + INTERVAL_NS {
            self.flush_interval(start, publish_ns)?;
            self.interval_start = Some(publish_ns);
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<()> {
        flush(&mut self.log.file, &self.run_dir)
    }

    fn end(&self) -> Result<FileEnd> {
        FileEnd::of(&self.log.file, files::LATENCY_LOG)
    }

    fn finish(&mut self, _report: &MonitorReport) -> Result<()> {
        if let Some(start) = self.interval_start {
            self.flush_interval(start, now_ns())?;
        }
        self.flush()
    }
}

/// The wall-clock time of a CLOCK_MONOTONIC time stamp.
fn wall_time(monotonic_ns: u64) -> SystemTime {
    SystemTime::now() - Duration::from_nanos(now_ns().saturating_sub(monotonic_ns))
}

/// The log file. Interval time stamps count from its BaseTime, the run's first loop record: a
/// restarted monitor appends and reads the BaseTime back, so its time stamps go on from the last
/// monitor's instead of starting again from zero.
struct IntervalLog {
    file: BufWriter<File>,
    /// The log's BaseTime, once its header is written.
    base: Option<SystemTime>,
}

impl IntervalLog {
    fn open(dir: &Path, restarted: bool) -> Result<Self> {
        let (file, new) = create(dir, files::LATENCY_LOG, restarted)?;
        let base = if new {
            None
        } else {
            let path = dir.join(files::LATENCY_LOG);
            let text = std::fs::read(&path).with_context(|| format!("read {}", path.display()))?;
            // Only the header matters; a killed monitor may have left a broken last line.
            IntervalLogIterator::new(&text).map_while(Result::ok).find_map(|entry| match entry {
                LogEntry::BaseTime(since_epoch) => Some(UNIX_EPOCH + since_epoch),
                _ => None,
            })
        };
        Ok(Self { file, base })
    }

    /// Writes the header with `first` as the time base, unless the log has one. Flushed at
    /// once, so that a monitor killed right after still leaves the base for the next.
    fn begin(&mut self, first: SystemTime) -> Result<()> {
        if self.base.is_some() {
            return Ok(());
        }
        // The header keeps milliseconds; the base is what a restarted monitor will read back.
        let since_epoch = first.duration_since(UNIX_EPOCH).unwrap_or_default();
        let base = UNIX_EPOCH + Duration::from_millis(since_epoch.as_millis() as u64);
        IntervalLogWriterBuilder::new()
            .add_comment("LoopLab latency per hop and end to end, in ns")
            .add_comment(
                "Tags: end_to_end (also untagged) and one per hop; one interval histogram per tag per second of \
                 wall-clock time",
            )
            .with_start_time(base)
            .with_base_time(base)
            .begin_log_with(&mut self.file, &mut V2DeflateSerializer::new())?;
        writeln!(
            self.file,
            "\"StartTimestamp\",\"Interval_Length\",\"Interval_Max\",\"Interval_Compressed_Histogram\""
        )?;
        self.file.flush()?;
        self.base = Some(base);
        Ok(())
    }

    /// Writes each non-empty histogram as the interval from `start`, `length` long, and resets it.
    fn write<'a>(
        &mut self,
        start: SystemTime,
        length: Duration,
        histograms: impl Iterator<Item = (&'a str, &'a mut Histogram<u64>)>,
    ) -> Result<()> {
        self.begin(start)?;
        let base = self.base.unwrap_or(start);
        let offset = start.duration_since(base).unwrap_or_default();
        let mut serializer = V2DeflateSerializer::new();
        let mut log = IntervalLogWriterBuilder::new().begin_log_with(&mut self.file, &mut serializer)?;
        for (tag, histogram) in histograms {
            if histogram.is_empty() {
                continue;
            }
            // End to end also goes untagged: the reference HistogramLogProcessor reads only
            // untagged intervals unless told a tag, and fails on a log without any.
            let tags = if tag == END_TO_END { vec![None, Tag::new(tag)] } else { vec![Tag::new(tag)] };
            for tag in tags {
                log.write_histogram(histogram, offset, length, tag).map_err(|e| anyhow!("write latency.hlog: {e}"))?;
            }
            histogram.reset();
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The intervals of a log as (start time stamp, tag), and its BaseTime entries.
    fn read_log(path: &Path) -> (Vec<(Duration, Option<String>)>, usize) {
        let text = std::fs::read(path).unwrap();
        let (mut intervals, mut bases) = (vec![], 0);
        for entry in IntervalLogIterator::new(&text) {
            match entry.expect("a valid interval log") {
                LogEntry::Interval(interval) => {
                    intervals.push((interval.start_timestamp(), interval.tag().map(|t| t.as_str().to_owned())))
                }
                LogEntry::BaseTime(_) => bases += 1,
                LogEntry::StartTime(_) => {}
            }
        }
        (intervals, bases)
    }

    /// The start time stamps of the intervals with this tag (None: untagged).
    fn starts(intervals: &[(Duration, Option<String>)], tag: Option<&str>) -> Vec<Duration> {
        intervals.iter().filter(|(_, t)| t.as_deref() == tag).map(|(start, _)| *start).collect()
    }

    fn write_interval(log: &mut IntervalLog, start: SystemTime) {
        let mut histogram = histogram();
        histogram.record(1000).unwrap();
        log.write(start, Duration::from_secs(1), std::iter::once(("end_to_end", &mut histogram))).unwrap();
        log.file.flush().unwrap();
    }

    #[test]
    fn a_restarted_monitor_continues_the_interval_log_time_base() {
        let dir = std::env::temp_dir().join(format!("looplab-hlog-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let run_start = UNIX_EPOCH + Duration::from_millis(1_700_000_000_123);
        let at = |ms: u64| run_start + Duration::from_millis(ms);

        let mut first = IntervalLog::open(&dir, false).unwrap();
        first.begin(at(0)).unwrap();
        write_interval(&mut first, at(0));
        write_interval(&mut first, at(1000));
        drop(first);

        // The restarted monitor's first record comes 2.5 s into the run.
        let mut second = IntervalLog::open(&dir, true).unwrap();
        second.begin(at(2500)).unwrap();
        write_interval(&mut second, at(2500));
        write_interval(&mut second, at(3500));
        drop(second);

        let (intervals, bases) = read_log(&dir.join("latency.hlog"));
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(bases, 1, "one header, the first monitor's");
        let expected = [0, 1000, 2500, 3500].map(Duration::from_millis);
        assert_eq!(starts(&intervals, Some("end_to_end")), expected);
        // End to end again, untagged, for tools that read only untagged intervals.
        assert_eq!(starts(&intervals, None), expected);
        assert_eq!(intervals.len(), 8);
    }
}
