//! The archive: run folders written by earlier versions of tribo stay readable, sample for sample.
//!
//! `fixtures/v1-run` is a run folder written by tribo at commit 9c9b111 (frame log format v1,
//! protocol v1 frames: unpacked `Samples` blocks, a run header without a sample clock), made with
//! `tribo demo --mu0 0.08 --mu1 0.004 --seed 7 --speed inf --no-report` there. The sample values
//! pinned below are the ones that version exported to its `samples.csv`.

use std::path::{Path, PathBuf};
use tribo_store::log::{LogHeader, LogReader, LogWriter};
use tribo_store::{Filter, Run, RunCatalog, RunStatus};
use tribo_wire::crc32::crc32;
use tribo_wire::{DeviceMsg, SampleClock};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// A copy of a fixture run in a store of its own (reading must not need to write, but a test must
/// never risk the checked-in bytes).
fn copy_of(name: &str) -> (tempfile::TempDir, PathBuf) {
    let store = tempfile::tempdir().unwrap();
    let dir = store.path().join(name);
    std::fs::create_dir(&dir).unwrap();
    for f in std::fs::read_dir(fixture(name)).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, dir.join(f.file_name().unwrap())).unwrap();
    }
    (store, dir)
}

#[test]
fn the_v1_fixture_is_the_one_checked_in() {
    let b = std::fs::read(fixture("v1-run/frames.log")).unwrap();
    assert_eq!((b.len(), crc32(&b)), (33_366, 0x05bf_92be));
    assert_eq!(&b[..16], b"TRIBOLOG\x01\0\0\0\0\0\0\0", "format v1 header");
}

#[test]
fn a_v1_run_folder_reads_whole_with_the_samples_v1_exported() {
    let (_store, dir) = copy_of("v1-run");
    let log = LogReader::read(&dir.join("frames.log"), false).unwrap();
    assert_eq!(
        log.header,
        LogHeader {
            format: 1,
            protocol: None
        }
    );
    assert_eq!(log.records.len(), 52, "header, 49 blocks, result, end");
    assert!(log.recovery.is_none());

    let run = Run::open(&dir).unwrap();
    assert_eq!(run.undecodable_records(), 0);
    let c = run.completeness();
    assert!(c.is_complete(), "{}", c.summary());
    assert_eq!(c.summary(), "complete: 49 of 49 blocks");
    assert_eq!(run.meta.status, RunStatus::Complete);
    assert_eq!(run.meta.device.as_ref().unwrap().protocol, 1);
    let h = run.header().unwrap();
    assert_eq!(h.run_id, 1);
    assert_eq!(
        run.clock(),
        SampleClock::exact(10_000),
        "v1: the configured rate"
    );
    let end = run.end().unwrap();
    assert_eq!((end.blocks, end.samples), (49, 3122));
    assert_eq!(run.result().unwrap().best.mu0, 0.080_003_925);
    // Every record is one of the run's frames, in the order the rig sent them.
    let frames: Vec<&[u8]> = run.frames();
    assert_eq!(frames.len(), 52);
    assert!(frames.iter().zip(&log.records).all(|(a, b)| *a == &b[..]));

    // The samples, as tribo v1 exported them (t, x, v, force, temperature).
    let s = run.samples_si().unwrap();
    assert_eq!(s.len(), 3122);
    let rows: [(usize, [f64; 5]); 3] = [
        (
            0,
            [
                0.0,
                6.668701535090804e-4,
                -1.9073486328125e-3,
                -9.1552734375e-5,
                2.2015380859375e1,
            ],
        ),
        (
            995,
            [
                9.95e-2,
                -1.796264696167782e-4,
                6.49261474609375e-2,
                2.50244140625e-2,
                2.2039794921875e1,
            ],
        ),
        (
            3121,
            [
                3.121e-1,
                -1.5869140952418093e-6,
                7.62939453125e-6,
                1.678466796875e-3,
                2.193603515625e1,
            ],
        ),
    ];
    for (i, want) in rows {
        assert!((s.t[i] - want[0]).abs() < 1e-12, "t[{i}] = {}", s.t[i]);
        let got = [
            s.x[i],
            s.v[i],
            s.force.as_ref().unwrap()[i],
            s.temp_c.as_ref().unwrap()[i],
        ];
        assert_eq!(got, want[1..], "sample {i}");
    }
    assert_eq!(
        s.ecr_range, None,
        "v1 firmware reported no ECR range changes"
    );

    // The catalog re-index lists it complete.
    let cat = RunCatalog::open(dir.parent().unwrap()).unwrap();
    let r = cat.reindex().unwrap();
    assert_eq!((r.indexed, r.unreadable.len()), (1, 0));
    let rows = cat.list(&Filter::default()).unwrap();
    assert_eq!(rows[0].status, "complete");
    assert_eq!(rows[0].samples, 3122);
}

#[test]
fn the_log_s_recorded_protocol_picks_the_decoder() {
    let (_store, dir) = copy_of("v1-run");
    let records = LogReader::read(&dir.join("frames.log"), false)
        .unwrap()
        .records;
    let want = Run::open(&dir).unwrap().samples_si().unwrap();
    // The same frames in a v2 log that says the rig spoke protocol 1: read the same.
    let log = dir.join("frames.log");
    std::fs::remove_file(&log).unwrap();
    let mut w = LogWriter::create(&log, Some(1)).unwrap();
    for r in &records {
        w.append(r).unwrap();
    }
    drop(w);
    let run = Run::open(&dir).unwrap();
    assert_eq!(run.log_header().protocol, Some(1));
    assert!(run.is_complete());
    // (Compared as text: the ECR column holds NaN where a block had no reading.)
    let same = format!("{:?}", run.samples_si().unwrap()) == format!("{want:?}");
    assert!(same, "the same samples");
    // A log that says protocol 2 is not guessed at: the v1 header is not a v2 frame.
    std::fs::remove_file(&log).unwrap();
    let mut w = LogWriter::create(&log, Some(2)).unwrap();
    for r in &records {
        w.append(r).unwrap();
    }
    drop(w);
    let run = Run::open(&dir).unwrap();
    assert_eq!(run.undecodable_records(), 1);
    assert!(run.header().is_none());
    assert!(!run.is_complete());
    assert!(
        run.completeness().summary().contains("no run header"),
        "{}",
        run.completeness().summary()
    );
    // The v1 header frame decodes as v1 only, with the configured rate as its clock.
    let f = tribo_wire::v1::decode(&records[0]).unwrap();
    assert!(matches!(f.msg, DeviceMsg::RunStarted(h) if h.clock == SampleClock::exact(10_000)));
}

/// `fixtures/v2-run`: written by this version (frame log format v2, protocol v2: packed blocks, a
/// run header with its sample clock, ECR range change frames), made with `tribo demo --mu0 0.08
/// --mu1 0.004 --seed 7 --speed inf --no-report`; pinned so that a later change of the format or
/// of the frames cannot pass unnoticed.
#[test]
fn the_v2_fixture_reads_whole_with_the_samples_it_was_made_with() {
    let b = std::fs::read(fixture("v2-run/frames.log")).unwrap();
    assert_eq!((b.len(), crc32(&b)), (9_719, 0xf9b0_6733));
    let (_store, dir) = copy_of("v2-run");
    let log = LogReader::read(&dir.join("frames.log"), false).unwrap();
    assert_eq!(log.header, LogHeader::current(Some(2)));
    let run = Run::open(&dir).unwrap();
    let c = run.completeness();
    assert!(c.is_complete(), "{}", c.summary());
    assert_eq!(run.undecodable_records(), 0);
    let kinds = |f: &&[u8]| match tribo_wire::frame::decode_one::<DeviceMsg>(f).unwrap().msg {
        DeviceMsg::Packed(_) => 'b',
        DeviceMsg::EcrRange(_) => 'e',
        DeviceMsg::RunStarted(_) => 'h',
        DeviceMsg::Result(_) => 'r',
        DeviceMsg::RunEnded(_) => 'z',
        _ => '?',
    };
    // The frames in the rig's order: header, ECR range changes among the packed blocks, result, end.
    let shape: String = run.frames().iter().map(kinds).collect();
    assert_eq!(
        shape,
        format!("he{}e{}e{}rz", "b".repeat(4), "b".repeat(40), "b".repeat(5))
    );
    assert_eq!(c.summary(), "complete: 49 of 49 blocks");
    assert_eq!(run.ecr_changes().count(), 3);
    let s = run.samples_si().unwrap();
    let rows: [(usize, [f64; 5]); 3] = [
        (
            0,
            [
                0.0,
                6.669311551377177e-4,
                -1.85394287109375e-3,
                -3.0517578125e-4,
                2.1990966796875e1,
            ],
        ),
        (
            995,
            [
                9.95e-2,
                -1.796264696167782e-4,
                6.491851806640625e-2,
                2.4932861328125e-2,
                2.19146728515625e1,
            ],
        ),
        (
            3119,
            [
                3.119e-1,
                -1.5258789289873675e-6,
                -3.814697265625e-5,
                1.739501953125e-3,
                2.196044921875e1,
            ],
        ),
    ];
    assert_eq!(s.len(), 3120);
    for (i, want) in rows {
        assert!((s.t[i] - want[0]).abs() < 1e-12, "t[{i}] = {}", s.t[i]);
        let got = [
            s.x[i],
            s.v[i],
            s.force.as_ref().unwrap()[i],
            s.temp_c.as_ref().unwrap()[i],
        ];
        assert_eq!(got, want[1..], "sample {i}");
    }
}
