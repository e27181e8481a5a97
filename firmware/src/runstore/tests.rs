//! The run store against the flash model: RAM and flash copies, recovery after power loss at any
//! point, runs larger than RAM or flash, wear spread, failures.

use super::memflash::MemFlash;
use super::*;
use crate::wire::frame::encode_vec;
use crate::wire::{
    ChannelSet, Configure, Counts, EndReason, EnvelopeShape, Estimate, Gap, OnboardResult,
    PackedBlock, RunEnd, RunHeader, SampleBlock, Verdict,
};

/// A small flash: 8 sectors of 8 KiB (the bank's shape, 16 times smaller).
const SMALL: FlashGeometry = FlashGeometry {
    sector_bytes: 8 * 1024,
    sectors: 8,
};

fn flash(g: FlashGeometry) -> MemFlash<Vec<u8>> {
    MemFlash::new(vec![0u8; g.bytes() as usize], g)
}

fn store(ram: usize) -> RunStore<'static> {
    let a: &'static mut [u8] = Box::leak(vec![0u8; ram / 3].into_boxed_slice());
    let b: &'static mut [u8] = Box::leak(vec![0u8; ram - ram / 3].into_boxed_slice());
    let index: &'static mut [u32] = Box::leak(vec![0u32; MAX_RUN_BLOCKS].into_boxed_slice());
    RunStore::new([a, b], index)
}

/// One record of a test run, as the application would store it.
#[derive(Debug, Clone, PartialEq)]
enum Rec {
    Block(u32, Vec<u8>),
    Event(Vec<u8>),
}

impl Rec {
    fn bytes(&self) -> &[u8] {
        match self {
            Rec::Block(_, b) | Rec::Event(b) => b,
        }
    }
}

/// The frames of a run of `blocks` five-channel blocks of a noisy oscillation, with a gap event
/// every `event_every` blocks (0: none).
struct TestRun {
    run_id: u32,
    header: Vec<u8>,
    records: Vec<Rec>,
    result: Vec<u8>,
    end: Vec<u8>,
}

fn test_run(run_id: u32, blocks: u32, event_every: u32) -> TestRun {
    let mut seq = run_id * 100_000;
    let mut next = || {
        seq += 1;
        seq
    };
    let header = encode_vec(
        next(),
        &DeviceMsg::RunStarted(RunHeader {
            run_id,
            config: Configure::real_rig(0.3),
            temp_c: 25.0,
            t_us: 1_000_000,
            clock: crate::wire::SampleClock::exact(10_000),
        }),
    )
    .unwrap();
    let mut records = vec![];
    let mut x = 0x1234_5678u32 ^ run_id;
    for k in 0..blocks {
        if event_every > 0 && k % event_every == event_every - 1 {
            let g = Gap {
                run_id,
                first_sample: k * 64,
                count: 3,
            };
            records.push(Rec::Event(encode_vec(next(), &DeviceMsg::Gap(g)).unwrap()));
        }
        let mut counts = Counts::default();
        for i in 0..64u32 {
            let t = (k * 64 + i) as f32 * 1e-4;
            let s = micromath::F32Ext::sin(2.0 * core::f32::consts::PI * 27.0 * t);
            for c in 0..5u32 {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                let noise = (x % 9) as f32 - 4.0;
                let v = 32768.0 + s * 8000.0 / (c + 1) as f32 + noise;
                let _ = counts.push(v as u16);
            }
        }
        let b = SampleBlock {
            run_id,
            block: k,
            first_sample: k * 64,
            t_us: 1_000_000 + k as u64 * 6400,
            channels: ChannelSet::ALL,
            ecr_range: 2,
            log10_ecr_ohm: 7.0,
            temp_c: 25.0,
            counts,
        };
        let p = PackedBlock::pack(&b).unwrap();
        records.push(Rec::Block(
            k,
            encode_vec(next(), &DeviceMsg::Packed(p)).unwrap(),
        ));
    }
    let none = Estimate::default();
    let result = encode_vec(
        next(),
        &DeviceMsg::Result(OnboardResult {
            run_id,
            verdict: Verdict::Ok,
            cycles: 40,
            frequency_hz: 27.0,
            initial_amplitude_m: 667e-6,
            duration_s: 1.0,
            best: none,
            averaging: none,
            decrement: none,
            shape: EnvelopeShape::Straight,
            curvature: 0.0,
        }),
    )
    .unwrap();
    let end = encode_vec(
        next(),
        &DeviceMsg::RunEnded(RunEnd {
            run_id,
            blocks,
            samples: blocks * 64,
            overruns: 0,
            reason: EndReason::Stopped,
        }),
    )
    .unwrap();
    TestRun {
        run_id,
        header,
        records,
        result,
        end,
    }
}

/// Feeds a run into the store, servicing the flash every `service_every` records (the flash
/// finishing its operations at once unless it has timings).
fn record(s: &mut RunStore, f: &mut MemFlash<Vec<u8>>, run: &TestRun, finish: bool) {
    assert!(s.begin(f, run.run_id, &run.header));
    for r in &run.records {
        match r {
            Rec::Block(k, b) => assert!(s.push_block(*k, b)),
            Rec::Event(b) => assert!(s.push_event(b)),
        }
        s.service(f);
        s.service(f);
    }
    if finish {
        assert!(s.set_result(&run.result));
        assert!(s.set_end(&run.end));
    }
}

/// Services the flash until its copy is done (or stuck), advancing the model's clock.
fn settle(s: &mut RunStore, f: &mut MemFlash<Vec<u8>>, now: &mut u64) {
    for _ in 0..1_000_000 {
        s.service(f);
        if s.flash_state() != FlashState::Writing {
            return;
        }
        *now += 1000;
        f.advance(*now);
    }
    panic!("the flash copy never finished");
}

/// Every record of the stream read back in order (header excluded), as the pump would.
fn stream(s: &RunStore, f: &mut MemFlash<Vec<u8>>) -> Vec<Vec<u8>> {
    let mut out = vec![];
    let mut pos = s.first_pos();
    let mut buf = [0u8; MAX_FRAME];
    loop {
        match s.read(f, pos, &mut buf) {
            Read::Frame { len, next } => {
                out.push(buf[..len].to_vec());
                pos = next;
            }
            Read::End => return out,
            Read::Lost { next } => pos = next,
            Read::Busy => panic!("busy flash in a test that settled it"),
        }
    }
}

fn all(run: &TestRun) -> Vec<Vec<u8>> {
    run.records.iter().map(|r| r.bytes().to_vec()).collect()
}

#[test]
fn a_run_is_read_back_byte_for_byte_in_order() {
    let mut f = flash(SMALL);
    let mut s = store(64 * 1024);
    let run = test_run(1, 60, 7);
    record(&mut s, &mut f, &run, true);
    assert_eq!(s.header(), Some(&run.header[..]));
    assert_eq!(s.result(), Some(&run.result[..]));
    assert_eq!(s.end(), Some(&run.end[..]));
    assert_eq!((s.blocks(), s.events()), (60, 8));
    assert_eq!(stream(&s, &mut f), all(&run));
    // Blocks by index, and where a pull from block k starts: just after block k - 1.
    let mut buf = [0u8; MAX_FRAME];
    for (i, r) in run.records.iter().enumerate() {
        if let Rec::Block(k, b) = r {
            let Read::Frame { len, .. } = s.read(&mut f, s.block_pos(*k).unwrap(), &mut buf) else {
                panic!("block {k}")
            };
            assert_eq!(&buf[..len], &b[..]);
            let from = s.start_of_block(&mut f, *k).unwrap();
            let mut expect_first = i;
            while expect_first > 0 && matches!(run.records[expect_first - 1], Rec::Event(_)) {
                expect_first -= 1;
            }
            let Read::Frame { len, .. } = s.read(&mut f, from, &mut buf) else {
                panic!()
            };
            assert_eq!(
                &buf[..len],
                run.records[expect_first].bytes(),
                "pull from block {k} starts with the events before it"
            );
        }
    }
    assert_eq!(f.violations(), 0);
}

#[test]
fn the_flash_copy_survives_power_loss_bit_identical() {
    let mut f = flash(SMALL);
    let mut s = store(64 * 1024);
    let run = test_run(7, 120, 25);
    record(&mut s, &mut f, &run, true);
    let mut now = 0;
    settle(&mut s, &mut f, &mut now);
    assert_eq!(s.flash_state(), FlashState::Done);
    assert_eq!(s.durable_blocks(), 120);
    // Power loss: RAM is gone, the flash stays.
    f.power_cut();
    let mut s2 = store(64 * 1024);
    let r = s2.recover(&mut f).expect("the run is in flash");
    assert_eq!(
        r,
        Recovered {
            run_id: 7,
            blocks: 120,
            events: 4,
            finished: true
        }
    );
    assert_eq!(s2.header(), Some(&run.header[..]));
    assert_eq!(s2.result(), Some(&run.result[..]));
    assert_eq!(s2.end(), Some(&run.end[..]));
    assert_eq!(stream(&s2, &mut f), all(&run));
    assert_eq!(f.violations(), 0);
}

#[test]
fn a_run_larger_than_ram_is_served_from_flash() {
    let mut f = flash(SMALL);
    // About 12 blocks of RAM; the flash settles after every record (it keeps up).
    let mut s = store(3 * 1024);
    let run = test_run(2, 150, 10);
    let mut now = 0;
    assert!(s.begin(&f, run.run_id, &run.header));
    for r in &run.records {
        match r {
            Rec::Block(k, b) => assert!(s.push_block(*k, b)),
            Rec::Event(b) => assert!(s.push_event(b)),
        }
        for _ in 0..3 {
            s.service(&mut f);
        }
    }
    s.set_result(&run.result);
    s.set_end(&run.end);
    settle(&mut s, &mut f, &mut now);
    assert!(s.first_block_in_ram() > 100, "{}", s.first_block_in_ram());
    assert_eq!(stream(&s, &mut f), all(&run));
    assert_eq!(f.violations(), 0);
}

#[test]
fn a_run_larger_than_flash_keeps_its_beginning_its_end_and_in_ram_its_last_part() {
    // 4 sectors of 8 KiB: about 150 blocks; the run has 400.
    let g = FlashGeometry {
        sector_bytes: 8 * 1024,
        sectors: 4,
    };
    let mut f = flash(g);
    let mut s = store(256 * 1024);
    let run = test_run(3, 400, 0);
    record(&mut s, &mut f, &run, true);
    let mut now = 0;
    settle(&mut s, &mut f, &mut now);
    assert_eq!(s.flash_state(), FlashState::Done);
    // RAM has everything: the live stream and pulls lose nothing.
    assert_eq!(stream(&s, &mut f), all(&run));
    let durable = s.durable_blocks();
    assert!(durable > 100 && durable < 400, "{durable}");
    // Between runs the store erases the next run's first sector ahead: never one of this copy's,
    // which fills the bank.
    for _ in 0..100 {
        s.service(&mut f);
        now += 100_000;
        f.advance(now);
    }
    f.power_cut();
    let mut s2 = store(256 * 1024);
    let r = s2.recover(&mut f).unwrap();
    assert_eq!(
        (r.blocks, r.finished),
        (durable, true),
        "the beginning, and the result and end"
    );
    assert_eq!(stream(&s2, &mut f), all(&run)[..durable as usize].to_vec());
    assert_eq!(s2.end(), Some(&run.end[..]));
    assert_eq!(f.violations(), 0);
}

#[test]
fn a_run_larger_than_both_loses_only_its_middle_and_says_where() {
    let g = FlashGeometry {
        sector_bytes: 8 * 1024,
        sectors: 4,
    };
    let mut f = flash(g);
    let mut s = store(8 * 1024);
    let run = test_run(4, 400, 0);
    record(&mut s, &mut f, &run, true);
    let mut now = 0;
    settle(&mut s, &mut f, &mut now);
    let durable = s.durable_blocks();
    let in_ram = s.first_block_in_ram();
    assert!(durable < in_ram, "{durable} {in_ram}");
    let got = stream(&s, &mut f);
    let mut expect = all(&run)[..durable as usize].to_vec();
    expect.extend(all(&run)[in_ram as usize..].iter().cloned());
    assert_eq!(got, expect);
    // A block in the hole reads as lost, and says where the next held one is.
    let mut buf = [0u8; MAX_FRAME];
    let hole = s.block_pos(durable).unwrap();
    assert_eq!(
        s.read(&mut f, hole, &mut buf),
        Read::Lost {
            next: s.block_pos(in_ram).unwrap()
        }
    );
}

/// Cuts the power at every flash operation of a run (and between them), with H7 timings: what is
/// recovered is always a prefix of the run, frame for frame, plus its result and end only if the
/// whole run made it.
#[test]
fn power_cut_at_any_point_recovers_a_valid_prefix() {
    let run = test_run(9, 90, 11);
    let frames = all(&run);
    // Each case: cut after `polls` polls of 1 ms.
    let mut prefixes_seen = std::collections::BTreeSet::new();
    let mut finished_seen = false;
    // An older run occupies the flash first: it must not be taken for the new one.
    let old = test_run(8, 200, 0);
    for polls in (0..400).step_by(3) {
        // Erases of 20 ms, programs of 100 µs a word: cuts land in erases, in programs, between.
        let mut f = flash(SMALL).with_timing(20_000, 100);
        let mut s = store(256 * 1024);
        record(&mut s, &mut f, &old, true);
        let mut now = 0;
        settle(&mut s, &mut f, &mut now);
        // The new run: one record per poll, then the end, flash served each poll.
        assert!(s.begin(&f, run.run_id, &run.header));
        let mut fed = 0;
        for p in 0..polls {
            if fed < run.records.len() {
                match &run.records[fed] {
                    Rec::Block(k, b) => assert!(s.push_block(*k, b)),
                    Rec::Event(b) => assert!(s.push_event(b)),
                }
                fed += 1;
            } else if fed == run.records.len() {
                s.set_result(&run.result);
                s.set_end(&run.end);
                fed += 1;
            }
            s.service(&mut f);
            now += 1000;
            f.advance(now);
            let _ = p;
        }
        f.power_cut();
        let mut s2 = store(256 * 1024);
        let r = s2.recover(&mut f);
        assert_eq!(f.violations(), 0);
        let Some(r) = r else {
            panic!("cut after {polls} polls: nothing recovered, not even the old run");
        };
        if r.run_id == 8 {
            // The new run's first sector was not written yet: the old run is intact.
            assert_eq!((r.blocks, r.finished), (200, true), "cut at {polls}");
            assert_eq!(stream(&s2, &mut f), all(&old));
            continue;
        }
        assert_eq!(r.run_id, 9);
        let got = stream(&s2, &mut f);
        assert!(got.len() <= frames.len());
        assert_eq!(got, frames[..got.len()].to_vec(), "cut at {polls}");
        if r.finished {
            assert_eq!(got.len(), frames.len());
            assert_eq!(s2.end(), Some(&run.end[..]));
            finished_seen = true;
        }
        prefixes_seen.insert(got.len());
    }
    assert!(
        finished_seen,
        "some cut came after the whole run was written"
    );
    assert!(
        prefixes_seen.len() > 10,
        "cuts landed at many points: {prefixes_seen:?}"
    );
}

#[test]
fn a_torn_or_damaged_record_ends_the_recovered_run_there() {
    let mut f = flash(SMALL);
    let mut s = store(64 * 1024);
    let run = test_run(5, 50, 0);
    record(&mut s, &mut f, &run, true);
    let mut now = 0;
    settle(&mut s, &mut f, &mut now);
    // Damage one byte inside block 30's record.
    let pos = s.block_pos(30).unwrap() as usize + 20;
    f.bytes_mut()[pos] ^= 0x40;
    let mut s2 = store(64 * 1024);
    let r = s2.recover(&mut f).unwrap();
    assert_eq!((r.blocks, r.finished), (30, false));
    assert_eq!(stream(&s2, &mut f), all(&run)[..30].to_vec());
    assert_eq!(s2.end(), None);
}

#[test]
fn the_next_run_starts_after_the_last_so_wear_spreads_over_the_bank() {
    let mut f = flash(SMALL);
    let mut s = store(64 * 1024);
    let mut now = 0;
    for id in 1..=40 {
        // About one and a half sectors each.
        let run = test_run(id, 60, 0);
        record(&mut s, &mut f, &run, true);
        settle(&mut s, &mut f, &mut now);
    }
    let counts: Vec<u32> = (0..SMALL.sectors).map(|i| f.erase_count(i)).collect();
    let (min, max) = (*counts.iter().min().unwrap(), *counts.iter().max().unwrap());
    assert!(max - min <= 1, "erases per sector: {counts:?}");
    // And after a reboot the newest run is the one recovered.
    let mut s2 = store(64 * 1024);
    assert_eq!(s2.recover(&mut f).unwrap().run_id, 40);
    assert_eq!(stream(&s2, &mut f), all(&test_run(40, 60, 0)));
    assert_eq!(f.violations(), 0);
}

#[test]
fn a_run_after_a_recovered_one_starts_in_the_next_free_sector() {
    let mut f = flash(SMALL);
    let mut s = store(64 * 1024);
    let mut now = 0;
    let a = test_run(11, 60, 0);
    record(&mut s, &mut f, &a, true);
    settle(&mut s, &mut f, &mut now);
    let mut s2 = store(64 * 1024);
    s2.recover(&mut f).unwrap();
    let b = test_run(12, 20, 0);
    record(&mut s2, &mut f, &b, true);
    settle(&mut s2, &mut f, &mut now);
    // Run 11 used sectors 0 and 1: run 12 went to sector 2, so both are whole in flash.
    assert_eq!(f.erase_count(2), 1);
    assert_eq!(f.erase_count(0), 1);
    let mut s3 = store(64 * 1024);
    assert_eq!(s3.recover(&mut f).unwrap().run_id, 12);
    assert_eq!(stream(&s3, &mut f), all(&b));
}

#[test]
fn a_failed_flash_stops_the_copy_and_ram_still_serves_the_run() {
    let mut f = flash(SMALL);
    let mut s = store(64 * 1024);
    let run = test_run(6, 40, 0);
    assert!(s.begin(&f, run.run_id, &run.header));
    f.fail_next_operation();
    for r in &run.records {
        if let Rec::Block(k, b) = r {
            assert!(s.push_block(*k, b));
        }
        s.service(&mut f);
    }
    s.service(&mut f);
    assert_eq!(s.flash_state(), FlashState::Failed);
    s.set_result(&run.result);
    s.set_end(&run.end);
    assert_eq!(stream(&s, &mut f), all(&run));
}

#[test]
fn a_busy_flash_holds_a_read_back_but_never_ram() {
    let mut f = flash(SMALL).with_timing(1_000_000, 10);
    let mut s = store(3 * 1024);
    let run = test_run(10, 80, 0);
    let mut now = 0;
    assert!(s.begin(&f, run.run_id, &run.header));
    for r in &run.records {
        if let Rec::Block(k, b) = r {
            assert!(s.push_block(*k, b));
        }
        settle_partly(&mut s, &mut f, &mut now);
    }
    // Block 0 only in flash now; start an erase by filling a sector's worth... simpler: make the
    // model busy with a long operation and read.
    let mut buf = [0u8; MAX_FRAME];
    let p0 = s.block_pos(0).unwrap();
    assert!(p0 < s.block_pos(s.first_block_in_ram()).unwrap());
    assert!(f.flash_erase(7));
    assert_eq!(s.read(&mut f, p0, &mut buf), Read::Busy);
    let last = s.block_pos(79).unwrap();
    assert!(matches!(s.read(&mut f, last, &mut buf), Read::Frame { .. }));
}

fn settle_partly(s: &mut RunStore, f: &mut MemFlash<Vec<u8>>, now: &mut u64) {
    for _ in 0..2000 {
        s.service(f);
        *now += 1000;
        f.advance(*now);
    }
}

#[test]
fn a_ring_of_many_small_buffers_keeps_records_whole() {
    // Four buffers of 200 bytes: every block record (~250 bytes) spans two or three of them. (The
    // ring must hold two records and a flash word: the word a record ends in is written only once
    // the next record fills it.)
    let bufs: Vec<&'static mut [u8]> = (0..4)
        .map(|_| -> &'static mut [u8] { Box::leak(vec![0u8; 200].into_boxed_slice()) })
        .collect();
    let index: &'static mut [u32] = Box::leak(vec![0u32; MAX_RUN_BLOCKS].into_boxed_slice());
    let mut s = RunStore::new(bufs, index);
    assert_eq!(s.ram_capacity(), 800);
    let mut f = flash(SMALL);
    let run = test_run(12, 30, 4);
    // The flash keeps up (it must: the ring holds about three records).
    assert!(s.begin(&f, run.run_id, &run.header));
    for r in &run.records {
        match r {
            Rec::Block(k, b) => assert!(s.push_block(*k, b)),
            Rec::Event(b) => assert!(s.push_event(b)),
        }
        for _ in 0..4 {
            s.service(&mut f);
        }
    }
    s.set_result(&run.result);
    s.set_end(&run.end);
    let mut now = 0;
    settle(&mut s, &mut f, &mut now);
    assert_eq!(s.flash_state(), FlashState::Done);
    // The last record is still in RAM, split over buffers; all of them read back from RAM or flash.
    assert_eq!(stream(&s, &mut f), all(&run));
    let mut buf = [0u8; MAX_FRAME];
    let last = s.block_pos(29).unwrap();
    assert!(last >= s.ring.lo, "block 29 is in RAM");
    let Read::Frame { len, .. } = s.read(&mut f, last, &mut buf) else {
        panic!()
    };
    assert_eq!(&buf[..len], run.records.last().unwrap().bytes());
}

#[test]
fn header_result_and_end_frames_fit_their_slots_at_worst() {
    let worst = f32::MIN_POSITIVE;
    let mut c = Configure::real_rig(0.7);
    c.sample_rate_hz = u32::MAX;
    c.max_duration_s = worst;
    let h = encode_vec(
        u32::MAX,
        &DeviceMsg::RunStarted(RunHeader {
            run_id: u32::MAX,
            config: c,
            temp_c: worst,
            t_us: u64::MAX,
            clock: crate::wire::SampleClock {
                timer_hz: u32::MAX,
                ticks_per_sample: u32::MAX,
            },
        }),
    )
    .unwrap();
    let e = Estimate {
        mu0: worst,
        mu1: worst,
        mu0_se: worst,
        mu1_se: worst,
    };
    let r = encode_vec(
        u32::MAX,
        &DeviceMsg::Result(OnboardResult {
            run_id: u32::MAX,
            verdict: Verdict::NotAnalysed,
            cycles: u16::MAX,
            frequency_hz: worst,
            initial_amplitude_m: worst,
            duration_s: worst,
            best: e,
            averaging: e,
            decrement: e,
            shape: EnvelopeShape::Mixed,
            curvature: worst,
        }),
    )
    .unwrap();
    let end = encode_vec(
        u32::MAX,
        &DeviceMsg::RunEnded(RunEnd {
            run_id: u32::MAX,
            blocks: u32::MAX,
            samples: u32::MAX,
            overruns: u32::MAX,
            reason: EndReason::Fault(crate::wire::HeaterFault::OverTemperature),
        }),
    )
    .unwrap();
    for (what, f) in [("header", &h), ("result", &r), ("end", &end)] {
        assert!(f.len() <= SLOT, "{what}: {} bytes", f.len());
    }
}

/// The run goes on long after the flash is full (a fast run: 20 kS/s fills bank 2 in ~18 s): RAM
/// drops the records around the cut long before the run ends, the last, partial flash word of the
/// cut among them. The flash copy still ends cleanly: its beginning, then the result and end.
#[test]
fn a_run_that_outlasts_the_flash_and_the_ring_still_ends_its_flash_copy_cleanly() {
    let g = FlashGeometry {
        sector_bytes: 8 * 1024,
        sectors: 4,
    };
    let mut f = flash(g);
    let mut s = store(8 * 1024);
    let run = test_run(13, 600, 50);
    record(&mut s, &mut f, &run, true);
    let mut now = 0;
    settle(&mut s, &mut f, &mut now);
    assert_eq!(s.flash_state(), FlashState::Done);
    let durable = s.durable_blocks();
    assert!(durable > 100 && durable < 600, "{durable}");
    // RAM holds the last part only; the live stream said what it lost.
    assert!(
        s.first_block_in_ram() > durable + 100,
        "{}",
        s.first_block_in_ram()
    );
    f.power_cut();
    let mut s2 = store(8 * 1024);
    let r = s2.recover(&mut f).unwrap();
    assert_eq!((r.run_id, r.blocks, r.finished), (13, durable, true));
    let back = stream(&s2, &mut f);
    assert_eq!(back[..], all(&run)[..back.len()]);
    assert_eq!(s2.result(), Some(&run.result[..]));
    assert_eq!(s2.end(), Some(&run.end[..]));
    assert_eq!(f.violations(), 0);
}

/// A flash slower than the run (a worn bank, long erases): the unwritten backlog would outgrow
/// the ring. The copy is cut at the first record the flash has not begun, so it ends cleanly
/// rather than failing, and the run lives on whole in RAM as long as RAM holds it.
#[test]
fn a_flash_slower_than_the_run_is_cut_before_the_ring_overtakes_it() {
    let mut f = flash(SMALL).with_timing(20_000, 400);
    let mut s = store(32 * 1024);
    let run = test_run(14, 300, 40);
    let mut now = 0;
    assert!(s.begin(&f, run.run_id, &run.header));
    for r in &run.records {
        match r {
            Rec::Block(k, b) => assert!(s.push_block(*k, b)),
            Rec::Event(b) => assert!(s.push_event(b)),
        }
        // A record every millisecond, the flash serviced every 100 µs.
        for _ in 0..10 {
            now += 100;
            f.advance(now);
            s.service(&mut f);
        }
    }
    assert_eq!(s.flash_state(), FlashState::Writing);
    assert!(s.set_result(&run.result) && s.set_end(&run.end));
    settle(&mut s, &mut f, &mut now);
    assert_eq!(s.flash_state(), FlashState::Done);
    let durable = s.durable_blocks();
    assert!(durable > 10 && durable < 300, "{durable}");
    f.power_cut();
    let mut s2 = store(32 * 1024);
    let r = s2.recover(&mut f).unwrap();
    assert_eq!((r.run_id, r.blocks, r.finished), (14, durable, true));
    let back = stream(&s2, &mut f);
    assert_eq!(back[..], all(&run)[..back.len()]);
    assert_eq!(s2.end(), Some(&run.end[..]));
    assert_eq!(f.violations(), 0);
}
