//! The run store on the target: a run larger than its RAM ring (the ring wraps, the flash copy
//! keeps all of it), read back record by record, then recovered from flash after a "power cut".
//!
//! Kept small on purpose (the store's own host tests go much further): a few calls of today's API,
//! so that it is quick to adapt when the store changes.

use crate::{check, check_eq, Cx, Outcome};
use tribo_firmware::hal::FlashGeometry;
use tribo_firmware::runstore::memflash::MemFlash;
use tribo_firmware::runstore::{FlashState, Read, RunStore, MAX_RUN_BLOCKS};
use tribo_firmware::wire::frame::MAX_FRAME;
use tribo_firmware::wire::{
    ChannelSet, Configure, Counts, DeviceMsg, Encoder, EndReason, EnvelopeShape, Estimate,
    OnboardResult, PackedBlock, RunEnd, RunHeader, SampleBlock, SampleClock, Verdict, BLOCK_LEN,
};

/// A small flash: 8 sectors of 4 KiB (the bank's shape, 32 times smaller).
const FLASH: FlashGeometry = FlashGeometry {
    sector_bytes: 4 * 1024,
    sectors: 8,
};
const RUN: u32 = 9;
const BLOCKS: u32 = 40;

/// Frame `k` of the test run: 0 the header, 1..=BLOCKS the packed blocks, then the result and the
/// end. Rebuilt identically on demand (no heap to keep them in).
fn frame(enc: &mut Encoder, k: u32, out: &mut [u8]) -> usize {
    let seq = 1000 + k;
    let msg = if k == 0 {
        DeviceMsg::RunStarted(RunHeader {
            run_id: RUN,
            config: Configure::real_rig(0.3),
            temp_c: 25.0,
            t_us: 1_000,
            clock: SampleClock::exact(10_000),
        })
    } else if k <= BLOCKS {
        let b = k - 1;
        let mut counts = Counts::default();
        let mut x = 0x2545_F491u32 ^ b;
        for i in 0..BLOCK_LEN * 5 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let _ = counts.push(30_000 + (i as u16 * 37) % 5_000 + (x % 7) as u16);
        }
        let blk = SampleBlock {
            run_id: RUN,
            block: b,
            first_sample: b * BLOCK_LEN as u32,
            t_us: 1_000 + b as u64 * 6_400,
            channels: ChannelSet::ALL,
            ecr_range: 2,
            log10_ecr_ohm: 7.0,
            temp_c: 25.0,
            counts,
        };
        match PackedBlock::pack(&blk) {
            Ok(p) => DeviceMsg::Packed(p),
            Err(_) => return 0,
        }
    } else if k == BLOCKS + 1 {
        DeviceMsg::Result(OnboardResult {
            run_id: RUN,
            verdict: Verdict::Ok,
            cycles: 10,
            frequency_hz: 27.0,
            initial_amplitude_m: 667e-6,
            duration_s: 0.3,
            best: Estimate::default(),
            averaging: Estimate::default(),
            decrement: Estimate::default(),
            shape: EnvelopeShape::Straight,
            curvature: 0.0,
        })
    } else {
        DeviceMsg::RunEnded(RunEnd {
            run_id: RUN,
            blocks: BLOCKS,
            samples: BLOCKS * BLOCK_LEN as u32,
            overruns: 0,
            reason: EndReason::Stopped,
        })
    };
    enc.encode(seq, &msg, out).map_or(0, |f| f.len())
}

/// Reads the stream back from its first record and compares every frame with the one stored.
fn read_back(
    s: &RunStore<'_>,
    f: &mut MemFlash<&mut [u8]>,
    enc: &mut Encoder,
) -> Result<u32, crate::Failure> {
    let (mut buf, mut want) = ([0u8; MAX_FRAME], [0u8; MAX_FRAME]);
    let mut pos = s.first_pos();
    let mut k = 1;
    loop {
        match s.read(f, pos, &mut buf) {
            Read::Frame { len, next } => {
                let n = frame(enc, k, &mut want);
                check!(buf[..len] == want[..n], "record {k} read back differs");
                pos = next;
                k += 1;
            }
            Read::End => return Ok(k - 1),
            other => check!(false, "record {k} at {pos}: {other:?}"),
        }
    }
}

/// A run of 40 packed blocks (~13 KiB) through a 5 KiB RAM ring: the ring wraps, the flash keeps
/// the run; every record reads back byte for byte; after a power cut the store recovers the run
/// from flash and reads it back again.
pub fn wraps_and_reads_back_and_recovers(cx: &mut Cx) -> Outcome {
    let mut enc = Encoder::new();
    let mut fbuf = [0u8; 32 * 1024];
    let mut f = MemFlash::new(&mut fbuf[..], FLASH).with_timing(2_000, 5);
    let (mut a, mut b) = ([0u8; 3 * 1024], [0u8; 2 * 1024]);
    let mut index = [0u32; MAX_RUN_BLOCKS];
    let mut s = RunStore::new([&mut a[..], &mut b[..]], &mut index);
    let mut out = [0u8; MAX_FRAME];
    let mut now = 0u64;
    let n = frame(&mut enc, 0, &mut out);
    check!(s.begin(&f, RUN, &out[..n]));
    let mut bytes = 0usize;
    let mut push = None::<u64>;
    for k in 1..=BLOCKS {
        let n = frame(&mut enc, k, &mut out);
        check!(n > 0, "block {k} does not pack");
        bytes += n;
        let mut ok = false;
        let c = cx.count(|| ok = s.push_block(k - 1, &out[..n]));
        check!(ok, "block {} refused", k - 1);
        push = c.map(|c| push.map_or(c, |p| p.max(c)));
        // a block every 6.4 ms at 10 kS/s: six polls, each a flash step and a millisecond
        for _ in 0..6 {
            s.service(&mut f);
            now += 1_000;
            f.advance(now);
        }
    }
    check!(
        bytes > 2 * s.ram_capacity() as usize,
        "the run ({bytes} bytes) should not fit the RAM ring ({})",
        s.ram_capacity()
    );
    let n = frame(&mut enc, BLOCKS + 1, &mut out);
    check!(s.set_result(&out[..n]));
    let n = frame(&mut enc, BLOCKS + 2, &mut out);
    check!(s.set_end(&out[..n]));
    for _ in 0..100_000 {
        s.service(&mut f);
        if s.flash_state() != FlashState::Writing {
            break;
        }
        now += 1_000;
        f.advance(now);
    }
    check_eq!(s.flash_state(), FlashState::Done);
    check_eq!(read_back(&s, &mut f, &mut enc)?, BLOCKS);
    check_eq!(s.blocks(), BLOCKS);
    check_eq!(f.violations(), 0, "flash rules broken");

    // Power cut: RAM is gone, the flash stays.
    let (mut a2, mut b2) = ([0u8; 3 * 1024], [0u8; 2 * 1024]);
    let mut index2 = [0u32; MAX_RUN_BLOCKS];
    let mut fresh = RunStore::new([&mut a2[..], &mut b2[..]], &mut index2);
    let mut r = None;
    let recover = cx.count(|| r = fresh.recover(&mut f));
    check!(r.is_some(), "nothing recovered");
    if let Some(r) = r {
        check_eq!((r.run_id, r.blocks, r.finished), (RUN, BLOCKS, true));
    }
    check_eq!(read_back(&fresh, &mut f, &mut enc)?, BLOCKS);
    let mut want = [0u8; MAX_FRAME];
    let n = frame(&mut enc, BLOCKS + 2, &mut want);
    check!(fresh.end() == Some(&want[..n]), "end frame recovered");
    cx.note(format_args!(
        "{BLOCKS} blocks, {bytes} bytes through a {} byte ring; all read back, then recovered",
        s.ram_capacity()
    ));
    cx.figure("store.worst_push_block", push, "instructions", None)?;
    // The boot recovery's time: this run's (~18 KiB of records) scaled to a full bank (1 MiB, the
    // most it reads), against the watchdog's 250 ms at the board's 400 MHz (one instruction a
    // cycle: QEMU's counts are not M7 cycles, and the board reads bank 2 uncached, with flash wait
    // states on top). At the time of writing ~68 M instructions, ~170 ms: too close to 250 ms to
    // trust, which is why the board starts the watchdog only after the recovery.
    let full = recover.map(|i| i * (1 << 20) / bytes as u64);
    if let (Some(i), Some(full)) = (recover, full) {
        cx.note(format_args!(
            "recovery: {i} instructions for {bytes} bytes, {full} for 1 MiB = {:.1} ms at 400 MHz \
             (the watchdog's timeout: {} ms)",
            full as f64 / 400e3,
            tribo_firmware::wire::limits::WATCHDOG_TIMEOUT_MS
        ));
    }
    cx.figure("store.recover", recover, "instructions", None)?;
    // No budget: with the watchdog started after it, the recovery has none to keep.
    cx.figure(
        "store.recover_1mib_extrapolated",
        full,
        "instructions",
        None,
    )
}
