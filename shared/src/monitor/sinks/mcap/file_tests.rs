//! The file read back with the `mcap` crate: linearly with every CRC checked, through its
//! summary and indexes, and, unfinished, as a killed monitor leaves it.

use std::collections::BTreeMap;
use std::path::Path;

use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

use super::*;

/// What was written: (channel, sequence, log time, publish time, data).
type Written = Vec<(u16, u32, u64, u64, Vec<u8>)>;

/// Two schemas, three channels, and messages enough for several chunks: flushed halfway and
/// then again before the end; `finish` or not.
fn write(path: &Path, compression: Compression, finish: bool) -> Written {
    let mut file = McapFile::create(path, compression).unwrap();
    let state = file.add_schema("looplab.State", "jsonschema", br#"{"type":"object"}"#).unwrap();
    let other = file.add_schema("looplab.Other", "jsonschema", b"{}").unwrap();
    assert_eq!((state, other), (1, 2));
    let metadata = BTreeMap::from([("log_time".to_string(), "simulation".to_string())]);
    let channels = [
        file.add_channel(state, "/state", "json", &metadata).unwrap(),
        file.add_channel(other, "/other", "json", &BTreeMap::new()).unwrap(),
        // Never written to: no message index, no count.
        file.add_channel(other, "/silent", "json", &BTreeMap::new()).unwrap(),
    ];
    assert_eq!(channels, [0, 1, 2]);
    let mut written = vec![];
    let n = 12_000u32;
    for i in 0..n {
        let channel = channels[(i % 2) as usize];
        // Some 200 bytes each, varied enough that chunks fill at their size.
        let data = format!("{{\"k\":{i},\"pad\":\"{}\"}}", "x".repeat(150 + (i % 50) as usize)).into_bytes();
        let (log, publish) = (u64::from(i) * 1_000_000, u64::from(i) * 1_000_000 + 7);
        file.write(channel, i / 2, log, publish, &data).unwrap();
        written.push((channel, i / 2, log, publish, data));
        if i == n / 2 || i == n - 10 {
            file.flush().unwrap();
        }
    }
    if finish {
        file.finish().unwrap();
    } else {
        file.flush().unwrap();
    }
    written
}

/// The messages read in order; `unfinished`: up to where the file ends.
fn messages(bytes: &[u8], unfinished: bool) -> Written {
    let stream = match unfinished {
        true => mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into()),
        false => mcap::MessageStream::new(bytes),
    };
    let mut read = vec![];
    for message in stream.unwrap() {
        match message {
            Ok(m) => read.push((m.channel.id, m.sequence, m.log_time, m.publish_time, m.data.into_owned())),
            Err(mcap::McapError::UnexpectedEof) => break,
            Err(e) => panic!("{e}"),
        }
    }
    read
}

/// Every record, with the chunks', the data section's and the summary's CRCs checked.
fn records_checked(bytes: &[u8]) -> Vec<u8> {
    let options = LinearReaderOptions::default()
        .with_validate_chunk_crcs(true)
        .with_validate_data_section_crc(true)
        .with_validate_summary_section_crc(true)
        .with_emit_chunks(true);
    let mut reader = LinearReader::new_with_options(options);
    let mut rest = bytes;
    let mut opcodes = vec![];
    while let Some(event) = reader.next_event() {
        match event.unwrap() {
            LinearReadEvent::ReadRequest(n) => {
                let n = n.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            LinearReadEvent::Record { opcode, .. } => opcodes.push(opcode),
        }
    }
    opcodes
}

#[test]
fn a_finished_file_reads_back_whole_with_every_crc_checked_and_every_index_right() {
    for compression in [Compression::Inline, Compression::OnThread] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.mcap");
        let written = write(&path, compression, true);
        let bytes = std::fs::read(&path).unwrap();

        assert_eq!(messages(&bytes, false), written, "{compression:?}");
        let opcodes = records_checked(&bytes);
        let chunks = opcodes.iter().filter(|&&op| op == op::CHUNK).count();
        // The data section: the header, the schemas and channels, the chunks with their indexes.
        assert_eq!(&opcodes[..6], [op::HEADER, op::SCHEMA, op::SCHEMA, op::CHANNEL, op::CHANNEL, op::CHANNEL]);
        assert!(chunks >= 4, "{chunks} chunks: two flushes and at least two full ones");
        assert_eq!(opcodes.last(), Some(&op::FOOTER));

        let summary = mcap::Summary::read(&bytes).unwrap().expect("a summary");
        let stats = summary.stats.as_ref().unwrap();
        assert_eq!((stats.message_count, stats.schema_count, stats.channel_count), (12_000, 2, 3));
        assert_eq!(
            (stats.chunk_count as usize, stats.message_start_time, stats.message_end_time),
            (chunks, 0, 11_999_000_000)
        );
        assert_eq!(stats.channel_message_counts, BTreeMap::from([(0, 6000), (1, 6000)]));
        assert_eq!(summary.channels[&0].topic, "/state");
        assert_eq!(summary.channels[&0].metadata["log_time"], "simulation");
        assert_eq!(summary.channels[&2].schema.as_ref().unwrap().name, "looplab.Other");
        assert_eq!(summary.chunk_indexes.len(), chunks);
        // Through the indexes: each chunk's messages, and where each lies in it.
        let mut indexed = vec![];
        for index in &summary.chunk_indexes {
            let in_chunk: Written = summary
                .stream_chunk(&bytes, index)
                .unwrap()
                .map(|m| m.unwrap())
                .map(|m| (m.channel.id, m.sequence, m.log_time, m.publish_time, m.data.into_owned()))
                .collect();
            assert_eq!((index.message_start_time, index.message_end_time), (in_chunk[0].2, in_chunk.last().unwrap().2));
            let indexes = summary.read_message_indexes(&bytes, index).unwrap();
            assert_eq!(indexes.values().map(Vec::len).sum::<usize>(), in_chunk.len());
            for (channel, entries) in &indexes {
                // Each seek decompresses the chunk: the first and the last message of each channel.
                for entry in [&entries[0], entries.last().unwrap()] {
                    let message = summary.seek_message(&bytes, index, entry).unwrap();
                    assert_eq!((message.channel.id, message.log_time), (channel.id, entry.log_time));
                }
            }
            indexed.extend(in_chunk);
        }
        assert_eq!(indexed, written);
    }
}

#[test]
fn a_file_left_unfinished_reads_up_to_its_last_flush() {
    for compression in [Compression::Inline, Compression::OnThread] {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.mcap");
        let written = write(&path, compression, false);
        let bytes = std::fs::read(&path).unwrap();
        assert!(!matches!(mcap::Summary::read(&bytes), Ok(Some(_))), "no summary");
        let read = messages(&bytes, true);
        assert_eq!(read, written, "{compression:?}");
    }
}

#[test]
fn no_messages_make_a_file_with_no_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let mut file = McapFile::create(&path, Compression::OnThread).unwrap();
    let schema = file.add_schema("s", "jsonschema", b"{}").unwrap();
    file.add_channel(schema, "/state", "json", &BTreeMap::new()).unwrap();
    file.flush().unwrap();
    file.finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert!(!records_checked(&bytes).contains(&op::CHUNK));
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert_eq!(summary.stats.unwrap().message_count, 0);
    assert_eq!(summary.channels.len(), 1);
}
