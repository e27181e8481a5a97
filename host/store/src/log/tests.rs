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

/// Payloads that are wire frames (as in a real log): a few device messages.
fn frames() -> Vec<Vec<u8>> {
    (0..20u32)
        .map(|i| {
            tribo_wire::frame::encode_vec(
                i * 3 + 1,
                &tribo_wire::DeviceMsg::Ack { seq: i * 1000 + 7 },
            )
            .unwrap()
        })
        .collect()
}

fn write_log_of(path: &Path, p: &[Vec<u8>]) {
    let mut w = LogWriter::create(path, Some(2)).unwrap();
    for r in p {
        w.append(r).unwrap();
    }
    w.sync().unwrap();
}

fn write_log(path: &Path) -> Vec<Vec<u8>> {
    let p = payloads();
    write_log_of(path, &p);
    p
}

/// Byte offset of each record, and the end.
fn ends(p: &[Vec<u8>]) -> Vec<usize> {
    let mut e = vec![HEADER_LEN as usize];
    for r in p {
        e.push(e.last().unwrap() + 8 + r.len());
    }
    e
}

#[test]
fn round_trip() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = write_log(&path);
    let c = LogReader::read(&path, false).unwrap();
    assert_eq!(c.records, p);
    assert!(c.recovery.is_none());
    assert_eq!(c.header, LogHeader::current(Some(2)));
}

#[test]
fn the_header_is_pinned() {
    // The v2 header, byte for byte: a change of layout is a new format version.
    let h = LogHeader::current(Some(2)).bytes();
    let mut want = b"TRIBOLOG".to_vec();
    want.extend_from_slice(&[2, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0]);
    want.extend_from_slice(&crc32(&want).to_le_bytes());
    assert_eq!(h, want);
    assert_eq!(h.len() as u64, HEADER_LEN);
    let v1 = LogHeader {
        format: 1,
        protocol: None,
    };
    assert_eq!(v1.bytes(), b"TRIBOLOG\x01\0\0\0\0\0\0\0");
    assert_eq!(v1.bytes().len() as u64, HEADER_LEN_V1);
}

#[test]
fn every_truncation_keeps_the_intact_prefix() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = write_log(&path);
    let full = std::fs::read(&path).unwrap();
    let ends = ends(&p);
    for cut in 0..full.len() {
        let c = parse(&full[..cut], &path, false).unwrap_or_else(|e| panic!("cut {cut}: {e}"));
        let whole = ends.iter().filter(|&&e| e <= cut).count().saturating_sub(1);
        assert_eq!(c.records, p[..whole], "cut at {cut}");
        assert_eq!(
            c.recovery.is_some(),
            !ends.contains(&cut) && cut != 0,
            "cut at {cut}"
        );
        // Salvage finds nothing more in a torn tail of plain payloads.
        let s = parse(&full[..cut], &path, true).unwrap();
        assert_eq!(s.records, c.records, "cut at {cut}");
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
    let (mut w, c) = LogWriter::reopen(&path, false, None).unwrap();
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
    assert_eq!(c.header.protocol, Some(2), "the header is kept");
}

#[test]
fn corruption_in_the_middle_is_an_error_unless_salvaged_and_salvage_keeps_what_follows() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = write_log(&path);
    let mut bytes = std::fs::read(&path).unwrap();
    // Flip a bit inside record 5's payload.
    let at = ends(&p)[5] + 8 + 3;
    bytes[at] ^= 0x10;
    std::fs::write(&path, &bytes).unwrap();
    let e = LogReader::read(&path, false).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Corrupt);
    assert!(
        e.msg.contains("record 5")
            && e.msg.contains("tribo pull")
            && e.msg.contains(&format!("from byte {}", ends(&p)[6])),
        "{e}"
    );
    let c = LogReader::read(&path, true).unwrap();
    let mut want = p.clone();
    want.remove(5);
    assert_eq!(c.records, want, "every record but the damaged one");
    let r = c.recovery.unwrap();
    assert!(r.salvaged_corruption);
    assert_eq!(
        r.damage,
        vec![Damage {
            at: ends(&p)[5] as u64,
            len: (8 + p[5].len()) as u64,
            after_record: 5,
            rescued: 0
        }]
    );
    assert_eq!(r.dropped_bytes, (8 + p[5].len()) as u64);
    assert!(r.to_string().contains("salvaged 19 intact records"), "{r}");
}

#[test]
fn a_flipped_byte_anywhere_costs_at_most_the_record_it_hits() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = write_log(&path);
    let full = std::fs::read(&path).unwrap();
    let ends = ends(&p);
    for at in 0..full.len() {
        for flip in [0x01u8, 0x80, 0xff] {
            let mut b = full.clone();
            b[at] ^= flip;
            let c = parse(&b, &path, true).unwrap_or_else(|e| panic!("byte {at}: {e}"));
            // The record holding the byte (none in the file header).
            let hit = ends.iter().rposition(|&e| e <= at).filter(|&i| i < p.len());
            let want: Vec<Vec<u8>> = match hit {
                Some(i) if at >= ends[0] => {
                    let mut w = p.clone();
                    w.remove(i);
                    w
                }
                _ => p.clone(),
            };
            // A flip in a length can make a record whose CRC still fails run into the next
            // one; nothing is ever invented, and nothing but the hit record is lost.
            assert_eq!(c.records, want, "byte {at} ^ {flip:#x}");
            assert!(c.recovery.is_some(), "byte {at}: reported");
        }
    }
}

#[test]
fn salvage_rescues_a_wire_frame_whose_record_header_was_hit() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = frames();
    write_log_of(&path, &p);
    let full = std::fs::read(&path).unwrap();
    let ends = ends(&p);
    // Every byte of record 7's length and checksum fields: the frame inside is whole.
    for k in 0..8 {
        let mut b = full.clone();
        b[ends[7] + k] ^= 0x5a;
        let c = parse(&b, &path, true).unwrap();
        assert_eq!(c.records, p, "byte {k} of the record header");
        let r = c.recovery.unwrap();
        assert_eq!(r.rescued(), 1, "byte {k}");
        assert!(r.to_string().contains("1 frames were whole"), "{r}");
    }
    // A hit in the frame itself: its own CRC fails too, so it is dropped, the rest kept.
    let mut b = full.clone();
    b[ends[7] + 10] ^= 0x5a;
    let c = parse(&b, &path, true).unwrap();
    assert_eq!(c.records.len(), 19);
    assert!(!c.records.contains(&p[7]));
    // The last record's checksum hit: rescued too, not cut as a torn tail.
    let mut b = full.clone();
    b[ends[19] + 5] ^= 0x5a;
    assert_eq!(parse(&b, &path, true).unwrap().records, p);
    assert_eq!(parse(&b, &path, false).unwrap().records, p[..19]);
}

#[test]
fn a_damaged_stretch_is_skipped_and_the_records_after_it_kept() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = write_log(&path);
    let mut b = std::fs::read(&path).unwrap();
    let ends = ends(&p);
    // 300 bytes of garbage from the middle of record 3 (over records 3..=k).
    for (i, x) in b[ends[3] + 20..ends[3] + 320].iter_mut().enumerate() {
        *x = (i as u8).wrapping_mul(37).wrapping_add(11);
    }
    let c = parse(&b, &path, true).unwrap();
    let last_hit = ends.iter().rposition(|&e| e < ends[3] + 320).unwrap();
    let want: Vec<Vec<u8>> = p[..3].iter().chain(&p[last_hit + 1..]).cloned().collect();
    assert_eq!(c.records, want);
    let r = c.recovery.unwrap();
    assert_eq!(r.damage.len(), 1);
    assert_eq!(r.damage[0].at, ends[3] as u64);
    assert_eq!(r.damage[0].len as usize, ends[last_hit + 1] - ends[3]);
}

#[test]
fn reopen_with_salvage_rewrites_the_log_and_keeps_the_damaged_file() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = write_log(&path);
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[ends(&p)[9] + 12] ^= 0x40;
    std::fs::write(&path, &bytes).unwrap();
    assert!(LogWriter::reopen(&path, false, None).is_err());
    assert_eq!(std::fs::read(&path).unwrap(), bytes, "nothing touched");
    let (mut w, c) = LogWriter::reopen(&path, true, None).unwrap();
    assert_eq!(c.records.len(), 19);
    w.append(b"after").unwrap();
    drop(w);
    let back = LogReader::read(&path, false).unwrap();
    assert!(back.recovery.is_none(), "clean after the repair");
    assert_eq!(back.records.len(), 20);
    assert_eq!(back.records[..9], p[..9]);
    assert_eq!(back.records[9..19], p[10..]);
    let kept = d.path().join("frames.log.damaged");
    assert_eq!(
        std::fs::read(&kept).unwrap(),
        bytes,
        "the damaged file is kept"
    );
    // A second repair does not overwrite the first copy.
    let mut again = std::fs::read(&path).unwrap();
    again[HEADER_LEN as usize + 9] ^= 1;
    std::fs::write(&path, &again).unwrap();
    LogWriter::reopen(&path, true, None).unwrap();
    assert!(d.path().join("frames.log.damaged-2").is_file());
    assert_eq!(std::fs::read(&kept).unwrap(), bytes);
}

#[test]
fn a_damaged_file_header_says_so_and_salvage_keeps_every_record() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = write_log(&path);
    let full = std::fs::read(&path).unwrap();
    for at in [0usize, 3, 8, 12, 16, 20] {
        let mut b = full.clone();
        b[at] ^= 0x21;
        std::fs::write(&path, &b).unwrap();
        let e = LogReader::read(&path, false).unwrap_err();
        assert!(e.msg.contains("--salvage"), "byte {at}: {e}");
        let c = LogReader::read(&path, true).unwrap();
        assert_eq!(c.records, p, "byte {at}");
        assert!(c.recovery.unwrap().header_damaged);
        let (_, c) = LogWriter::reopen(&path, true, Some(2)).unwrap();
        assert_eq!(c.records, p);
        let back = LogReader::read(&path, false).unwrap();
        assert_eq!(back.records, p);
        assert_eq!(back.header, LogHeader::current(Some(2)), "rebuilt");
    }
}

#[test]
fn v1_logs_read_and_append_in_their_own_format() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    let p = payloads();
    let v1 = LogHeader {
        format: 1,
        protocol: None,
    };
    let mut b = v1.bytes();
    for r in &p[..5] {
        frame_record(&mut b, r);
    }
    std::fs::write(&path, &b).unwrap();
    let c = LogReader::read(&path, false).unwrap();
    assert_eq!(c.header, v1);
    assert_eq!(c.records, p[..5]);
    let (mut w, _) = LogWriter::reopen(&path, false, Some(2)).unwrap();
    w.append(&p[5]).unwrap();
    drop(w);
    let c = LogReader::read(&path, false).unwrap();
    assert_eq!((c.header, c.records.len()), (v1, 6));
}

#[test]
fn wrong_files_and_newer_formats_are_refused_clearly() {
    let d = tempfile::tempdir().unwrap();
    let path = d.path().join("frames.log");
    std::fs::write(&path, b"t_s,x_m,v_m_s\n0,0,0\n").unwrap();
    let e = LogReader::read(&path, false).unwrap_err();
    assert!(e.msg.contains("not a tribo frame log"), "{e}");
    assert!(LogReader::read(&path, true).is_err(), "nothing to salvage");
    for v in [3u32, 9] {
        let mut b = LogHeader {
            format: v,
            protocol: Some(3),
        }
        .bytes();
        frame_record(&mut b, b"payload");
        std::fs::write(&path, &b).unwrap();
        for salvage in [false, true] {
            let e = LogReader::read(&path, salvage).unwrap_err();
            assert!(
                e.msg.contains(&format!("format v{v} is newer")) && e.msg.contains("update tribo"),
                "{e}"
            );
        }
    }
}
