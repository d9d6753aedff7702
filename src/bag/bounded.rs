//! MCAP reading with every declared length bounded.
//!
//! The mcap crate's `MessageStream` flattens chunks with no record-length
//! limit: a record inside a chunk that declares 3·10¹⁸ bytes makes the
//! linear reader reserve that much and the process abort (found by the
//! fuzz pass over mutated bags; a cap on the chunk's declared uncompressed
//! size did not cover it). `Summary::read` likewise trusts the lengths of
//! the summary section. These readers drive the crate's sans-io readers
//! with a record-length limit instead, so a lying length is an error.

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
                    return Some(mcap::parse_record(opcode, data).map(Record::into_owned));
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
