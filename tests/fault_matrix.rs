//! The fault-injection matrix of whole runs: every row damages a run somewhere between the rig and
//! the disk, then asserts that the stored run is bit-identical to the run the rig produced (its own
//! copy, pulled over a clean line: the same frames, byte for byte, each logged once), or, where
//! the rig itself no longer holds part of it, that the stored run says exactly what is missing and
//! why, and the command's outcome is "incomplete" (exit status 3).
//!
//! | row | fault | expected |
//! |---|---|---|
//! | `flipped_bytes_at_start_middle_and_end_of_a_log` | one byte of the frame log flipped: file header, run header, a block, a record header, the end | salvage keeps every intact record, the pull fetches only what the flip cost; bit-identical |
//! | `killed_before_the_header_was_logged` | the recorder killed after the folder and its metadata were written, before the run header reached the log | `tribo pull` finds the folder by the rig's run id and fills it; bit-identical |
//! | `truncated_log` | the log cut in the middle of a record | shown incomplete (N of at least N blocks); the pull fetches the tail; bit-identical |
//! | `cable_pulled_mid_stream` | the line cut a third into the run, the run going on | `run` ends incomplete (exit 3); the pull fetches the rest; bit-identical |
//! | `lossy_link` | 1 % (and 5 %) of the frames each way dropped or corrupted | stored whole by `run` itself; bit-identical |
//! | `lost_header_events_result_and_end` | the run header, an acquisition gap, the result and the end lost live | all fetched again; bit-identical; the gap stays a gap |
//! | `power_cut_after_the_run` | the rig power-cycled after a run taken with the cable out | pulled from the rig's flash; bit-identical to before the cut |
//! | `power_cut_during_the_run` | the rig power-cycled mid-run | stored as far as the rig's flash kept it; "restarted during the run"; exit 3 |
//! | `a_run_longer_than_the_rig_keeps` | 60 s at 20 kS/s × 5 channels: the rig loses the middle | the blocks the rig holds, bit-identical; exactly the others missing, "no longer holds"; exit 3 |
//! | `a_rig_that_stops_hearing_is_not_said_to_have_lost_the_blocks` | blocks lost live, then the rig hears no more pulls | `run` exits 3 saying the rig may still hold them; a later pull completes the run |
//! | `events_an_older_host_did_not_store_are_fetched_into_the_same_run` | a stored run without its gap and ECR frames | recognised as the rig's run, events fetched; bit-identical |
//!
//! The host `kill -9` row runs the real `tribo` binary: `host/tests/crash.rs`.

mod faulty_line;
mod host_common;

use faulty_line::{Bench, Faults, LineStats};
use host_common::plan;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use tribo::link::session::{pull_run, record_run, Outcome};
use tribo::link::Link;
use tribo_rig::{AcquisitionFaults, VirtualRig, VirtualRigConfig};
use tribo_store::log::{LogReader, HEADER_LEN};
use tribo_store::Run;
use tribo_wire::frame::decode_one;
use tribo_wire::{Configure, DeviceMsg, HostMsg};

fn rig(mu0: f64, seed: u64) -> VirtualRig {
    VirtualRig::new(VirtualRigConfig {
        law: tribo_physics::FrictionLaw::coulomb_viscous(mu0, 0.004),
        seed,
        ..Default::default()
    })
    .unwrap()
}

/// Takes a run of [`plan`] through a line with `faults`.
fn record(bench: &mut Bench, faults: Faults, store: &Path) -> anyhow::Result<Outcome> {
    record_seen(bench, faults, store).0
}

/// [`record`], with what the line saw.
fn record_seen(
    bench: &mut Bench,
    faults: Faults,
    store: &Path,
) -> (anyhow::Result<Outcome>, Arc<LineStats>) {
    bench.session(faults, |link| {
        let info = link.hello()?;
        record_run(
            link,
            &info,
            store,
            &plan(),
            &AtomicBool::new(false),
            &mut |_| {},
        )
    })
}

/// `tribo pull [target]` (with `--salvage`) through a line with `faults`.
fn pull(
    bench: &mut Bench,
    faults: Faults,
    store: &Path,
    target: Option<&Path>,
    salvage: bool,
) -> Outcome {
    bench
        .session(faults, |link: &mut Link| {
            let info = link.hello()?;
            pull_run(link, &info, store, target, salvage, &mut |_| {})
        })
        .0
        .expect("the pull finishes")
}

/// The message of a frame.
fn msg(raw: &[u8]) -> DeviceMsg {
    decode_one::<DeviceMsg>(raw).expect("a rig frame").msg
}

fn block_of(raw: &[u8]) -> Option<u32> {
    match msg(raw) {
        DeviceMsg::Packed(p) => Some(p.block),
        DeviceMsg::Samples(b) => Some(b.block),
        _ => None,
    }
}

/// The stored run is the rig's, bit for bit: complete, the very frames in the rig's order, and
/// its log holds each of them once and nothing else.
fn assert_bit_identical(run: &Run, rig: &[Vec<u8>]) {
    let c = run.completeness();
    assert!(c.is_complete(), "{}", c.summary());
    assert!(c
        .summary()
        .starts_with(&format!("complete: {0} of {0} blocks", c.blocks_held)));
    let got = run.frames();
    assert_eq!(got.len(), rig.len(), "frames stored vs the rig's");
    for (i, (a, b)) in got.iter().zip(rig).enumerate() {
        assert!(*a == &b[..], "frame {i} differs from the rig's");
    }
    let mut log = LogReader::read(&run.dir().join("frames.log"), false)
        .unwrap()
        .records;
    log.sort();
    let mut want = rig.to_vec();
    want.sort();
    assert!(log == want, "the log holds each frame of the run once");
}

/// Copies a run folder into a store of its own.
fn copy_run(from: &Path, store: &Path) -> PathBuf {
    let to = store.join(from.file_name().unwrap());
    std::fs::create_dir_all(&to).unwrap();
    for f in std::fs::read_dir(from).unwrap() {
        let f = f.unwrap().path();
        if f.is_file() {
            std::fs::copy(&f, to.join(f.file_name().unwrap())).unwrap();
        }
    }
    to
}

/// Byte offset of each record of a log.
fn record_starts(log: &[u8]) -> Vec<usize> {
    let mut at = HEADER_LEN as usize;
    let mut v = vec![];
    while at < log.len() {
        v.push(at);
        at += 8 + u32::from_le_bytes(log[at..at + 4].try_into().unwrap()) as usize;
    }
    v
}

/// A run recorded whole over a clean line, and the rig's own copy of it.
fn reference_run(mu0: f64, seed: u64) -> (Bench, tempfile::TempDir, PathBuf, Vec<Vec<u8>>) {
    let mut bench = Bench::new(rig(mu0, seed));
    let store = tempfile::tempdir().unwrap();
    let o = record(&mut bench, Faults::default(), store.path()).unwrap();
    let id = o.run.header().unwrap().run_id;
    let truth = bench.rig_frames(id);
    assert_bit_identical(&o.run, &truth);
    (bench, store, o.run.dir().to_owned(), truth)
}

#[test]
fn flipped_bytes_at_start_middle_and_end_of_a_log() {
    let (mut bench, _store, dir, truth) = reference_run(0.02, 31);
    let log = std::fs::read(dir.join("frames.log")).unwrap();
    let starts = record_starts(&log);
    let n = starts.len();
    assert_eq!(n, truth.len());
    let mid = n / 2;
    // (what, byte flipped, frames a salvage keeps, blocks the pull must fetch)
    let cases: [(&str, usize, usize, usize); 5] = [
        ("file header", 9, n, 0),
        ("run header", starts[0] + 8 + 20, n - 1, 0),
        ("a block in the middle", starts[mid] + 8 + 30, n - 1, 1),
        (
            "a record's checksum field (its frame is whole)",
            starts[mid] + 5,
            n,
            0,
        ),
        ("the end frame", starts[n - 1] + 8 + 6, n - 1, 0),
    ];
    assert!(
        block_of(&truth[mid]).is_some(),
        "the middle record is a block"
    );
    for (what, at, salvaged, fetched) in cases {
        let store = tempfile::tempdir().unwrap();
        let d = copy_run(&dir, store.path());
        let mut bytes = log.clone();
        bytes[at] ^= 0x20;
        std::fs::write(d.join("frames.log"), &bytes).unwrap();
        // Read honestly: an error naming the damage, or a run that is not complete.
        match Run::open(&d) {
            Ok(r) => assert!(!r.is_complete(), "{what}: read as complete"),
            Err(e) => assert!(e.msg.contains("--salvage"), "{what}: {e}"),
        }
        // Salvage keeps every intact record, before and after the damage, and invents none.
        let s = Run::open_salvage(&d).unwrap();
        assert_eq!(s.frames().len(), salvaged, "{what}: frames salvaged");
        assert!(s
            .frames()
            .iter()
            .all(|f| truth.iter().any(|t| &t[..] == *f)));
        // `tribo pull --salvage RUN`: the rest from the rig, only what the flip cost.
        let o = pull(&mut bench, Faults::default(), store.path(), Some(&d), true);
        assert_eq!(o.run.dir(), d, "{what}");
        assert_bit_identical(&o.run, &truth);
        assert_eq!(o.pulled_blocks, fetched, "{what}: blocks fetched");
        assert!(o.incomplete().is_none());
        assert!(
            d.join("frames.log.damaged").is_file() || salvaged == n - 1 && what == "the end frame",
            "{what}: the damaged log is kept"
        );
    }
}

/// The recorder writes the rig's run id into the folder's metadata before it logs the run header,
/// so a recorder killed in between leaves a folder `tribo pull` finds (not a second folder).
#[test]
fn killed_before_the_header_was_logged() {
    let (mut bench, _store, dir, truth) = reference_run(0.02, 33);
    let store = tempfile::tempdir().unwrap();
    let d = copy_run(&dir, store.path());
    let log = std::fs::read(d.join("frames.log")).unwrap();
    std::fs::write(d.join("frames.log"), &log[..HEADER_LEN as usize]).unwrap();
    let meta_path = d.join(tribo_store::run::META_FILE);
    let mut meta: tribo_store::RunMeta =
        toml::from_str(&std::fs::read_to_string(&meta_path).unwrap()).unwrap();
    assert_eq!(meta.device_run_id, Some(truth_run_id(&truth)));
    meta.status = tribo_store::RunStatus::Recording;
    std::fs::write(&meta_path, toml::to_string(&meta).unwrap()).unwrap();
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    assert_eq!(
        o.run.dir(),
        d,
        "the pull fills the folder the recorder left"
    );
    assert_bit_identical(&o.run, &truth);
    assert_eq!(
        std::fs::read_dir(store.path())
            .unwrap()
            .filter(|e| e.as_ref().unwrap().path().is_dir())
            .count(),
        1
    );
}

/// The rig's run id of a run's frames (from its header).
fn truth_run_id(truth: &[Vec<u8>]) -> u32 {
    truth
        .iter()
        .find_map(|f| match msg(f) {
            DeviceMsg::RunStarted(h) => Some(h.run_id),
            _ => None,
        })
        .expect("a run header")
}

#[test]
fn truncated_log() {
    let (mut bench, _store, dir, truth) = reference_run(0.02, 32);
    let log = std::fs::read(dir.join("frames.log")).unwrap();
    let starts = record_starts(&log);
    let keep = starts.len() * 3 / 5;
    let store = tempfile::tempdir().unwrap();
    let d = copy_run(&dir, store.path());
    std::fs::write(d.join("frames.log"), &log[..starts[keep] + 37]).unwrap();
    let run = Run::open(&d).unwrap();
    let held = truth[..keep]
        .iter()
        .filter(|f| block_of(f).is_some())
        .count();
    let summary = run.completeness().summary();
    assert_eq!(
        summary,
        format!(
            "incomplete: {held} of at least {held} blocks (the run's end was not received, so how many \
             blocks it has is not known)"
        )
    );
    assert_eq!(
        run.meta.status,
        tribo_store::RunStatus::Incomplete,
        "not the stored 'complete'"
    );
    // The catalog re-index says so too.
    let r = tribo_store::RunCatalog::open(store.path())
        .unwrap()
        .reindex()
        .unwrap();
    assert_eq!(r.incomplete.len(), 1);
    assert!(
        r.incomplete[0].1.starts_with(&summary),
        "{:?}",
        r.incomplete
    );
    // The pull fetches the rest, and only the rest.
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    assert_eq!(o.run.dir(), d);
    assert_bit_identical(&o.run, &truth);
    let total = truth.iter().filter(|f| block_of(f).is_some()).count();
    assert_eq!(o.pulled_blocks, total - held);
}

#[test]
fn cable_pulled_mid_stream() {
    let mut bench = Bench::new(rig(0.02, 33));
    let store = tempfile::tempdir().unwrap();
    let cut = Faults {
        cut_after_bytes: Some(12_000),
        ..Faults::default()
    };
    let o = record(&mut bench, cut, store.path()).unwrap();
    assert!(o.link_lost.is_some());
    let before = o.run.block_count();
    assert!(before > 10, "{before} blocks before the cut");
    let inc = o.incomplete().expect("`tribo run` exits 3").0;
    assert!(
        inc.contains("incomplete: ")
            && inc.contains("may still hold")
            && inc.contains("tribo pull"),
        "{inc}"
    );
    let id = o.run.header().unwrap().run_id;
    // The rig finishes the run with nobody listening; the next pull completes it in place.
    bench.run_on(30.0);
    let truth = bench.rig_frames(id);
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    assert_bit_identical(&o.run, &truth);
    let total = truth.iter().filter(|f| block_of(f).is_some()).count();
    assert_eq!(
        o.pulled_blocks,
        total - before,
        "exactly the blocks not held"
    );
    assert_eq!(
        tribo_store::run::list_run_dirs(store.path()).unwrap().len(),
        1
    );
}

fn lossy_row(seed: u64, per_100k: u32) {
    let mut bench = Bench::new(rig(0.01, seed));
    let store = tempfile::tempdir().unwrap();
    let (o, stats) = record_seen(&mut bench, Faults::lossy(seed, per_100k), store.path());
    let o = o.expect("the run finishes");
    let damaged = stats.damaged_rig_frames();
    let frames = stats.rig_frames.load(std::sync::atomic::Ordering::Relaxed);
    eprintln!(
        "seed {seed}, {per_100k}/100000: {damaged} of {frames} rig frames and {} of {} host frames damaged; {} pull \
         rounds, {} blocks fetched again",
        stats.damaged_host_frames(),
        stats.host_frames.load(std::sync::atomic::Ordering::Relaxed),
        o.pull_rounds,
        o.pulled_blocks
    );
    assert!(damaged > 0, "the line damaged something");
    assert!(o.not_held.is_none(), "{:?}", o.not_held);
    assert!(o.incomplete().is_none(), "{:?}", o.incomplete());
    let id = o.run.header().unwrap().run_id;
    let truth = bench.rig_frames(id);
    assert_bit_identical(&o.run, &truth);
}

#[test]
fn lossy_link() {
    for seed in [41, 42, 43] {
        lossy_row(seed, 1_000);
    }
    lossy_row(44, 5_000);
    // A line that damages one frame in five, each way: commands are sent again, pulls retried.
    lossy_row(45, 20_000);
}

#[test]
fn lost_header_events_result_and_end() {
    // A run with an acquisition gap (the reader stalls 300 ms), and ECR range changes.
    let cfg = VirtualRigConfig {
        law: tribo_physics::FrictionLaw::coulomb_viscous(0.01, 0.004),
        seed: 21,
        acquisition: AcquisitionFaults {
            stall_reader_after_ms: Some(600),
            stall_reader_ms: 300,
            adc_overrun_after_ms: None,
        },
        ..Default::default()
    };
    let mut bench = Bench::new(VirtualRig::new(cfg).unwrap());
    let store = tempfile::tempdir().unwrap();
    let faults = Faults {
        drop_once: vec![
            |m| matches!(m, DeviceMsg::RunStarted(_)),
            |m| matches!(m, DeviceMsg::Gap(_)),
            |m| matches!(m, DeviceMsg::EcrRange(_)),
            |m| matches!(m, DeviceMsg::Chain(_)),
            |m| matches!(m, DeviceMsg::Result(_)),
            |m| matches!(m, DeviceMsg::RunEnded(_)),
        ],
        ..Faults::default()
    };
    let (o, stats) = record_seen(&mut bench, faults, store.path());
    let o = o.expect("the run finishes");
    assert!(
        stats.damaged_rig_frames() >= 5,
        "header, gap, result, end dropped (the chain as well)"
    );
    let id = o.run.header().unwrap().run_id;
    let truth = bench.rig_frames(id);
    assert!(
        truth.iter().any(|f| matches!(msg(f), DeviceMsg::Gap(_))),
        "the run has a gap"
    );
    assert_bit_identical(&o.run, &truth);
    // The gap is the rig's, not a missing block.
    assert!(o.run.lost_samples() > 0);
    assert!(o.run.missing_blocks().is_empty());
}

#[test]
fn power_cut_after_the_run() {
    let mut bench = Bench::new(rig(0.02, 34));
    let store = tempfile::tempdir().unwrap();
    let cut = Faults {
        cut_after_bytes: Some(3_000),
        ..Faults::default()
    };
    let o = record(&mut bench, cut, store.path()).unwrap();
    let id = o.run.header().unwrap().run_id;
    bench.run_on(30.0);
    let truth = bench.rig_frames(id);
    // Power lost, then back: the rig recovers its last run from flash.
    bench.rig().power_cycle();
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    assert_bit_identical(&o.run, &truth);
}

#[test]
fn power_cut_during_the_run() {
    let mut bench = Bench::new(rig(0.005, 35));
    // In real time, so that the line is cut early in the run (as fast as it goes, the rig would be
    // done before the host noticed).
    bench.opts.speed = 1.0;
    let store = tempfile::tempdir().unwrap();
    let cut = Faults {
        cut_after_bytes: Some(3_000),
        ..Faults::default()
    };
    let o = record(&mut bench, cut, store.path()).unwrap();
    let id = o.run.header().unwrap().run_id;
    // On, with the cable out, until the flash holds some of the run (it starts writing once its
    // first sector is erased, ~1 s in), then the power goes.
    while bench.rig().app().store().durable_blocks() < 20 {
        bench.run_on(0.05);
        assert_eq!(
            bench.rig().app().state(),
            tribo_wire::RigState::Running,
            "still running"
        );
    }
    bench.rig().power_cycle();
    // What the rig kept: its flash's copy, without an end.
    let truth = bench.rig_frames(id);
    assert!(!truth
        .iter()
        .any(|f| matches!(msg(f), DeviceMsg::RunEnded(_))));
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    let got = o.run.frames();
    assert_eq!(got.len(), truth.len());
    assert!(got.iter().zip(&truth).all(|(a, b)| *a == &b[..]));
    let inc = o.incomplete().expect("exit 3").0;
    assert!(inc.contains("of at least"), "{inc}");
    let n = o.not_held.as_deref().unwrap_or_default();
    assert!(
        n.contains("restarted during the run") && n.contains("without sending it"),
        "{n}"
    );
}

#[test]
fn a_run_longer_than_the_rig_keeps() {
    // Unloaded (the pin oscillates all the way), 60 s at 20 kS/s with every channel: more than
    // the rig's RAM and flash hold together; taken with the cable out.
    let mut bench = Bench::new(
        VirtualRig::new(VirtualRigConfig {
            load_n: 0.0,
            ..Default::default()
        })
        .unwrap(),
    );
    let mut c = Configure::real_rig(0.0);
    c.sample_rate_hz = 20_000;
    c.max_duration_s = 60.0;
    bench.session(Faults::default(), |link| {
        link.hello().unwrap();
        for m in [
            HostMsg::Configure(c),
            HostMsg::HeaterOff,
            HostMsg::Arm,
            HostMsg::Release,
        ] {
            link.command(m).unwrap();
        }
    });
    bench.run_on(61.0);
    let durable = {
        let st = bench.rig().app().store();
        eprintln!(
            "store: {} blocks, {} durable, RAM from {}, flash {:?}",
            st.blocks(),
            st.durable_blocks(),
            st.first_block_in_ram(),
            st.flash_state()
        );
        // The flash is full long before the end and RAM drops the records around its cut: the
        // flash copy still ends cleanly, the run's beginning then its result and end.
        assert_eq!(st.flash_state(), tribo_firmware::runstore::FlashState::Done);
        st.durable_blocks()
    };
    let truth = bench.rig_frames(1);
    let held: BTreeSet<u32> = truth.iter().filter_map(|f| block_of(f)).collect();
    let end = truth
        .iter()
        .find_map(|f| match msg(f) {
            DeviceMsg::RunEnded(e) => Some(e),
            _ => None,
        })
        .expect("the end is kept");
    let lost: Vec<u32> = (0..end.blocks).filter(|b| !held.contains(b)).collect();
    eprintln!(
        "rig holds {} blocks of {}: lost {}",
        held.len(),
        end.blocks,
        tribo_store::run::block_ranges(&lost)
    );
    assert!(!lost.is_empty(), "the rig lost the middle of this run");
    let store = tempfile::tempdir().unwrap();
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    // Every frame the rig holds, bit for bit; exactly the others missing, and why.
    let got = o.run.frames();
    assert_eq!(got.len(), truth.len());
    assert!(got.iter().zip(&truth).all(|(a, b)| *a == &b[..]));
    assert_eq!(o.run.missing_blocks(), lost);
    let ranges = tribo_store::run::block_ranges(&lost);
    let inc = o.incomplete().expect("exit 3").0;
    assert!(
        inc.contains(&format!(
            "incomplete: {} of {} blocks (missing {ranges}",
            held.len(),
            end.blocks
        )),
        "{inc}"
    );
    let n = o.not_held.as_deref().unwrap_or_default();
    assert!(
        n.contains(&ranges) && n.contains("no longer holds them"),
        "{n}"
    );
    eprintln!("{inc}");
    // Power lost, then back: the run comes back from flash finished, its beginning whole.
    bench.rig().power_cycle();
    bench.run_on(0.1);
    let st = bench.rig().app().store();
    assert!(st.is_finished(), "the result and end survive the power cut");
    assert_eq!(st.blocks(), durable);
}

#[test]
fn events_an_older_host_did_not_store_are_fetched_into_the_same_run() {
    // A run with acquisition gaps and ECR range changes, stored by a host that kept only header,
    // blocks, result and end (as tribo did before it stored run events): the pull recognises the
    // run as the rig's (same header) and adds the events, instead of taking it for another run.
    let cfg = VirtualRigConfig {
        law: tribo_physics::FrictionLaw::coulomb_viscous(0.01, 0.004),
        seed: 22,
        acquisition: AcquisitionFaults {
            stall_reader_after_ms: Some(500),
            stall_reader_ms: 200,
            adc_overrun_after_ms: None,
        },
        ..Default::default()
    };
    let mut bench = Bench::new(VirtualRig::new(cfg).unwrap());
    let store = tempfile::tempdir().unwrap();
    let o = record(&mut bench, Faults::default(), store.path()).unwrap();
    let id = o.run.header().unwrap().run_id;
    let truth = bench.rig_frames(id);
    let dir = o.run.dir().to_owned();
    let old: Vec<Vec<u8>> = truth
        .iter()
        .filter(|f| !matches!(msg(f), DeviceMsg::Gap(_) | DeviceMsg::EcrRange(_)))
        .cloned()
        .collect();
    assert!(old.len() < truth.len(), "the run has events");
    let log = dir.join("frames.log");
    std::fs::remove_file(&log).unwrap();
    let mut w = tribo_store::LogWriter::create(&log, Some(2)).unwrap();
    for f in &old {
        w.append(f).unwrap();
    }
    drop(w);
    let stored = Run::open(&dir).unwrap();
    assert!(!stored.is_complete(), "events are part of the run");
    assert!(stored.completeness().summary().contains("run events"));
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    assert_eq!(o.run.dir(), dir, "the same run, completed");
    assert!(o.warnings.is_empty(), "{:?}", o.warnings);
    assert_eq!(o.pulled_blocks, 0, "no block fetched: only the events");
    // The log now holds every frame once (the events appended after the rest).
    assert_bit_identical(&o.run, &truth);
}

#[test]
fn a_rig_that_stops_hearing_is_not_said_to_have_lost_the_blocks() {
    // Blocks 10–19 lost on the way; after the release the rig hears nothing more: the pulls go
    // unanswered. `tribo run` must not claim the rig no longer holds the blocks.
    let mut bench = Bench::new(rig(0.02, 36));
    let store = tempfile::tempdir().unwrap();
    let faults = Faults {
        drop_always: Some(|m| matches!(m, DeviceMsg::Packed(p) if (10..20).contains(&p.block))),
        deaf_after_host_frames: Some(6),
        ..Faults::default()
    };
    let t0 = std::time::Instant::now();
    let o = record(&mut bench, faults, store.path()).unwrap();
    eprintln!("gave up after {:.1} s", t0.elapsed().as_secs_f64());
    assert_eq!(o.run.missing_blocks(), (10..20).collect::<Vec<_>>());
    assert!(o.not_held.is_none(), "{:?}", o.not_held);
    let e = o.link_lost.as_ref().expect("the rig did not answer");
    assert_eq!(e.kind, tribo::link::LinkErrorKind::NoAnswer);
    let inc = o.incomplete().expect("exit 3").0;
    assert!(
        inc.contains("missing 10–19")
            && inc.contains("may still hold")
            && !inc.contains("no longer"),
        "{inc}"
    );
    // It did: a pull over a sound line fetches exactly those.
    let id = o.run.header().unwrap().run_id;
    let truth = bench.rig_frames(id);
    let o = pull(&mut bench, Faults::default(), store.path(), None, false);
    assert_bit_identical(&o.run, &truth);
    assert_eq!(o.pulled_blocks, 10);
}

/// The frames a packed run opens with, right after its header (the ECR range at sample 0, the
/// analog chain), lost live: the pulls fetch them, on a clean line and on lossy ones. (The soak
/// found runs ending incomplete, "run events missing before block 0", with the rig holding the
/// chain: the run being written did not know its protocol, so it did not miss the chain and never
/// asked for it; read back, the run did.)
#[test]
fn the_frames_after_the_header_lost_live_are_pulled() {
    let first_range = |m: &DeviceMsg| matches!(m, DeviceMsg::EcrRange(e) if e.first_sample == 0);
    let chain = |m: &DeviceMsg| matches!(m, DeviceMsg::Chain(_));
    let lines = [
        Faults::default(),
        Faults::lossy(71, 1_000),
        Faults::lossy(72, 5_000),
    ];
    for (i, line) in lines.into_iter().enumerate() {
        for (what, lost) in [
            ("the first ECR range", first_range as fn(&DeviceMsg) -> bool),
            ("the chain", chain),
        ] {
            let mut bench = Bench::new(rig(0.01, 60 + i as u64));
            let store = tempfile::tempdir().unwrap();
            let faults = Faults {
                drop_once: vec![lost],
                ..line.clone()
            };
            let (o, stats) = record_seen(&mut bench, faults, store.path());
            let o = o.expect("the run finishes");
            assert!(stats.damaged_rig_frames() >= 1, "{what} was dropped");
            assert!(
                o.not_held.is_none(),
                "line {i}, {what} lost: {:?}",
                o.not_held
            );
            assert!(
                o.incomplete().is_none(),
                "line {i}, {what} lost: {:?}",
                o.incomplete()
            );
            let id = o.run.header().unwrap().run_id;
            let truth = bench.rig_frames(id);
            assert!(
                truth.iter().any(|f| lost(&msg(f))),
                "the rig's run holds {what}"
            );
            assert_bit_identical(&o.run, &truth);
        }
    }
}
