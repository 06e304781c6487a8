//! The MCAP file itself (https://mcap.dev/spec), written record by record: the header, the
//! schemas and channels, zstd-compressed chunks of messages each followed by its message
//! indexes, and at the end the summary (schemas, channels, statistics, chunk indexes, summary
//! offsets) and the footer, with every CRC, so that any MCAP reader reads it and seeks in it.
//!
//! Written here rather than through the `mcap` crate's writer (which reads it back in the
//! tests): that writer passes each field of each message to the zstd stream on its own, about
//! forty small compression calls per loop, which cost as much as the compression itself. Here a
//! message is appended to the chunk's buffer, and a whole chunk is compressed in one call, on a
//! thread of its own if asked ([`Compression::OnThread`]).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;

use anyhow::{Context as _, Result, anyhow};
use crossbeam_channel::{Receiver, Sender, bounded};

use crate::monitor::sinks::FileEnd;

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// A chunk is compressed once its messages reach this size (the `mcap` crate's default).
const CHUNK_SIZE: usize = 1024 * 1024;
/// zstd's fastest level: it shrinks a recording about fivefold.
const ZSTD_LEVEL: i32 = 1;

/// Record opcodes.
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const MESSAGE_INDEX: u8 = 0x07;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const STATISTICS: u8 = 0x0B;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// Where the chunks are compressed and written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compression {
    /// In the writing thread.
    Inline,
    /// On a thread of its own, which a full chunk is handed to.
    OnThread,
}

/// An MCAP file being written: add the schemas and channels, then the messages, then finish.
pub struct McapFile {
    path: PathBuf,
    schemas: Vec<u8>,
    channels: Vec<u8>,
    schema_count: u16,
    channel_count: u16,
    chunk: Chunk,
    /// Messages per channel, and the first and last log time, for the statistics.
    counts: BTreeMap<u16, u64>,
    times: Option<(u64, u64)>,
    writer: ChunkWriter,
}

impl McapFile {
    /// Creates `path` (replaced if it exists) and writes the header.
    pub fn create(path: &Path, compression: Compression) -> Result<Self> {
        let file = crate::runtime::storage::run_file::open(path, crate::runtime::storage::run_file::Existing::Replace)?;
        let mut out = Output::new(BufWriter::new(file));
        out.write(MAGIC);
        let mut header = Record::new(op::HEADER);
        header.string("");
        header.string(concat!("looplab ", env!("CARGO_PKG_VERSION")));
        out.write(header.finish());
        let writer = ChunkWriter::Inline(Box::new(FileWriter::new(out)?));
        let writer = match compression {
            Compression::Inline => writer,
            Compression::OnThread => writer.on_thread()?,
        };
        let path = path.to_path_buf();
        Ok(Self {
            path,
            schemas: vec![],
            channels: vec![],
            schema_count: 0,
            channel_count: 0,
            chunk: Chunk::new(),
            counts: BTreeMap::new(),
            times: None,
            writer,
        })
    }

    /// Adds a schema (ids from 1); it goes to the data section before any message, and to the
    /// summary.
    pub fn add_schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> Result<u16> {
        self.schema_count += 1;
        let mut record = Record::new(op::SCHEMA);
        record.u16(self.schema_count);
        record.string(name);
        record.string(encoding);
        record.u32(data.len() as u32);
        record.bytes(data);
        self.schemas.extend_from_slice(record.finish());
        self.writer.header_record(record.finish()).map_err(|e| self.error(e))?;
        Ok(self.schema_count)
    }

    /// Adds a channel (ids from 0) of `schema`, with its metadata.
    pub fn add_channel(
        &mut self,
        schema: u16,
        topic: &str,
        encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<u16> {
        let id = self.channel_count;
        self.channel_count += 1;
        let mut record = Record::new(op::CHANNEL);
        record.u16(id);
        record.u16(schema);
        record.string(topic);
        record.string(encoding);
        record.map(metadata.iter(), |r, (key, value)| {
            r.string(key);
            r.string(value);
        });
        self.channels.extend_from_slice(record.finish());
        self.writer.header_record(record.finish()).map_err(|e| self.error(e))?;
        Ok(id)
    }

    /// Writes one message (its data as given).
    pub fn write(&mut self, channel: u16, sequence: u32, log_time: u64, publish_time: u64, data: &[u8]) -> Result<()> {
        self.chunk.message(channel, sequence, log_time, publish_time, data);
        *self.counts.entry(channel).or_default() += 1;
        self.times = Some(match self.times {
            Some((first, last)) => (first.min(log_time), last.max(log_time)),
            None => (log_time, log_time),
        });
        if self.chunk.records.len() >= CHUNK_SIZE {
            self.end_chunk()?;
        }
        Ok(())
    }

    fn end_chunk(&mut self) -> Result<()> {
        if self.chunk.is_empty() {
            return Ok(());
        }
        self.writer.chunk(&mut self.chunk).map_err(|e| self.error(e))
    }

    /// Ends the chunk and pushes everything to the file, so that a reader of the file as it is
    /// (a killed monitor's) gets every message so far.
    pub fn flush(&mut self) -> Result<()> {
        self.end_chunk()?;
        self.writer.flush().map_err(|e| self.error(e))
    }

    /// Its name and length: after [`flush`](Self::flush), everything written so far.
    pub fn end(&self) -> Result<FileEnd> {
        let name = self.path.file_name().and_then(|n| n.to_str()).context("an MCAP file's name")?;
        let len = std::fs::symlink_metadata(&self.path).with_context(|| format!("the length of {name}"))?.len();
        Ok(FileEnd { name: name.to_owned(), len })
    }

    /// Ends the data section and writes the summary and the footer.
    pub fn finish(mut self) -> Result<()> {
        self.end_chunk()?;
        let mut statistics = Record::new(op::STATISTICS);
        statistics.u64(self.counts.values().sum());
        statistics.u16(self.schema_count);
        statistics.u32(self.channel_count.into());
        statistics.u32(0); // attachments
        statistics.u32(0); // metadata
        let (first, last) = self.times.unwrap_or((0, 0));
        // The chunk count is the writer's to give: it goes in at the end.
        let summary =
            Summary { schemas: self.schemas, channels: self.channels, statistics, first, last, counts: self.counts };
        let path = self.path;
        self.writer.finish(summary).with_context(|| format!("write to {}", path.display()))
    }

    fn error(&self, e: anyhow::Error) -> anyhow::Error {
        e.context(format!("write to {}", self.path.display()))
    }
}

/// One record being built: opcode, length, fields.
struct Record {
    bytes: Vec<u8>,
}

impl Record {
    fn new(opcode: u8) -> Self {
        let mut bytes = Vec::with_capacity(64);
        bytes.push(opcode);
        bytes.extend_from_slice(&[0; 8]);
        Self { bytes }
    }

    fn u16(&mut self, value: u16) {
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    fn u32(&mut self, value: u32) {
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    fn u64(&mut self, value: u64) {
        self.bytes.extend_from_slice(&value.to_le_bytes());
    }

    fn bytes(&mut self, value: &[u8]) {
        self.bytes.extend_from_slice(value);
    }

    fn string(&mut self, value: &str) {
        self.u32(value.len() as u32);
        self.bytes(value.as_bytes());
    }

    /// A map or an array: its length in bytes, then its entries.
    fn map<T>(&mut self, entries: impl IntoIterator<Item = T>, mut entry: impl FnMut(&mut Self, T)) {
        let at = self.bytes.len();
        self.u32(0);
        entries.into_iter().for_each(|e| entry(self, e));
        let length = (self.bytes.len() - at - 4) as u32;
        self.bytes[at..at + 4].copy_from_slice(&length.to_le_bytes());
    }

    /// The record with its length filled in.
    fn finish(&mut self) -> &[u8] {
        let length = (self.bytes.len() - 9) as u64;
        self.bytes[1..9].copy_from_slice(&length.to_le_bytes());
        &self.bytes
    }
}

/// The messages of the chunk being filled, uncompressed, and where each lies in it.
struct Chunk {
    records: Vec<u8>,
    /// Per channel, each message's (log time, offset in `records`).
    index: BTreeMap<u16, Vec<(u64, u64)>>,
    times: Option<(u64, u64)>,
}

impl Chunk {
    fn new() -> Self {
        Self { records: Vec::with_capacity(CHUNK_SIZE + 4096), index: BTreeMap::new(), times: None }
    }

    fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    fn message(&mut self, channel: u16, sequence: u32, log_time: u64, publish_time: u64, data: &[u8]) {
        let offset = self.records.len() as u64;
        self.index.entry(channel).or_default().push((log_time, offset));
        self.times = Some(match self.times {
            Some((first, last)) => (first.min(log_time), last.max(log_time)),
            None => (log_time, log_time),
        });
        let r = &mut self.records;
        r.push(op::MESSAGE);
        r.extend_from_slice(&(2 + 4 + 8 + 8 + data.len() as u64).to_le_bytes());
        r.extend_from_slice(&channel.to_le_bytes());
        r.extend_from_slice(&sequence.to_le_bytes());
        r.extend_from_slice(&log_time.to_le_bytes());
        r.extend_from_slice(&publish_time.to_le_bytes());
        r.extend_from_slice(data);
    }

    /// Ready to be filled again.
    fn clear(&mut self) {
        self.records.clear();
        self.index.clear();
        self.times = None;
    }
}

/// What the summary section is made of, from the writing side.
struct Summary {
    schemas: Vec<u8>,
    channels: Vec<u8>,
    /// The statistics record up to the chunk count.
    statistics: Record,
    first: u64,
    last: u64,
    counts: BTreeMap<u16, u64>,
}

/// The file, with its position and the CRC of everything written to it (the data section's).
struct Output {
    file: BufWriter<File>,
    position: u64,
    crc: crc32fast::Hasher,
    /// The first error, kept until the next call that can return it.
    error: Option<std::io::Error>,
}

impl Output {
    fn new(file: BufWriter<File>) -> Self {
        Self { file, position: 0, crc: crc32fast::Hasher::new(), error: None }
    }

    fn write(&mut self, bytes: &[u8]) {
        self.crc.update(bytes);
        self.position += bytes.len() as u64;
        if self.error.is_none()
            && let Err(e) = self.file.write_all(bytes)
        {
            self.error = Some(e);
        }
    }

    fn check(&mut self) -> Result<()> {
        match self.error.take() {
            Some(e) => Err(e.into()),
            None => Ok(()),
        }
    }
}

/// Compresses chunks and writes them with their indexes; keeps what the summary needs of them.
struct FileWriter {
    out: Output,
    compressor: zstd::bulk::Compressor<'static>,
    compressed: Vec<u8>,
    chunk_indexes: Vec<u8>,
    chunk_count: u32,
}

impl FileWriter {
    fn new(out: Output) -> Result<Self> {
        let compressor = zstd::bulk::Compressor::new(ZSTD_LEVEL)?;
        Ok(Self { out, compressor, compressed: vec![], chunk_indexes: vec![], chunk_count: 0 })
    }

    fn chunk(&mut self, chunk: &Chunk) -> Result<()> {
        let records = &chunk.records;
        self.compressed.clear();
        self.compressed.reserve(zstd::zstd_safe::compress_bound(records.len()));
        self.compressor.compress_to_buffer(records, &mut self.compressed)?;
        let (first, last) = chunk.times.unwrap_or((0, 0));
        let start = self.out.position;
        let mut header = Record::new(op::CHUNK);
        header.u64(first);
        header.u64(last);
        header.u64(records.len() as u64);
        header.u32(crc32fast::hash(records));
        header.string("zstd");
        header.u64(self.compressed.len() as u64);
        // The record's length covers the compressed records after this header.
        let length = (header.bytes.len() - 9 + self.compressed.len()) as u64;
        header.bytes[1..9].copy_from_slice(&length.to_le_bytes());
        self.out.write(&header.bytes);
        self.out.write(&self.compressed);
        let chunk_length = self.out.position - start;

        let indexes_start = self.out.position;
        let mut offsets = vec![];
        for (&channel, entries) in &chunk.index {
            offsets.push((channel, self.out.position));
            let mut index = Record::new(op::MESSAGE_INDEX);
            index.u16(channel);
            index.map(entries, |r, &(log_time, offset)| {
                r.u64(log_time);
                r.u64(offset);
            });
            self.out.write(index.finish());
        }
        let mut chunk_index = Record::new(op::CHUNK_INDEX);
        chunk_index.u64(first);
        chunk_index.u64(last);
        chunk_index.u64(start);
        chunk_index.u64(chunk_length);
        chunk_index.map(offsets, |r, (channel, offset)| {
            r.u16(channel);
            r.u64(offset);
        });
        chunk_index.u64(self.out.position - indexes_start);
        chunk_index.string("zstd");
        chunk_index.u64(self.compressed.len() as u64);
        chunk_index.u64(records.len() as u64);
        self.chunk_indexes.extend_from_slice(chunk_index.finish());
        self.chunk_count += 1;
        self.out.check()
    }

    fn flush(&mut self) -> Result<()> {
        self.out.check()?;
        Ok(self.out.file.flush()?)
    }

    /// The data end, the summary section, the footer.
    fn finish(mut self, summary: Summary) -> Result<()> {
        let mut data_end = Record::new(op::DATA_END);
        data_end.u32(self.out.crc.clone().finalize());
        self.out.write(data_end.finish());
        // From here the CRC is the summary's.
        self.out.crc = crc32fast::Hasher::new();
        let summary_start = self.out.position;
        let mut offsets = vec![];
        let mut group = |out: &mut Output, opcode: u8, records: &[u8]| {
            if !records.is_empty() {
                offsets.push((opcode, out.position, records.len() as u64));
                out.write(records);
            }
        };
        group(&mut self.out, op::SCHEMA, &summary.schemas);
        group(&mut self.out, op::CHANNEL, &summary.channels);
        let mut statistics = summary.statistics;
        statistics.u32(self.chunk_count);
        statistics.u64(summary.first);
        statistics.u64(summary.last);
        statistics.map(&summary.counts, |r, (&channel, &count)| {
            r.u16(channel);
            r.u64(count);
        });
        group(&mut self.out, op::STATISTICS, statistics.finish());
        group(&mut self.out, op::CHUNK_INDEX, &self.chunk_indexes);
        let summary_offset_start = self.out.position;
        for (opcode, start, length) in offsets {
            let mut offset = Record::new(op::SUMMARY_OFFSET);
            offset.bytes(&[opcode]);
            offset.u64(start);
            offset.u64(length);
            self.out.write(offset.finish());
        }
        // The summary's CRC covers the footer up to the CRC itself, which its length counts.
        let mut footer = Record::new(op::FOOTER);
        footer.u64(summary_start);
        footer.u64(summary_offset_start);
        footer.bytes[1..9].copy_from_slice(&20u64.to_le_bytes());
        self.out.write(&footer.bytes);
        let crc = self.out.crc.clone().finalize();
        self.out.write(&crc.to_le_bytes());
        self.out.write(MAGIC);
        self.flush()
    }
}

/// The chunk writer in this thread, or on its own.
enum ChunkWriter {
    Inline(Box<FileWriter>),
    OnThread {
        jobs: Sender<Job>,
        /// Chunks it is done with, to be filled again.
        emptied: Receiver<Chunk>,
        /// None once joined.
        thread: Option<JoinHandle<Result<FileWriter>>>,
    },
}

enum Job {
    /// A record of the data section before the first chunk (a schema, a channel).
    Record(Vec<u8>),
    Chunk(Chunk),
    /// Flush, then say so.
    Flush(Sender<Result<()>>),
}

impl ChunkWriter {
    fn on_thread(self) -> Result<Self> {
        let ChunkWriter::Inline(mut writer) = self else { return Ok(self) };
        // Two chunks in flight: one compressed while the next fills.
        let (jobs, received) = bounded::<Job>(2);
        let (give_back, emptied) = bounded(4);
        let thread = std::thread::Builder::new().name("mcap-chunks".into()).spawn(move || {
            for job in received {
                match job {
                    Job::Record(bytes) => writer.out.write(&bytes),
                    Job::Chunk(mut chunk) => {
                        writer.chunk(&chunk)?;
                        chunk.clear();
                        let _ = give_back.try_send(chunk);
                    }
                    Job::Flush(done) => {
                        let _ = done.send(writer.flush());
                    }
                }
            }
            Ok(*writer)
        })?;
        Ok(ChunkWriter::OnThread { jobs, emptied, thread: Some(thread) })
    }

    fn send(&mut self, job: Job) -> Result<()> {
        match self {
            ChunkWriter::Inline(_) => unreachable!("an inline writer takes no jobs"),
            ChunkWriter::OnThread { jobs, .. } => match jobs.send(job) {
                Ok(()) => Ok(()),
                // The thread ended on an error: that error.
                Err(_) => Err(self.join().err().unwrap_or_else(|| anyhow!("the MCAP chunk writer stopped"))),
            },
        }
    }

    /// Ends the thread, if there is one, and takes its writer back.
    fn join(&mut self) -> Result<Box<FileWriter>> {
        match self {
            ChunkWriter::Inline(_) => unreachable!("joined an inline writer"),
            ChunkWriter::OnThread { jobs, thread, .. } => {
                // Hang up, so that the thread ends.
                drop(std::mem::replace(jobs, bounded(0).0));
                let thread = thread.take().ok_or_else(|| anyhow!("the MCAP chunk writer stopped"))?;
                Ok(Box::new(thread.join().map_err(|_| anyhow!("the MCAP chunk writer panicked"))??))
            }
        }
    }

    fn header_record(&mut self, bytes: &[u8]) -> Result<()> {
        match self {
            ChunkWriter::Inline(writer) => {
                writer.out.write(bytes);
                writer.out.check()
            }
            ChunkWriter::OnThread { .. } => self.send(Job::Record(bytes.to_vec())),
        }
    }

    /// Writes `chunk` and leaves it empty, to be filled again.
    fn chunk(&mut self, chunk: &mut Chunk) -> Result<()> {
        match self {
            ChunkWriter::Inline(writer) => {
                writer.chunk(chunk)?;
                chunk.clear();
                Ok(())
            }
            ChunkWriter::OnThread { emptied, .. } => {
                let next = emptied.try_recv().unwrap_or_else(|_| Chunk::new());
                let full = std::mem::replace(chunk, next);
                self.send(Job::Chunk(full))
            }
        }
    }

    fn flush(&mut self) -> Result<()> {
        match self {
            ChunkWriter::Inline(writer) => writer.flush(),
            ChunkWriter::OnThread { .. } => {
                let (done, flushed) = bounded(1);
                self.send(Job::Flush(done))?;
                match flushed.recv() {
                    Ok(result) => result,
                    Err(_) => Err(self.join().err().unwrap_or_else(|| anyhow!("the MCAP chunk writer stopped"))),
                }
            }
        }
    }

    fn finish(mut self, summary: Summary) -> Result<()> {
        let writer = match self {
            ChunkWriter::Inline(writer) => writer,
            ChunkWriter::OnThread { .. } => self.join()?,
        };
        writer.finish(summary)
    }
}

#[cfg(test)]
#[path = "file_tests.rs"]
mod tests;
