//! Costs of the pieces of the per-sample path on the target (figures only): assembling blocks,
//! storing them, framing them.

use crate::{check, Cx, Outcome};
use tribo_firmware::acquisition::BlockBuilder;
use tribo_firmware::analysis::Pipeline;
use tribo_firmware::hal::ANALOG_CHANNELS;
use tribo_firmware::peaks::PeakFitter;
use tribo_firmware::runstore::{BlockMeta, Item, RunStore};
use tribo_firmware::wire::frame::MAX_FRAME;
use tribo_firmware::wire::{
    Channel, ChannelSet, Configure, DeviceMsg, Encoder, RunHeader, BLOCK_LEN,
};

/// Per sample, on the counts of the `coulomb_viscous` record (five channels, the temperature from
/// the thermocouple as the application does): `BlockBuilder::push`, `RunStore::push_block`, the
/// block rebuilt from the store (`RunStore::frame`), its framing (`Encoder::encode`).
pub fn block_path(cx: &mut Cx) -> Outcome {
    let rec = cx.bundle()?.record("coulomb_viscous");
    check!(rec.is_some(), "no coulomb_viscous record");
    let Some(rec) = rec else { return Ok(()) };
    let cfg = rec.configure;
    let mut b = BlockBuilder::new(
        1,
        ChannelSet::ALL,
        cfg.calibration[Channel::Temperature.index()],
    );
    const BLOCKS: usize = 4;
    let mut samples = [[0u16; ANALOG_CHANNELS]; BLOCKS * BLOCK_LEN];
    for (k, s) in samples.iter_mut().enumerate() {
        s.copy_from_slice(&rec.sample(rec.hold as usize + 500 + k)[..ANALOG_CHANNELS]);
    }
    let mut blocks = heapless::Vec::<_, BLOCKS>::new();
    let build = cx.count(|| {
        for (k, s) in samples.iter().enumerate() {
            if let Some(blk) = b.push(s, crate::tests::app::TEMP_C, 100 * k as u64) {
                let _ = blocks.push(blk);
            }
        }
    });
    check!(blocks.len() == BLOCKS);
    let mut counts = [0u16; 8 * BLOCK_LEN * 5];
    let mut meta = [BlockMeta::EMPTY; 8];
    let mut store = RunStore::new(&mut counts, &mut meta);
    store.begin(
        0,
        RunHeader {
            run_id: 1,
            config: cfg,
            temp_c: 25.0,
            t_us: 0,
        },
    );
    let mut ok = true;
    let stored = cx.count(|| {
        for (k, blk) in blocks.iter().enumerate() {
            ok &= store.push_block(k as u32 + 1, blk);
        }
    });
    check!(ok);
    let mut msgs = heapless::Vec::<(u32, DeviceMsg), BLOCKS>::new();
    let rebuilt = cx.count(|| {
        for k in 0..BLOCKS as u32 {
            if let Some(f) = store.frame(Item::Block(k)) {
                let _ = msgs.push(f);
            }
        }
    });
    check!(msgs.len() == BLOCKS);
    let mut enc = Encoder::new();
    let mut out = [0u8; MAX_FRAME];
    let mut n = 0;
    let framed = cx.count(|| {
        for (seq, msg) in &msgs {
            n += enc.encode(*seq, msg, &mut out).map_or(0, |b| b.len());
        }
    });
    check!(n > 0);
    // the three steps of framing, on the first block
    let mut body = [0u8; MAX_FRAME];
    let mut len = 0;
    let ser = cx.count(|| len = postcard::to_slice(&msgs[0].1, &mut body).map_or(0, |b| b.len()));
    let mut crc = 0;
    let crc_cost = cx.count(|| crc = tribo_firmware::wire::crc32::crc32(&body[..len]));
    let mut stuffed = [0u8; MAX_FRAME + 8];
    let mut m = None;
    let cobs =
        cx.count(|| m = tribo_firmware::wire::frame::cobs_encode(&body[..len], &mut stuffed));
    check!(crc != 0 && m.is_some());
    cx.note(format_args!(
        "framing one block: postcard {:?}, CRC {:?}, COBS {:?} instructions; {} zero bytes in {len}",
        ser,
        crc_cost,
        cobs,
        body[..len].iter().filter(|&&b| b == 0).count()
    ));
    let per = |v: Option<u64>| v.map(|v| v / (BLOCKS * BLOCK_LEN) as u64);
    cx.note(format_args!(
        "a block frame of the record: {} bytes",
        n / BLOCKS
    ));
    let figures = [
        ("parts.block_builder_per_sample", build),
        ("parts.store_push_per_sample", stored),
        ("parts.block_from_store_per_sample", rebuilt),
        ("parts.framing_per_sample", framed),
    ];
    let mut r = Ok(());
    for (name, v) in figures {
        r = r.and(cx.figure(name, per(v), "instructions/sample", None));
    }
    r
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
