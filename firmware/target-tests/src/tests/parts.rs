//! Costs of the pieces of the per-sample path on the target (figures only): assembling blocks,
//! packing and framing them, storing them.

use crate::{check, Cx, Outcome};
use tribo_firmware::acquisition::BlockBuilder;
use tribo_firmware::analysis::Pipeline;
use tribo_firmware::hal::ANALOG_CHANNELS;
use tribo_firmware::peaks::arc::ArcFitter;
use tribo_firmware::peaks::PeakFitter;
use tribo_firmware::runstore::memflash::MemFlash;
use tribo_firmware::runstore::{RunStore, MAX_RUN_BLOCKS};
use tribo_firmware::wire::frame::MAX_FRAME;
use tribo_firmware::wire::{
    Channel, ChannelSet, Configure, DeviceMsg, Encoder, PackedBlock, RunHeader, SampleClock,
    BLOCK_LEN,
};

/// Per sample, on the counts of the `coulomb_viscous` record (five channels, the temperature from
/// the thermocouple as the application does): `BlockBuilder::push`, packing a block
/// (`PackedBlock::pack`, the codec), framing it (`Encoder::encode`), storing it
/// (`RunStore::push_block`).
pub fn block_path(cx: &mut Cx) -> Outcome {
    let rec = cx.bundle()?.record("coulomb_viscous");
    check!(rec.is_some(), "no coulomb_viscous record");
    let Some(rec) = rec else { return Ok(()) };
    let cfg = rec.configure;
    let clock = SampleClock::exact(cfg.sample_rate_hz);
    let mut b = BlockBuilder::new(
        1,
        ChannelSet::ALL,
        cfg.calibration[Channel::Temperature.index()],
        clock,
        0,
    );
    const BLOCKS: usize = 4;
    let mut samples = [[0u16; ANALOG_CHANNELS]; BLOCKS * BLOCK_LEN];
    for (k, s) in samples.iter_mut().enumerate() {
        s.copy_from_slice(&rec.sample(rec.hold as usize + 500 + k)[..ANALOG_CHANNELS]);
    }
    let mut blocks = heapless::Vec::<_, BLOCKS>::new();
    let build = cx.count(|| {
        for (k, s) in samples.iter().enumerate() {
            if let Some(blk) = b.push(s, crate::tests::app::TEMP_C, k as u32) {
                let _ = blocks.push(blk);
            }
        }
    });
    check!(blocks.len() == BLOCKS);
    let mut packed = heapless::Vec::<PackedBlock, BLOCKS>::new();
    let pack = cx.count(|| {
        for blk in &blocks {
            if let Ok(p) = PackedBlock::pack(blk) {
                let _ = packed.push(p);
            }
        }
    });
    check!(packed.len() == BLOCKS, "a block did not pack");
    // The packing as the application spreads it: one channel per step.
    let mut worst_step = None::<u64>;
    let mut steps = 0;
    for blk in &blocks {
        let mut p = None;
        let c = cx.count(|| p = PackedBlock::start(blk).ok());
        worst_step = c.map(|c| worst_step.map_or(c, |w: u64| w.max(c)));
        let Some(mut p) = p else { continue };
        let mut packer = tribo_firmware::wire::codec::Packer::new();
        let mut done = false;
        while !done {
            let c = cx.count(|| done = p.pack_step(blk, &mut packer).unwrap_or(true));
            worst_step = c.map(|c| worst_step.map_or(c, |w: u64| w.max(c)));
            steps += 1;
        }
    }
    check!(
        steps == 5 * BLOCKS,
        "{steps} packing steps for {BLOCKS} five-channel blocks"
    );
    let mut enc = Encoder::new();
    let mut frames = [[0u8; MAX_FRAME]; BLOCKS];
    let mut lens = [0usize; BLOCKS];
    let framed = cx.count(|| {
        for ((p, f), n) in packed.iter().zip(frames.iter_mut()).zip(lens.iter_mut()) {
            *n = enc
                .encode(p.block, &DeviceMsg::Packed(p.clone()), f)
                .map_or(0, |b| b.len());
        }
    });
    check!(lens.iter().all(|&n| n > 0));
    let mut fbuf = [0u8; 32 * 1024];
    let f = MemFlash::new(
        &mut fbuf[..],
        tribo_firmware::hal::FlashGeometry {
            sector_bytes: 4096,
            sectors: 8,
        },
    );
    let (mut r0, mut index) = ([0u8; 8 * 1024], [0u32; MAX_RUN_BLOCKS]);
    let mut store = RunStore::new([&mut r0[..]], &mut index);
    let mut hdr = [0u8; MAX_FRAME];
    let n = enc
        .encode(
            0,
            &DeviceMsg::RunStarted(RunHeader {
                run_id: 1,
                config: cfg,
                temp_c: 25.0,
                t_us: 0,
                clock,
            }),
            &mut hdr,
        )
        .map_or(0, |b| b.len());
    check!(store.begin(&f, 1, &hdr[..n]));
    let mut ok = true;
    let stored = cx.count(|| {
        for (k, (fr, &n)) in frames.iter().zip(lens.iter()).enumerate() {
            ok &= store.push_block(k as u32, &fr[..n]);
        }
    });
    check!(ok);
    let per = |v: Option<u64>| v.map(|v| v / (BLOCKS * BLOCK_LEN) as u64);
    let bytes: usize = lens.iter().sum();
    cx.note(format_args!(
        "a packed block frame of the record: {} bytes (raw counts: {} bytes)",
        bytes / BLOCKS,
        2 * 5 * BLOCK_LEN
    ));
    let figures = [
        ("parts.block_builder_per_sample", build),
        ("parts.pack_per_sample", pack),
        ("parts.framing_per_sample", framed),
        ("parts.store_push_per_sample", stored),
    ];
    let mut r = Ok(());
    for (name, v) in figures {
        r = r.and(cx.figure(name, per(v), "instructions/sample", None));
    }
    let framing_one = framed.map(|f| f / BLOCKS as u64);
    r.and(cx.figure("parts.worst_pack_step", worst_step, "instructions", None))
        .and(cx.figure(
            "parts.frame_one_packed_block",
            framing_one,
            "instructions",
            None,
        ))
}

/// What configuring the on-board analysis costs: `Pipeline::reset` (every Configure and Arm) and
/// the peak fitter's window table, rebuilt when the measured half-period changes by 0.1 %.
pub fn analysis_setup(cx: &mut Cx) -> Outcome {
    let cfg = Configure::real_rig(0.3);
    let p = Pipeline::new(&cfg);
    check!(p.is_ok());
    let Ok(mut p) = p else { return Ok(()) };
    let mut ok = true;
    let reset = cx.count(|| ok &= p.reset(&cfg).is_ok());
    check!(ok);
    let mut f = PeakFitter::new();
    let mut step = 0.017;
    let table = cx.count(|| {
        step *= 1.01;
        f.set_step(step)
    });
    check!(f.half_window() > 50);
    let r1 = cx.figure("parts.pipeline_reset", reset, "instructions", None);
    let r2 = cx.figure(
        "parts.peak_window_table_10kSps",
        table,
        "instructions",
        None,
    );
    r1.and(r2)
}

/// What a short run's peak refit costs (`peaks::arc`, a 10 kS/s, 27 Hz window: 117 samples): a
/// window sample read into the fit's moments (mean over the window), the heaviest of the later
/// stages, and the whole fit done at once.
pub fn peak_fit(cx: &mut Cx) -> Outcome {
    let step = 0.017;
    let mut f = ArcFitter::new();
    f.set_step(step);
    let half = f.half_window() as i32;
    let arc = |k: i32| {
        let th = (k as f64 - 0.23) * step;
        let kk = if th > 0.0 { 9000.0 } else { 11000.0 };
        let x = 30000.0 - kk * (1.0 - tribo_firmware::fit::cos(th)) + ((k * 7919) % 5) as f64;
        x as u16
    };
    for k in -half - 3..=half {
        f.push(arc(k));
    }
    let mut whole_fit = f.clone();
    check!(f.start(half as usize, 0.23) == Some(None));
    let (mut read, mut reads, mut worst_stage, mut stages) = (0u64, 0u64, 0u64, 0u64);
    let mut k = half;
    let mut done = None;
    while done.is_none() && k < 20 * half {
        k += 1;
        f.push(arc(k));
        let reading = f.is_reading();
        let c = cx.count(|| done = f.step(1));
        if let Some(c) = c {
            if reading {
                read += c;
                reads += 1;
            } else if c > 100 {
                worst_stage = worst_stage.max(c);
                stages += 1;
                cx.note(format_args!("stage {stages}: {c} instructions"));
            }
        }
    }
    check!(done.is_some(), "the fit never finished");
    let mut once = None;
    let whole = cx.count(|| {
        once = whole_fit.fit(0.23);
    });
    check!(once.is_some() && once == done, "{once:?} vs {done:?}");
    let counting = cx.counting();
    cx.note(format_args!(
        "{} window samples read, {} later stages (pushes that did more than 100 instructions)",
        reads, stages
    ));
    let r1 = cx.figure(
        "parts.peak_fit_per_window_sample",
        counting.then(|| read / reads.max(1)),
        "instructions",
        None,
    );
    let r2 = cx.figure(
        "parts.peak_fit_worst_stage",
        counting.then_some(worst_stage),
        "instructions",
        None,
    );
    let r3 = cx.figure("parts.peak_fit_at_once", whole, "instructions", None);
    r1.and(r2).and(r3)
}
