//! MCAP reading with every declared length bounded.
//!
//! The mcap crate's `MessageStream` flattens chunks with no record-length
//! limit: a record inside a chunk that declares 3·10¹⁸ bytes makes the
//! linear reader reserve that much and the process abort (found by the
//! fuzz pass over mutated bags; a cap on the chunk's declared uncompressed
//! size did not cover it). `Summary::read` likewise trusts the lengths of
//! the summary section. These readers drive the crate's sans-io readers
//! with a record-length limit instead, so a lying length is an error.
//!
//! Inside a record, every length prefix (strings, byte arrays, maps) is
//! checked against the record's own length before the crate parses it
//! ([`check_lengths`]): the crate reads strings through binrw, which
//! reserves the claimed length first, and libFuzzer found a 4.7 kB bag
//! whose summary Channel record claimed a 2.8 GB topic string (a 2.8 GB
//! allocation; an abort where memory is not overcommitted).

use std::borrow::Cow;
use std::sync::Arc;

use mcap::read::ChannelAccumulator;
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::sans_io::summary_reader::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
use mcap::{McapError, McapResult, Message, Summary};

/// Largest record accepted inside a chunk, and largest uncompressed chunk
/// (rosbag2 writes 4 MiB chunks by default; one 20 k-point cloud is
/// 320 KiB). A larger declared length is rejected before any allocation.
const MAX_RECORD_BYTES: usize = 1 << 30;

/// The record-length limit for a file of `file_len` bytes: 64 times its
/// size (real sensor data compresses 1.5–4×), at least 1 MiB, at most
/// [`MAX_RECORD_BYTES`]. The crate zero-fills a record's declared length
/// before decompressing into it, so the limit is also the work a lying
/// length can cause: with 1 GiB for every file, 10 in 10⁶ mutated 4.9 kB
/// bags took 3–25 ms (over 100 ms per MB of input).
fn record_limit(file_len: usize) -> usize {
    file_len.saturating_mul(64).clamp(1 << 20, MAX_RECORD_BYTES)
}

/// The messages of an in-memory MCAP file, in file order, with their
/// channels; chunks are decompressed with every length bounded by
/// [`record_limit`]. Ends at the first error.
pub(super) struct Messages<'a> {
    buf: &'a [u8],
    reader: LinearReader,
    channels: ChannelAccumulator<'static>,
    past_data_end: bool,
    done: bool,
}

impl<'a> Messages<'a> {
    /// A stream over `buf` (both magics expected).
    pub(super) fn new(buf: &'a [u8]) -> Self {
        let options =
            LinearReaderOptions::default().with_record_length_limit(record_limit(buf.len()));
        Self {
            buf,
            reader: LinearReader::new_with_options(options),
            channels: ChannelAccumulator::default(),
            past_data_end: false,
            done: false,
        }
    }

    /// The next record, or `None` at the end of the file.
    fn record(&mut self) -> Option<McapResult<Record<'static>>> {
        while let Some(event) = self.reader.next_event() {
            match event {
                Ok(LinearReadEvent::ReadRequest(need)) => {
                    let len = need.min(self.buf.len());
                    self.reader.insert(len).copy_from_slice(&self.buf[..len]);
                    self.reader.notify_read(len);
                    self.buf = &self.buf[len..];
                }
                Ok(LinearReadEvent::Record { data, opcode }) => {
                    let parsed =
                        check_lengths(opcode, data).and_then(|()| mcap::parse_record(opcode, data));
                    return Some(parsed.map(Record::into_owned));
                }
                Err(e) => return Some(Err(e)),
            }
        }
        None
    }

    /// Account for one record; a message comes back with its channel.
    fn take(&mut self, record: Record<'static>) -> McapResult<Option<Message<'static>>> {
        if self.past_data_end {
            // The summary repeats schemas and channels: not re-checked.
            return Ok(None);
        }
        match record {
            Record::Schema { header, data } => {
                self.channels
                    .add_schema(header, Cow::Owned(data.into_owned()))?;
            }
            Record::Channel(channel) => self.channels.add_channel(channel)?,
            Record::Message { header, data } => {
                let channel: Arc<_> =
                    self.channels
                        .get(header.channel_id)
                        .ok_or(McapError::UnknownChannel(
                            header.sequence,
                            header.channel_id,
                        ))?;
                return Ok(Some(Message {
                    channel,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    data: Cow::Owned(data.into_owned()),
                }));
            }
            Record::DataEnd(_) => self.past_data_end = true,
            _ => {}
        }
        Ok(None)
    }
}

impl Iterator for Messages<'_> {
    type Item = McapResult<Message<'static>>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let step = match self.record() {
                Some(Ok(record)) => self.take(record).transpose(),
                Some(Err(e)) => Some(Err(e)),
                None => {
                    self.done = true;
                    return None;
                }
            };
            if let Some(item) = step {
                self.done = item.is_err();
                return Some(item);
            }
        }
        None
    }
}

/// The summary section of an in-memory MCAP file, if it has one, with every
/// record length bounded by the file's size.
pub(super) fn summary(buf: &[u8]) -> McapResult<Option<Summary>> {
    check_summary(buf)?;
    let options = SummaryReaderOptions::default()
        .with_file_size(buf.len() as u64)
        .with_record_length_limit(buf.len());
    let mut reader = SummaryReader::new_with_options(options);
    let mut pos = 0usize;
    while let Some(event) = reader.next_event() {
        match event? {
            SummaryReadEvent::ReadRequest(need) => {
                let from = pos.min(buf.len());
                let len = need.min(buf.len() - from);
                reader.insert(len).copy_from_slice(&buf[from..from + len]);
                reader.notify_read(len);
                pos = from + len;
            }
            SummaryReadEvent::SeekRequest(to) => {
                pos = seek(to, pos, buf.len())?;
                reader.notify_seeked(pos as u64);
            }
        }
    }
    Ok(reader.finish())
}

/// A seek within a buffer of `len` bytes (past the end reads nothing).
fn seek(to: std::io::SeekFrom, pos: usize, len: usize) -> McapResult<usize> {
    let target = match to {
        std::io::SeekFrom::Start(n) => i128::from(n),
        std::io::SeekFrom::End(n) => len as i128 + i128::from(n),
        std::io::SeekFrom::Current(n) => pos as i128 + i128::from(n),
    };
    usize::try_from(target).map_err(|_| {
        McapError::Io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("seek to {target}, outside the file"),
        ))
    })
}

/// A field of a record, in the MCAP specification's order.
#[derive(Debug, Clone, Copy)]
enum Field {
    /// `n` bytes of fixed-size fields.
    Fixed(usize),
    /// A `u32` byte length and that many bytes (strings, byte arrays, maps
    /// of fixed-size entries).
    Sized32,
    /// A `u64` byte length and that many bytes.
    Sized64,
    /// A `u32` byte length of `string → string` entries, each two strings.
    StrMap,
    /// A `u32` byte length of fixed-size entries of this many bytes: the
    /// crate reads whole entries while it has read less than the length,
    /// so a length that is not a multiple shifts every later field.
    Entries(usize),
}

/// The fields of each record type up to its last length-prefixed one.
fn layout(opcode: u8) -> &'static [Field] {
    use Field::{Entries, Fixed, Sized32, Sized64, StrMap};
    match opcode {
        0x01 => &[Sized32, Sized32],
        0x03 => &[Fixed(2), Sized32, Sized32, Sized32],
        0x04 => &[Fixed(4), Sized32, Sized32, StrMap],
        0x06 => &[Fixed(28), Sized32, Sized64],
        0x07 => &[Fixed(2), Entries(16)],
        0x08 => &[Fixed(32), Entries(10), Fixed(8), Sized32],
        0x09 => &[Fixed(16), Sized32, Sized32, Sized64],
        0x0A => &[Fixed(40), Sized32, Sized32],
        0x0B => &[Fixed(42), Entries(10)],
        0x0C => &[Sized32, StrMap],
        0x0D => &[Fixed(16), Sized32],
        _ => &[],
    }
}

/// The end of a field at `at` of a `width`-byte little-endian length and
/// that many bytes, if it lies within `body`.
fn prefixed(body: &[u8], at: usize, width: usize) -> Option<usize> {
    let start = at.checked_add(width)?;
    let mut raw = [0u8; 8];
    raw[..width].copy_from_slice(body.get(at..start)?);
    let end = start.checked_add(usize::try_from(u64::from_le_bytes(raw)).ok()?)?;
    (end <= body.len()).then_some(end)
}

/// The end of a `string → string` map at `at`, if it and every string in
/// it lie within `body`.
fn str_map(body: &[u8], at: usize) -> Option<usize> {
    let end = prefixed(body, at, 4)?;
    let entries = &body[..end];
    let mut p = at + 4;
    while p < end {
        p = prefixed(entries, prefixed(entries, p, 4)?, 4)?;
    }
    Some(end)
}

/// Check that every length prefix of a record of type `opcode` lies within
/// its `body`.
///
/// # Errors
/// An `InvalidData` error naming the record type and the offset.
pub(super) fn check_lengths(opcode: u8, body: &[u8]) -> McapResult<()> {
    let mut at = 0usize;
    for field in layout(opcode) {
        let end = match *field {
            Field::Fixed(n) => at.checked_add(n).filter(|&e| e <= body.len()),
            Field::Sized32 => prefixed(body, at, 4),
            Field::Sized64 => prefixed(body, at, 8),
            Field::StrMap => str_map(body, at),
            Field::Entries(size) => prefixed(body, at, 4).filter(|&end| (end - at - 4) % size == 0),
        };
        at = end.ok_or_else(|| {
            McapError::Io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "record {opcode:#04x} of {} bytes: the field at byte {at} claims more than the record holds",
                    body.len()
                ),
            ))
        })?;
    }
    Ok(())
}

/// Check the length prefixes of every record of the summary section (found
/// through the footer) before the crate's summary reader parses them; a
/// record running past the footer is an error. A file without a footer or
/// a summary passes (the reader reports those).
fn check_summary(buf: &[u8]) -> McapResult<()> {
    // Footer: opcode, u64 length 20, summary_start, summary_offset_start,
    // crc; then the 8-byte magic.
    let Some(footer) = buf.len().checked_sub(8 + 29) else {
        return Ok(());
    };
    let u64_at = |p: usize| {
        buf.get(p..p + 8).map(|b| {
            let mut raw = [0u8; 8];
            raw.copy_from_slice(b);
            u64::from_le_bytes(raw)
        })
    };
    if buf[footer] != 0x02 {
        return Ok(());
    }
    let start = u64_at(footer + 9)
        .and_then(|s| usize::try_from(s).ok())
        .unwrap_or(0);
    if start == 0 || start >= footer {
        return Ok(());
    }
    let mut p = start;
    while p + 9 <= footer {
        let opcode = buf[p];
        let len = u64_at(p + 1).and_then(|l| usize::try_from(l).ok());
        let Some(end) = len
            .and_then(|l| (p + 9).checked_add(l))
            .filter(|&e| e <= footer)
        else {
            return Err(McapError::RecordTooLarge {
                opcode,
                len: u64_at(p + 1).unwrap_or(u64::MAX),
            });
        };
        check_lengths(opcode, &buf[p + 9..end])?;
        p = end;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn string(s: &[u8]) -> Vec<u8> {
        let mut v = (s.len() as u32).to_le_bytes().to_vec();
        v.extend_from_slice(s);
        v
    }

    #[test]
    fn a_length_prefix_past_its_record_is_an_error() {
        // Channel: id, schema id, topic, encoding, empty metadata map.
        let mut ok = vec![1, 0, 0, 0];
        ok.extend(string(b"/points"));
        ok.extend(string(b"cdr"));
        ok.extend(0u32.to_le_bytes());
        assert!(check_lengths(0x04, &ok).is_ok());
        let mut lying = ok.clone();
        lying[4..8].copy_from_slice(&0xA7A0_0000u32.to_le_bytes());
        assert!(check_lengths(0x04, &lying).is_err());
        // A metadata map whose value claims 2 GB.
        let mut meta = string(b"name");
        let mut entries = string(b"k");
        entries.extend(0x8000_0000u32.to_le_bytes());
        meta.extend((entries.len() as u32).to_le_bytes());
        meta.extend(entries);
        assert!(check_lengths(0x0C, &meta).is_err());
        // A chunk index whose offsets map is not a whole number of entries
        // (the crate would read past it and take the compression string's
        // length from the wrong bytes).
        let mut index = vec![0u8; 32];
        index.extend(5u32.to_le_bytes());
        index.extend([0u8; 5 + 8]);
        index.extend(string(b"zstd"));
        assert!(check_lengths(0x08, &index).is_err());
        let mut whole = vec![0u8; 32];
        whole.extend(10u32.to_le_bytes());
        whole.extend([0u8; 10 + 8]);
        whole.extend(string(b"zstd"));
        whole.extend([0u8; 16]);
        assert!(check_lengths(0x08, &whole).is_ok());
        // Truncated fixed fields, and an unknown opcode (nothing to check).
        assert!(check_lengths(0x0D, &[0; 10]).is_err());
        assert!(check_lengths(0x80, &[]).is_ok());
    }
}
