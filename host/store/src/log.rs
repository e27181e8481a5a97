//! The append-only, crash-safe frame log (`frames.log`).
//!
//! Layout: a 16-byte header (`TRIBOLOG`, format version u32 LE, flags u32 LE = 0), then records
//! `len: u32 LE ‖ crc32(payload): u32 LE ‖ payload`. A payload is one wire frame exactly as the rig
//! sent it (COBS-stuffed, closing zero included), so the log can be replayed byte for byte.
//!
//! Crash safety: each record is written with a single `write_all` on an unbuffered file opened for
//! appending, so a killed process leaves at most one torn record at the end; a pulled cable leaves
//! the log as it was. [`LogWriter::sync`] (fsync) is called by the run writer after the run header,
//! then at most every second, and at the end, bounding what a power cut can take.
//!
//! Reading tells a torn tail (the last record runs past the end of the file or fails its CRC with
//! nothing after it: the normal trace of an interrupted write, cut off and reported as a
//! [`Recovery`]) from corruption (a bad record followed by more data: an error, unless salvaging).

use crate::{ErrorKind, Result, StoreError};
use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use tribo_wire::crc32::crc32;

pub const MAGIC: &[u8; 8] = b"TRIBOLOG";
pub const FORMAT_VERSION: u32 = 1;
pub const HEADER_LEN: u64 = 16;
/// Largest payload accepted (a wire frame is at most ~1.1 kB).
pub const MAX_RECORD: u32 = 64 * 1024;

/// What was cut off the end of a log when it was read or reopened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recovery {
    /// Intact records kept.
    pub records: usize,
    /// Length of the intact prefix, bytes.
    pub valid_bytes: u64,
    /// Bytes dropped after it.
    pub dropped_bytes: u64,
    /// True when the dropped part was not a torn tail but corruption (salvage mode only).
    pub salvaged_corruption: bool,
}

impl std::fmt::Display for Recovery {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.salvaged_corruption {
            write!(
                f,
                "salvaged the first {} records ({} bytes); dropped {} corrupt bytes after them",
                self.records, self.valid_bytes, self.dropped_bytes
            )
        } else {
            write!(
                f,
                "dropped a torn last record ({} bytes after byte {}): the writer was stopped mid-write; \
                 the {} records before it are intact",
                self.dropped_bytes, self.valid_bytes, self.records
            )
        }
    }
}

/// The records of a log and what, if anything, had to be cut off.
#[derive(Debug, Clone, Default)]
pub struct LogContents {
    pub records: Vec<Vec<u8>>,
    pub recovery: Option<Recovery>,
}

/// Reads frame logs.
pub struct LogReader;

impl LogReader {
    /// Reads the log at `path`. A torn tail is dropped and reported in
    /// [`LogContents::recovery`]; corruption before the end is an error unless `salvage`, in which
    /// case the intact prefix is returned.
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

/// Parses a whole log held in memory.
pub fn parse(bytes: &[u8], path: &Path, salvage: bool) -> Result<LogContents> {
    let hl = HEADER_LEN as usize;
    if bytes.len() < hl {
        if MAGIC.starts_with(&bytes[..bytes.len().min(8)]) {
            // Killed before the header was complete: an empty run.
            return Ok(LogContents {
                records: vec![],
                recovery: (!bytes.is_empty()).then_some(Recovery {
                    records: 0,
                    valid_bytes: 0,
                    dropped_bytes: bytes.len() as u64,
                    salvaged_corruption: false,
                }),
            });
        }
        return Err(corrupt(
            path,
            "not a tribo frame log (bad magic); is this the right file?".into(),
        ));
    }
    if &bytes[..8] != MAGIC {
        return Err(corrupt(
            path,
            "not a tribo frame log (bad magic); is this the right file?".into(),
        ));
    }
    let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    if version != FORMAT_VERSION {
        return Err(corrupt(
            path,
            format!(
                "frame log format v{version}, this tribo reads v{FORMAT_VERSION}: use the tribo version that \
                 wrote it"
            ),
        ));
    }
    let mut records = Vec::new();
    let mut at = hl;
    while at < bytes.len() {
        let rest = &bytes[at..];
        let bad = |why: &str, tail: bool| -> Result<LogContents> {
            let rec = Recovery {
                records: records.len(),
                valid_bytes: at as u64,
                dropped_bytes: (bytes.len() - at) as u64,
                salvaged_corruption: !tail,
            };
            if tail || salvage {
                Ok(LogContents {
                    records: records.clone(),
                    recovery: Some(rec),
                })
            } else {
                Err(corrupt(
                    path,
                    format!(
                        "corrupt at byte {at} (record {}): {why}, and {} more bytes follow, so this is \
                         damage, not an interrupted write. The {} records before it are intact: re-fetch the \
                         run with `tribo pull` if the rig still holds it, or keep the intact part with \
                         `tribo pull --salvage`",
                        records.len(),
                        rest.len(),
                        records.len()
                    ),
                ))
            }
        };
        if rest.len() < 8 {
            return bad("incomplete record header", true);
        }
        let len = u32::from_le_bytes([rest[0], rest[1], rest[2], rest[3]]);
        let crc = u32::from_le_bytes([rest[4], rest[5], rest[6], rest[7]]);
        if len == 0 || len > MAX_RECORD {
            // A garbage length: torn only if nothing plausible could follow.
            return bad(
                &format!("impossible record length {len}"),
                rest.len() <= 8 + MAX_RECORD as usize && len > rest.len() as u32,
            );
        }
        let end = 8 + len as usize;
        if end > rest.len() {
            return bad("record runs past the end of the file", true);
        }
        let payload = &rest[8..end];
        if crc32(payload) != crc {
            return bad("record checksum mismatch", end == rest.len());
        }
        records.push(payload.to_vec());
        at += end;
    }
    Ok(LogContents {
        records,
        recovery: None,
    })
}

/// Appends records to a log.
pub struct LogWriter {
    file: File,
    path: PathBuf,
    records: usize,
    buf: Vec<u8>,
}

impl LogWriter {
    /// Creates a new, empty log (fails if the file exists) and makes it durable.
    pub fn create(path: &Path) -> Result<LogWriter> {
        let mut file = OpenOptions::new()
            .create_new(true)
            .append(true)
            .open(path)
            .map_err(|e| StoreError::io(format!("cannot create {}", path.display()), e))?;
        let mut header = Vec::with_capacity(HEADER_LEN as usize);
        header.extend_from_slice(MAGIC);
        header.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        header.extend_from_slice(&0u32.to_le_bytes());
        file.write_all(&header)
            .and_then(|_| file.sync_all())
            .map_err(|e| StoreError::io(format!("cannot write {}", path.display()), e))?;
        if let Some(dir) = path.parent() {
            // Make the new directory entry durable too (best effort: not every FS supports it).
            let _ = File::open(dir).and_then(|d| d.sync_all());
        }
        Ok(LogWriter {
            file,
            path: path.to_owned(),
            records: 0,
            buf: Vec::new(),
        })
    }

    /// Reopens a log to append to it: reads it, cuts a torn tail (or, with `salvage`, everything
    /// after the first bad record) off the file, and returns the intact records.
    pub fn reopen(path: &Path, salvage: bool) -> Result<(LogWriter, LogContents)> {
        let contents = LogReader::read(path, salvage)?;
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| {
                StoreError::io(format!("cannot open {} for appending", path.display()), e)
            })?;
        let io = |e| StoreError::io(format!("cannot repair {}", path.display()), e);
        if let Some(r) = &contents.recovery {
            if r.valid_bytes < HEADER_LEN {
                file.set_len(0).map_err(io)?;
                file.seek(SeekFrom::Start(0)).map_err(io)?;
                let mut header = Vec::new();
                header.extend_from_slice(MAGIC);
                header.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
                header.extend_from_slice(&0u32.to_le_bytes());
                file.write_all(&header).map_err(io)?;
            } else {
                file.set_len(r.valid_bytes).map_err(io)?;
            }
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
        self.buf
            .extend_from_slice(&(payload.len() as u32).to_le_bytes());
        self.buf.extend_from_slice(&crc32(payload).to_le_bytes());
        self.buf.extend_from_slice(payload);
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

    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn payloads() -> Vec<Vec<u8>> {
        (1..=20u8)
            .map(|i| {
                (0..(i as usize * 7))
                    .map(|j| (j as u8).wrapping_mul(i) | 1)
                    .collect()
            })
            .collect()
    }

    fn write_log(path: &Path) -> Vec<Vec<u8>> {
        let mut w = LogWriter::create(path).unwrap();
        let p = payloads();
        for r in &p {
            w.append(r).unwrap();
        }
        w.sync().unwrap();
        p
    }

    #[test]
    fn round_trip() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("frames.log");
        let p = write_log(&path);
        let c = LogReader::read(&path, false).unwrap();
        assert_eq!(c.records, p);
        assert!(c.recovery.is_none());
    }

    #[test]
    fn every_truncation_keeps_the_intact_prefix() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("frames.log");
        let p = write_log(&path);
        let full = std::fs::read(&path).unwrap();
        // Record boundaries.
        let mut ends = vec![HEADER_LEN as usize];
        for r in &p {
            ends.push(ends.last().unwrap() + 8 + r.len());
        }
        for cut in 0..full.len() {
            let c = parse(&full[..cut], &path, false).unwrap_or_else(|e| panic!("cut {cut}: {e}"));
            let whole = ends.iter().filter(|&&e| e <= cut).count().saturating_sub(1);
            assert_eq!(c.records, p[..whole], "cut at {cut}");
            assert_eq!(
                c.recovery.is_some(),
                !ends.contains(&cut) && cut != 0,
                "cut at {cut}"
            );
        }
    }

    #[test]
    fn reopen_cuts_torn_tail_and_appends_after_it() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("frames.log");
        let p = write_log(&path);
        let len = std::fs::metadata(&path).unwrap().len();
        // Tear the last record in half.
        let f = OpenOptions::new().write(true).open(&path).unwrap();
        f.set_len(len - (p[19].len() as u64) / 2).unwrap();
        drop(f);
        let (mut w, c) = LogWriter::reopen(&path, false).unwrap();
        assert_eq!(c.records, p[..19]);
        let r = c.recovery.unwrap();
        assert_eq!(r.records, 19);
        assert!(!r.salvaged_corruption);
        w.append(b"after").unwrap();
        drop(w);
        let c = LogReader::read(&path, false).unwrap();
        assert!(c.recovery.is_none());
        assert_eq!(c.records.len(), 20);
        assert_eq!(c.records[19], b"after");
    }

    #[test]
    fn corruption_in_the_middle_is_an_error_unless_salvaged() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("frames.log");
        let p = write_log(&path);
        let mut bytes = std::fs::read(&path).unwrap();
        // Flip a bit inside record 5's payload.
        let at = HEADER_LEN as usize + p[..5].iter().map(|r| 8 + r.len()).sum::<usize>() + 8 + 3;
        bytes[at] ^= 0x10;
        std::fs::write(&path, &bytes).unwrap();
        let e = LogReader::read(&path, false).unwrap_err();
        assert_eq!(e.kind, ErrorKind::Corrupt);
        assert!(
            e.msg.contains("record 5") && e.msg.contains("tribo pull"),
            "{e}"
        );
        let c = LogReader::read(&path, true).unwrap();
        assert_eq!(c.records, p[..5]);
        assert!(c.recovery.unwrap().salvaged_corruption);
    }

    #[test]
    fn wrong_files_are_refused_clearly() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("frames.log");
        std::fs::write(&path, b"t_s,x_m,v_m_s\n0,0,0\n").unwrap();
        let e = LogReader::read(&path, false).unwrap_err();
        assert!(e.msg.contains("not a tribo frame log"), "{e}");
        let mut b = MAGIC.to_vec();
        b.extend_from_slice(&9u32.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        std::fs::write(&path, &b).unwrap();
        assert!(LogReader::read(&path, false)
            .unwrap_err()
            .msg
            .contains("format v9"));
    }
}
