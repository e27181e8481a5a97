//! Damaged run folders: truncated and corrupt frame logs, missing metadata. Each gives either the
//! intact part with a note, or an error that says what is wrong and what to do.

mod host_common;

use host_common::*;
use std::path::{Path, PathBuf};
use tribo::link::session::pull_run;
use tribo_store::log::HEADER_LEN;
use tribo_store::{ErrorKind, Run};

/// Records one run from a fast virtual rig; returns the store, the run folder and the port (the
/// rig still holds the run).
fn recorded() -> (tempfile::TempDir, PathBuf, RigOnTcp) {
    let (port, _) = virtual_rig(0.02, 0.004, 6, 20.0);
    let store = tempfile::tempdir().unwrap();
    let o = record_plain_run(&port, store.path());
    assert_lossless(&o.run);
    let dir = o.run.dir().to_owned();
    (store, dir, port)
}

/// Byte offsets at which each log record starts, and the file's length.
fn record_starts(log: &Path) -> Vec<usize> {
    let b = std::fs::read(log).unwrap();
    let mut at = HEADER_LEN as usize;
    let mut v = vec![];
    while at < b.len() {
        v.push(at);
        at += 8 + u32::from_le_bytes(b[at..at + 4].try_into().unwrap()) as usize;
    }
    assert_eq!(at, b.len());
    v
}

/// Sample blocks among the first `n` records of a log (the others are the header and run events).
fn blocks_in_first(log: &[u8], starts: &[usize], n: usize) -> usize {
    starts[..n]
        .iter()
        .filter(|&&at| {
            let len = u32::from_le_bytes(log[at..at + 4].try_into().unwrap()) as usize;
            matches!(
                tribo_wire::frame::decode_one::<tribo_wire::DeviceMsg>(&log[at + 8..at + 8 + len])
                    .map(|f| f.msg),
                Ok(tribo_wire::DeviceMsg::Samples(_) | tribo_wire::DeviceMsg::Packed(_))
            )
        })
        .count()
}

fn total_blocks(log: &[u8], starts: &[usize]) -> usize {
    blocks_in_first(log, starts, starts.len())
}

#[test]
fn truncated_log_keeps_every_whole_frame_and_says_what_was_cut() {
    let (_store, dir, _port) = recorded();
    let log = dir.join("frames.log");
    let full = std::fs::read(&log).unwrap();
    let starts = record_starts(&log);
    let total = Run::open(&dir).unwrap().block_count();
    // Cut inside record 40 (a sample block): 40 records survive, the header being the first.
    let kept = blocks_in_first(&full, &starts, 40);
    assert!(kept > 20, "{kept}");
    let cut = starts[40] + 100;
    std::fs::write(&log, &full[..cut]).unwrap();
    let run = Run::open(&dir).expect("a truncated log opens");
    let rec = run.recovery.clone().expect("the cut is reported");
    assert_eq!(rec.records, 40);
    assert_eq!(rec.valid_bytes as usize, starts[40]);
    assert_eq!(rec.dropped_bytes, 100);
    assert!(rec.to_string().contains("torn last record"), "{rec}");
    assert_eq!(run.block_count(), kept);
    assert!(run.block_count() < total);
    assert!(!run.is_complete());
    // `tribo fit RUN` still reads it (the gap shows as a shorter record).
    let r = tribo::load_record(&dir).unwrap();
    assert_eq!(r.len(), kept * tribo_wire::BLOCK_LEN);

    // Truncated inside the file header: an empty run, not a crash; fit explains there is nothing.
    std::fs::write(&log, &full[..5]).unwrap();
    let run = Run::open(&dir).unwrap();
    assert_eq!(run.block_count(), 0);
    let e = tribo::exit::chain_text(&tribo::load_record(&dir).unwrap_err());
    assert!(e.contains("too short"), "{e}");
}

#[test]
fn corrupt_log_is_an_error_naming_the_place_and_the_remedy_and_pull_salvage_repairs_it() {
    let (store, dir, port) = recorded();
    let log = dir.join("frames.log");
    let mut bytes = std::fs::read(&log).unwrap();
    let starts = record_starts(&log);
    // A flipped bit in the payload of record 25.
    bytes[starts[25] + 8 + 40] ^= 0x04;
    std::fs::write(&log, &bytes).unwrap();

    let e = Run::open(&dir).unwrap_err();
    assert_eq!(e.kind, ErrorKind::Corrupt);
    assert!(
        e.msg.contains(&format!("byte {}", starts[25])) && e.msg.contains("record 25"),
        "{e}"
    );
    assert!(
        e.msg.contains("tribo pull") && e.msg.contains("--salvage"),
        "{e}"
    );
    // `tribo fit RUN` shows the same sentence.
    let fe = tribo::load_record(&dir).unwrap_err();
    // The run named, the store's own sentence as its source.
    assert!(matches!(fe, tribo::load::LoadError::Run { .. }), "{fe:?}");
    let fe = tribo::exit::chain_text(&fe);
    assert!(fe.contains("corrupt at byte"), "{fe}");
    // Salvaging keeps every intact record: all but the damaged one, before and after it.
    let run = Run::open_salvage(&dir).unwrap();
    let hit_is_block = blocks_in_first(&bytes, &starts, 26) > blocks_in_first(&bytes, &starts, 25);
    assert_eq!(
        run.block_count() + usize::from(hit_is_block),
        total_blocks(&bytes, &starts)
    );

    // `tribo pull --salvage RUN`: cut the damage, fetch the rest from the rig, whole again.
    let (mut link, info) = connect(&port);
    let o = pull_run(
        &mut link,
        &info,
        store.path(),
        Some(&dir),
        true,
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(o.run.dir(), dir);
    assert_lossless(&o.run);
    assert!(
        o.warnings.iter().any(|w| w.contains("salvaged")),
        "{:?}",
        o.warnings
    );
    assert!(Run::open(&dir).unwrap().recovery.is_none());
}

#[test]
fn wrong_or_missing_files_say_what_they_are() {
    let (_store, dir, _port) = recorded();
    let log = dir.join("frames.log");
    std::fs::write(&log, "t_s,x_m,v_m_s\n0,1,2\n").unwrap();
    let e = Run::open(&dir).unwrap_err();
    assert!(e.msg.contains("not a tribo frame log"), "{e}");

    std::fs::remove_file(dir.join("meta.toml")).unwrap();
    let e = Run::open(&dir).unwrap_err();
    assert_eq!(e.kind, ErrorKind::NotFound);
    assert!(
        e.msg.contains("meta.toml is missing") && e.msg.contains("run folder"),
        "{e}"
    );

    std::fs::write(dir.join("meta.toml"), "format = 1\nid = 3\n").unwrap();
    let e = Run::open(&dir).unwrap_err();
    assert!(e.msg.contains("meta.toml is damaged"), "{e}");
}
