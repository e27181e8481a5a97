//! The append-only, crash-safe frame log (`frames.log`).
//!
//! # Format
//!
//! A file header, then records `len: u32 LE ‖ crc32(payload): u32 LE ‖ payload`. A payload is one
//! wire frame exactly as the rig sent it (COBS-stuffed, closing zero included, with its own CRC-32),
//! so the log can be replayed byte for byte.
//!
//! | format | header | |
//! |---|---|---|
//! | v2 (written now) | 24 bytes: `TRIBOLOG`, format u32 LE = 2, flags u32 LE = 0, protocol u16 LE, reserved u16 = 0, CRC-32 of the 20 bytes before it | `protocol`: the wire protocol the rig spoke (0: not known), which picks the decoder of the frames |
//! | v1 | 16 bytes: `TRIBOLOG`, format u32 LE = 1, flags u32 LE = 0 | the protocol was not recorded: frames are read as today's protocol, else as v1 |
//!
//! Every later format keeps the v2 header's first 24 bytes as they are (a new format may add after
//! them), so a log of a newer format is told from a damaged header by the header's CRC and refused
//! with a clear error (update tribo). v1 logs stay readable, and are appended to in their own format.
//!
//! # Crash safety
//!
//! Each record is written with a single `write_all` on an unbuffered file opened for appending, so a
//! killed process leaves at most one torn record at the end; a pulled cable leaves the log as it
//! was. [`LogWriter::sync`] (fsync) is called by the run writer after the run header, then at most
//! every second, and at the end, bounding what a power cut can take.
//!
//! # Damage
//!
//! Reading tells a torn tail (the last record runs past the end of the file, or fails its CRC with
//! nothing valid after it: the trace of an interrupted write, cut off and reported as a
//! [`Recovery`]) from corruption (a bad record with intact records after it: an error, unless
//! salvaging). Salvage keeps every record whose CRC holds, wherever the damage is: after a bad
//! record it resynchronises on the next position where a whole record with a valid CRC starts, and
//! inside the damaged stretch it rescues each wire frame whose own CRC holds (a record whose length
//! or checksum field was hit keeps its frame). [`LogWriter::reopen`] with salvage rewrites the log
//! with the records kept (atomically) and keeps the damaged file beside it (`frames.log.damaged`).

use crate::{ErrorKind, Result, StoreError};
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use tribo_wire::crc32::crc32;
use tribo_wire::frame::{cobs_decode_in_place, MAX_FRAME};

/// The first eight bytes of every frame log.
pub const MAGIC: &[u8; 8] = b"TRIBOLOG";
/// The format written.
pub const FORMAT_VERSION: u32 = 2;
/// Length of the v2 header (the one written).
pub const HEADER_LEN: u64 = 24;
/// Length of the v1 header.
pub const HEADER_LEN_V1: u64 = 16;
/// Largest payload accepted (a wire frame is at most ~1.1 kB).
pub const MAX_RECORD: u32 = 64 * 1024;

/// What the file header says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LogHeader {
    /// Format version (1 or 2).
    pub format: u32,
    /// The wire protocol of the frames (`None`: not recorded, or the header was damaged).
    pub protocol: Option<u16>,
}

impl LogHeader {
    /// The header a new log gets.
    pub fn current(protocol: Option<u16>) -> LogHeader {
        LogHeader {
            format: FORMAT_VERSION,
            protocol,
        }
    }

    /// Its length in the file.
    pub fn len(&self) -> u64 {
        if self.format == 1 {
            HEADER_LEN_V1
        } else {
            HEADER_LEN
        }
    }

    /// Always false: a header has bytes (for clippy's `len_without_is_empty`).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The header's bytes.
    pub fn bytes(&self) -> Vec<u8> {
        let mut h = Vec::with_capacity(HEADER_LEN as usize);
        h.extend_from_slice(MAGIC);
        h.extend_from_slice(&self.format.to_le_bytes());
        h.extend_from_slice(&0u32.to_le_bytes());
        if self.format >= 2 {
            h.extend_from_slice(&self.protocol.unwrap_or(0).to_le_bytes());
            h.extend_from_slice(&0u16.to_le_bytes());
            let c = crc32(&h);
            h.extend_from_slice(&c.to_le_bytes());
        }
        h
    }
}

/// A damaged stretch of a log that salvage skipped.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    /// Byte offset where the damage starts (where a valid record was expected).
    pub at: u64,
    /// Its length, up to the next intact record (or the end of the file).
    pub len: u64,
    /// Intact records read before it.
    pub after_record: usize,
    /// Wire frames found whole inside it (their own CRC holds), kept as records.
    pub rescued: usize,
}

/// What was cut off or skipped when a log was read or reopened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recovery {
    /// Records kept (intact ones, and frames rescued from damaged stretches).
    pub records: usize,
    /// Length of the intact prefix, bytes (up to the first problem).
    pub valid_bytes: u64,
    /// Bytes not kept in any record (damaged stretches and a torn tail).
    pub dropped_bytes: u64,
    /// True when corruption (not just a torn tail) was skipped (salvage mode only).
    pub salvaged_corruption: bool,
    /// The damaged stretches skipped, in order (salvage mode only).
    pub damage: Vec<Damage>,
    /// The file header was damaged and rebuilt (salvage mode only).
    pub header_damaged: bool,
    /// Bytes of a torn or damaged last record cut off the end, if any.
    pub tail_bytes: u64,
}

impl Recovery {
    fn tail(records: usize, at: u64, dropped: u64) -> Recovery {
        Recovery {
            records,
            valid_bytes: at,
            dropped_bytes: dropped,
            salvaged_corruption: false,
            damage: vec![],
            header_damaged: false,
            tail_bytes: dropped,
        }
    }

    /// Frames rescued from damaged stretches.
    pub fn rescued(&self) -> usize {
        self.damage.iter().map(|d| d.rescued).sum()
    }
}

impl std::fmt::Display for Recovery {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if !self.salvaged_corruption {
            return write!(
                f,
                "dropped a torn last record ({} bytes after byte {}): the writer was stopped mid-write \
                 (or the record was damaged); the {} records before it are intact",
                self.tail_bytes, self.valid_bytes, self.records
            );
        }
        let spans: Vec<String> = self
            .damage
            .iter()
            .map(|d| format!("bytes {}–{}", d.at, d.at + d.len))
            .collect();
        write!(
            f,
            "salvaged {} intact records; skipped {} damaged stretch{} ({}){}{}",
            self.records,
            self.damage.len(),
            if self.damage.len() == 1 { "" } else { "es" },
            spans.join(", "),
            match self.rescued() {
                0 => String::new(),
                n =>
                    format!(", in which {n} frames were whole (their own CRC holds) and were kept"),
            },
            if self.header_damaged {
                "; the file header was damaged and was rebuilt"
            } else {
                ""
            }
        )?;
        if self.tail_bytes > 0 {
            write!(f, "; cut a torn last record of {} bytes", self.tail_bytes)?;
        }
        write!(f, "; {} bytes dropped in all", self.dropped_bytes)
    }
}

/// The records of a log and what, if anything, had to be cut off or skipped.
#[derive(Debug, Clone)]
pub struct LogContents {
    /// The log's header.
    pub header: LogHeader,
    /// Its records, in order, each as written.
    pub records: Vec<Vec<u8>>,
    /// What had to be cut off or skipped, if anything.
    pub recovery: Option<Recovery>,
}

/// Reads frame logs.
pub struct LogReader;

impl LogReader {
    /// Reads the log at `path`. A torn tail is dropped and reported in
    /// [`LogContents::recovery`]; corruption before the end is an error unless `salvage`, in which
    /// case every intact record is returned.
    pub fn read(path: &Path, salvage: bool) -> Result<LogContents> {
        let mut bytes = Vec::new();
        File::open(path)
            .and_then(|mut f| f.read_to_end(&mut bytes))
            .map_err(|e| {
                StoreError::io(format!("cannot read the frame log {}", path.display()), e)
            })?;
        parse(&bytes, path, salvage)
    }
}

fn corrupt(path: &Path, what: String) -> StoreError {
    StoreError::new(ErrorKind::Corrupt, format!("{}: {what}", path.display()))
}

/// Why the bytes at a position are not a record.
#[derive(Debug, Clone, Copy)]
enum Bad {
    /// Fewer than 8 bytes left.
    ShortHeader,
    /// Length 0 or above [`MAX_RECORD`].
    Length(u32),
    /// The record runs past the end of the file.
    PastEnd,
    /// Its CRC does not match (`last`: it ends exactly at the end of the file).
    Crc { last: bool },
}

impl Bad {
    fn why(self) -> String {
        match self {
            Bad::ShortHeader => "incomplete record header".into(),
            Bad::Length(l) => format!("impossible record length {l}"),
            Bad::PastEnd => "record runs past the end of the file".into(),
            Bad::Crc { .. } => "record checksum mismatch".into(),
        }
    }
}

/// The record at `at`: its payload's length, or why it is not one.
fn record_at(bytes: &[u8], at: usize) -> std::result::Result<usize, Bad> {
    let rest = &bytes[at..];
    if rest.len() < 8 {
        return Err(Bad::ShortHeader);
    }
    let len = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]);
    let crc = u32::from_le_bytes([rest[4], rest[5], rest[6], rest[7]]);
    if len == 0 || len > MAX_RECORD {
        return Err(Bad::Length(len));
    }
    let end = 8 + len as usize;
    if end > rest.len() {
        return Err(Bad::PastEnd);
    }
    if crc32(&rest[8..end]) != crc {
        return Err(Bad::Crc {
            last: end == rest.len(),
        });
    }
    Ok(len as usize)
}

/// The first position at or after `from` where a whole record with a valid CRC starts.
fn next_record(bytes: &[u8], from: usize) -> Option<usize> {
    (from..bytes.len().saturating_sub(8)).find(|&p| record_at(bytes, p).is_ok())
}

/// Whether `frame` (stuffed, closing zero included) is a wire frame whose own CRC holds.
fn is_whole_frame(frame: &[u8]) -> bool {
    let Some((&0, body)) = frame.split_last() else {
        return false;
    };
    if body.is_empty() || body.len() > MAX_FRAME || body.contains(&0) {
        return false;
    }
    let mut buf = body.to_vec();
    let Some(n) = cobs_decode_in_place(&mut buf) else {
        return false;
    };
    if n < 8 {
        return false;
    }
    let (data, crc) = buf[..n].split_at(n - 4);
    crc32(data).to_le_bytes() == crc
}

/// The wire frames found whole inside a damaged stretch: each stretch between zero bytes, with up
/// to 8 leading bytes (a record header's remains) skipped, whose frame CRC holds.
fn rescue_frames(region: &[u8]) -> Vec<Vec<u8>> {
    let mut out = vec![];
    for chunk in region.split_inclusive(|&b| b == 0) {
        for skip in 0..=chunk.len().saturating_sub(9).min(8) {
            if is_whole_frame(&chunk[skip..]) {
                out.push(chunk[skip..].to_vec());
                break;
            }
        }
    }
    out
}

/// Reads the file header: `Ok(header)`, or why it cannot be trusted.
fn read_header(bytes: &[u8]) -> std::result::Result<LogHeader, String> {
    if bytes.len() < 12 || &bytes[..8] != MAGIC {
        return Err("not a tribo frame log (bad magic); is this the right file?".into());
    }
    let format = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    match format {
        1 if bytes.len() >= HEADER_LEN_V1 as usize => Ok(LogHeader {
            format,
            protocol: None,
        }),
        2 if bytes.len() >= HEADER_LEN as usize => {
            let crc = u32::from_le_bytes([bytes[20], bytes[21], bytes[22], bytes[23]]);
            if crc32(&bytes[..20]) != crc {
                return Err("the file header is damaged (its checksum does not match)".into());
            }
            let p = u16::from_le_bytes([bytes[16], bytes[17]]);
            Ok(LogHeader {
                format,
                protocol: (p != 0).then_some(p),
            })
        }
        1 | 2 => Err("the file ends inside its header".into()),
        // Every format keeps the v2 header's first 24 bytes (magic, format, flags, protocol,
        // reserved, CRC), so a newer one is told from a damaged number by its checksum.
        v if v > FORMAT_VERSION
            && bytes.len() >= HEADER_LEN as usize
            && crc32(&bytes[..20]).to_le_bytes() == bytes[20..24] =>
        {
            Err(format!(
                "frame log format v{v} is newer than this tribo, which reads v1–v{FORMAT_VERSION}: update \
                 tribo (or read the run with the tribo version that wrote it)"
            ))
        }
        v => Err(format!(
            "the file header is damaged (format number {v:#x} with a header checksum that does not match)"
        )),
    }
}

/// Whether `bytes` are the beginning of a header and nothing more (a writer stopped while writing it).
fn is_torn_header(bytes: &[u8]) -> bool {
    if bytes.len() < 12 {
        return MAGIC.starts_with(&bytes[..bytes.len().min(8)]);
    }
    let format = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    &bytes[..8] == MAGIC
        && ((format == 1 && bytes.len() < HEADER_LEN_V1 as usize)
            || (format == 2 && bytes.len() < HEADER_LEN as usize))
}

/// Parses a whole log held in memory.
pub fn parse(bytes: &[u8], path: &Path, salvage: bool) -> Result<LogContents> {
    if is_torn_header(bytes) {
        // Killed before the header was complete: an empty run.
        return Ok(LogContents {
            header: LogHeader::current(None),
            records: vec![],
            recovery: (!bytes.is_empty()).then(|| Recovery::tail(0, 0, bytes.len() as u64)),
        });
    }
    let (header, start, header_damaged) = match read_header(bytes) {
        Ok(h) => (h, h.len() as usize, false),
        Err(why) if why.contains("is newer") => {
            return Err(corrupt(path, why));
        }
        Err(why) => {
            // A damaged header: is there a log behind it?
            let first = next_record(bytes, HEADER_LEN_V1 as usize);
            if !salvage || first.is_none() {
                let follow = match first {
                    Some(_) => {
                        " — but intact records follow it: keep them with `tribo pull --salvage RUN`"
                    }
                    None => "",
                };
                return Err(corrupt(path, format!("{why}{follow}")));
            }
            // The format is whatever lines up with the first record.
            let at = first.unwrap_or(HEADER_LEN as usize);
            let format = if at == HEADER_LEN_V1 as usize { 1 } else { 2 };
            (
                LogHeader {
                    format,
                    protocol: None,
                },
                HEADER_LEN_V1 as usize,
                true,
            )
        }
    };
    let mut records: Vec<Vec<u8>> = Vec::new();
    let mut damage: Vec<Damage> = Vec::new();
    let mut first_problem: Option<usize> = header_damaged.then_some(0);
    let mut tail_bytes = 0u64;
    let mut rescued_bytes = 0u64;
    let mut at = start;
    while at < bytes.len() {
        let bad = match record_at(bytes, at) {
            Ok(len) => {
                records.push(bytes[at + 8..at + 8 + len].to_vec());
                at += 8 + len;
                continue;
            }
            Err(b) => b,
        };
        first_problem.get_or_insert(at);
        let next = next_record(bytes, at + 1);
        let tail_like = match bad {
            Bad::ShortHeader | Bad::PastEnd => true,
            Bad::Length(len) => {
                bytes.len() - at <= 8 + MAX_RECORD as usize && len as usize > bytes.len() - at
            }
            Bad::Crc { last } => last,
        };
        if next.is_none() && tail_like {
            // The trace of an interrupted write: cut off (salvage keeps a whole frame in it).
            let rescued = if salvage {
                rescue_frames(&bytes[at..])
            } else {
                vec![]
            };
            if rescued.is_empty() {
                tail_bytes = (bytes.len() - at) as u64;
            } else {
                rescued_bytes += rescued.iter().map(|r| r.len() as u64).sum::<u64>();
                damage.push(Damage {
                    at: at as u64,
                    len: (bytes.len() - at) as u64,
                    after_record: records.len(),
                    rescued: rescued.len(),
                });
                records.extend(rescued);
            }
            break;
        }
        if !salvage {
            return Err(corrupt(
                path,
                format!(
                    "corrupt at byte {at} (record {}): {}, and intact records follow{}, so this is damage, \
                     not an interrupted write. The {} records before it are intact: re-fetch the run with \
                     `tribo pull` if the rig still holds it, or keep every intact record and fetch only what \
                     is missing with `tribo pull --salvage`",
                    records.len(),
                    bad.why(),
                    next.map_or(String::new(), |n| format!(" from byte {n}")),
                    records.len(),
                ),
            ));
        }
        let end = next.unwrap_or(bytes.len());
        let rescued = rescue_frames(&bytes[at..end]);
        rescued_bytes += rescued.iter().map(|r| r.len() as u64).sum::<u64>();
        damage.push(Damage {
            at: at as u64,
            len: (end - at) as u64,
            after_record: records.len(),
            rescued: rescued.len(),
        });
        records.extend(rescued);
        at = end;
    }
    let recovery = first_problem.map(|p| {
        let skipped: u64 = damage.iter().map(|d| d.len).sum();
        Recovery {
            records: records.len(),
            valid_bytes: p as u64,
            dropped_bytes: tail_bytes + skipped - rescued_bytes,
            salvaged_corruption: !damage.is_empty() || header_damaged,
            damage,
            header_damaged,
            tail_bytes,
        }
    });
    Ok(LogContents {
        header,
        records,
        recovery,
    })
}

/// Appends records to a log.
pub struct LogWriter {
    file: File,
    path: PathBuf,
    records: usize,
    buf: Vec<u8>,
    header: LogHeader,
}

fn sync_dir(path: &Path) {
    if let Some(dir) = path.parent() {
        // Make directory entries durable too (best effort: not every system supports it).
        let _ = File::open(dir).and_then(|d| d.sync_all());
    }
}

fn frame_record(buf: &mut Vec<u8>, payload: &[u8]) {
    buf.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    buf.extend_from_slice(&crc32(payload).to_le_bytes());
    buf.extend_from_slice(payload);
}

/// A name beside `path` that does not exist yet: `frames.log.damaged`, `frames.log.damaged-2`…
fn free_name(path: &Path, suffix: &str) -> PathBuf {
    let base = format!("{}.{suffix}", path.display());
    (1..)
        .map(|n| {
            if n == 1 {
                PathBuf::from(&base)
            } else {
                PathBuf::from(format!("{base}-{n}"))
            }
        })
        .find(|p| !p.exists())
        .expect("a free name")
}

impl LogWriter {
    /// Creates a new, empty log (fails if the file exists) for frames of wire protocol `protocol`
    /// (`None`: not known) and makes it durable.
    pub fn create(path: &Path, protocol: Option<u16>) -> Result<LogWriter> {
        let mut file = OpenOptions::new()
            .create_new(true)
            .append(true)
            .open(path)
            .map_err(|e| StoreError::io(format!("cannot create {}", path.display()), e))?;
        let header = LogHeader::current(protocol);
        file.write_all(&header.bytes())
            .and_then(|_| file.sync_all())
            .map_err(|e| StoreError::io(format!("cannot write {}", path.display()), e))?;
        sync_dir(path);
        Ok(LogWriter {
            file,
            path: path.to_owned(),
            records: 0,
            buf: Vec::new(),
            header,
        })
    }

    /// Reopens a log to append to it: reads it and cuts a torn tail off the file. With `salvage`, a
    /// damaged log is rewritten with every record kept (atomically; the damaged file stays beside it
    /// as `frames.log.damaged`). `protocol` is written in a header that has to be rebuilt. Returns
    /// the writer and what was read.
    pub fn reopen(
        path: &Path,
        salvage: bool,
        protocol: Option<u16>,
    ) -> Result<(LogWriter, LogContents)> {
        let mut contents = LogReader::read(path, salvage)?;
        let io = |e| StoreError::io(format!("cannot repair {}", path.display()), e);
        let rewrite = contents
            .recovery
            .as_ref()
            .is_some_and(|r| r.salvaged_corruption || r.valid_bytes < contents.header.len());
        if rewrite {
            if contents.header.protocol.is_none() && contents.header.format >= 2 {
                contents.header.protocol = protocol;
            }
            if contents.records.is_empty() && contents.header.format == 1 {
                contents.header = LogHeader::current(protocol);
            }
            let mut bytes = contents.header.bytes();
            for r in &contents.records {
                frame_record(&mut bytes, r);
            }
            let tmp = PathBuf::from(format!("{}.tmp", path.display()));
            let mut f = File::create(&tmp).map_err(io)?;
            f.write_all(&bytes).and_then(|_| f.sync_all()).map_err(io)?;
            drop(f);
            if contents
                .recovery
                .as_ref()
                .is_some_and(|r| r.salvaged_corruption)
            {
                // Lose nothing: the damaged file stays beside the repaired one.
                let keep = free_name(path, "damaged");
                std::fs::copy(path, &keep).map_err(io)?;
                File::open(&keep).and_then(|f| f.sync_all()).map_err(io)?;
            }
            std::fs::rename(&tmp, path).map_err(io)?;
            sync_dir(path);
        }
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| {
                StoreError::io(format!("cannot open {} for appending", path.display()), e)
            })?;
        if let (false, Some(r)) = (rewrite, &contents.recovery) {
            file.set_len(r.valid_bytes).map_err(io)?;
            file.sync_all().map_err(io)?;
        }
        file.seek(SeekFrom::End(0)).map_err(io)?;
        let records = contents.records.len();
        Ok((
            LogWriter {
                file,
                path: path.to_owned(),
                records,
                buf: Vec::new(),
                header: contents.header,
            },
            contents,
        ))
    }

    /// Appends one record with a single write.
    pub fn append(&mut self, payload: &[u8]) -> Result<()> {
        if payload.is_empty() || payload.len() > MAX_RECORD as usize {
            return Err(StoreError::new(
                ErrorKind::Invalid,
                format!(
                    "record of {} bytes cannot be logged (1..={MAX_RECORD})",
                    payload.len()
                ),
            ));
        }
        self.buf.clear();
        frame_record(&mut self.buf, payload);
        self.file.write_all(&self.buf).map_err(|e| {
            StoreError::io(
                format!("cannot append to {} (disk full?)", self.path.display()),
                e,
            )
        })?;
        self.records += 1;
        Ok(())
    }

    /// Forces what was appended to disk (fsync).
    pub fn sync(&mut self) -> Result<()> {
        self.file
            .sync_data()
            .map_err(|e| StoreError::io(format!("cannot sync {}", self.path.display()), e))
    }

    /// Records in the log.
    pub fn records(&self) -> usize {
        self.records
    }

    /// The log's header (format, protocol of its frames).
    pub fn header(&self) -> LogHeader {
        self.header
    }

    /// The log's file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests;
