//! The run store on the target: filled past its capacity, wrapped, read back.
//!
//! Written against today's `RunStore` API (small on purpose: the whole-run work is rewriting the
//! store, and this test should take minutes to adapt).

use crate::{check, check_eq, Cx, Outcome};
use tribo_firmware::runstore::{BlockMeta, Item, RunStore};
use tribo_firmware::wire::{
    ChannelSet, Configure, Counts, DeviceMsg, EndReason, RunEnd, RunHeader, SampleBlock, BLOCK_LEN,
};

/// Block `k` of a run with `channels`: counts that name their block and position.
fn block(k: u32, channels: ChannelSet, samples: usize) -> SampleBlock {
    let mut counts = Counts::default();
    for i in 0..samples * channels.len() {
        let _ = counts.push((k as u16).wrapping_mul(1000).wrapping_add(i as u16));
    }
    SampleBlock {
        run_id: 5,
        block: k,
        first_sample: k * BLOCK_LEN as u32,
        t_us: 6_400 * k as u64,
        channels,
        ecr_range: (k % 5) as u8,
        log10_ecr_ohm: k as f32 * 0.5,
        temp_c: 25.0 + k as f32,
        counts,
    }
}

/// Four blocks' worth of five-channel counts; ten blocks pushed: the last four are held, in
/// order, equal to what was pushed and with their sequence numbers; older ones are gone and a pull
/// from block 0 starts at the oldest held. A narrower (two-channel) run fits more blocks in the same
/// counts.
pub fn fills_wraps_and_reads_back(_cx: &mut Cx) -> Outcome {
    let mut counts = [0u16; 4 * BLOCK_LEN * 5];
    let mut meta = [BlockMeta::EMPTY; 10];
    let mut store = RunStore::new(&mut counts, &mut meta);
    let mut config = Configure::real_rig(0.3);
    config.channels = ChannelSet::ALL;
    let header = RunHeader {
        run_id: 5,
        config,
        temp_c: 25.0,
        t_us: 0,
    };
    store.begin(100, header);
    check_eq!(store.run_id(), Some(5));
    check_eq!(store.capacity_blocks(), 4);
    check_eq!(store.first_from(0), None, "nothing stored yet");
    for k in 0..10u32 {
        let n = if k == 9 { 10 } else { BLOCK_LEN };
        check!(store.push_block(101 + k, &block(k, ChannelSet::ALL, n)));
    }
    // out of order and wrong channels are refused
    check!(!store.push_block(200, &block(3, ChannelSet::ALL, BLOCK_LEN)));
    check!(!store.push_block(200, &block(10, ChannelSet::VIBROMETER, BLOCK_LEN)));
    check_eq!(store.blocks(), 10);
    check_eq!(store.oldest_block(), 6);
    for k in 0..6 {
        check!(store.block(k).is_none(), "block {k} should be overwritten");
    }
    for k in 6..10u32 {
        let n = if k == 9 { 10 } else { BLOCK_LEN };
        let got = store.block(k);
        check_eq!(
            got,
            Some((101 + k, block(k, ChannelSet::ALL, n))),
            "block {}",
            k
        );
    }
    check!(store.block(10).is_none());
    check_eq!(store.first_from(0), Some(Item::Block(6)));
    check_eq!(store.first_from(8), Some(Item::Block(8)));
    check_eq!(store.first_from(10), None, "no result yet");
    let end = RunEnd {
        run_id: 5,
        blocks: 10,
        samples: 9 * BLOCK_LEN as u32 + 10,
        overruns: 0,
        reason: EndReason::Stopped,
    };
    store.set_end(112, end);
    check!(store.is_finished());
    check_eq!(store.first_from(10), Some(Item::End));
    check_eq!(
        store.frame(Item::End),
        Some((112, DeviceMsg::RunEnded(end)))
    );
    check_eq!(
        store.frame(Item::Header),
        Some((100, DeviceMsg::RunStarted(header)))
    );

    // A new run forgets the old one; two channels fit 2.5× the blocks (capped by the metadata).
    let mut narrow = header;
    narrow.run_id = 6;
    narrow.config.channels = ChannelSet::VIBROMETER;
    store.begin(300, narrow);
    check_eq!(store.blocks(), 0);
    check!(!store.is_finished());
    check_eq!(store.capacity_blocks(), 10);
    for k in 0..25u32 {
        let mut b = block(k, ChannelSet::VIBROMETER, BLOCK_LEN);
        b.run_id = 6;
        check!(store.push_block(301 + k, &b));
    }
    check_eq!(store.oldest_block(), 15);
    for k in 15..25u32 {
        let mut b = block(k, ChannelSet::VIBROMETER, BLOCK_LEN);
        b.run_id = 6;
        check_eq!(store.block(k), Some((301 + k, b)), "narrow block {}", k);
    }
    Ok(())
}
