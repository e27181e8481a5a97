//! The last run, kept in RAM so that a host that connected late or lost the cable can pull it again.
//!
//! What is kept: the run's header, result and end frames always; its sample blocks in a ring of
//! whole blocks over a caller-provided count buffer, so the *most recent* blocks that fit are held
//! (on the board: [`BOARD_COUNTS`] = 72 Ki counts, i.e. the last 1.47 s of a run with all five
//! channels at 10 kS/s, the last 3.7 s of a displacement + velocity run; see `firmware/README.md`).
//! A run that fits is held entirely. Each frame keeps the sequence number it was first sent with, so a replay is
//! byte-for-byte the original frame.
//!
//! Blocks are rebuilt from their counts and a few bytes of per-block metadata instead of being
//! stored encoded, which keeps ~2 bytes per count.

use crate::wire::{
    ChannelSet, Counts, DeviceMsg, EcrRangeChange, Gap, OnboardResult, RunEnd, RunHeader,
    SampleBlock, BLOCK_LEN,
};

/// Counts the board keeps for the last run (144 KiB of the 256 KiB static RAM budget): the last 1.47 s
/// of a five-channel run at 10 kS/s, 1.84 s with four channels, 3.7 s with displacement + velocity.
pub const BOARD_COUNTS: usize = 72 * 1024;
/// Block slots the board keeps: enough for the narrowest run (two channels) filling [`BOARD_COUNTS`].
pub const BOARD_BLOCKS: usize = BOARD_COUNTS / (2 * BLOCK_LEN);

/// Per-block data not in the counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockMeta {
    pub seq: u32,
    /// Index in the run of the block's first sample (blocks after a gap start further on than
    /// `block × BLOCK_LEN`).
    pub first_sample: u32,
    pub t_us: u64,
    pub ecr_range: u8,
    pub log10_ecr_ohm: f32,
    pub temp_c: f32,
    /// Number of counts (less than a full block only for the last one).
    pub len: u16,
}

impl BlockMeta {
    pub const EMPTY: BlockMeta = BlockMeta {
        seq: 0,
        first_sample: 0,
        t_us: 0,
        ecr_range: 0,
        log10_ecr_ohm: 0.0,
        temp_c: 0.0,
        len: 0,
    };
}

impl Default for BlockMeta {
    fn default() -> Self {
        Self::EMPTY
    }
}

/// The stored run (see the module docs).
pub struct RunStore<'a> {
    counts: &'a mut [u16],
    meta: &'a mut [BlockMeta],
    header: Option<(u32, RunHeader)>,
    result: Option<(u32, OnboardResult)>,
    end: Option<(u32, RunEnd)>,
    channels: ChannelSet,
    /// Block slots available for this run.
    slots: usize,
    /// Blocks pushed so far.
    blocks: u32,
    /// The run's events (see [`RunEvent`]).
    events: heapless::Vec<StoredEvent, MAX_EVENTS>,
}

// ---- Run events -----------------------------------------------------------------------------------
// Self-contained on purpose (the block storage around it may change): a short list of run frames
// that are not sample blocks, each kept whole with its sequence number and its place among the
// blocks, so that the live stream and a Pull send them in the same order, byte for byte.

/// Most events a run keeps: a run that would need more is ended by the application (a gap) or
/// stops autoranging (an ECR range change), see `app.rs`.
pub const MAX_EVENTS: usize = 128;

/// A run frame that is not a sample block: what the acquisition reports about the samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RunEvent {
    /// Samples that were lost (acquisition overrun).
    Gap(Gap),
    /// The ECR range changed (and its settling samples).
    EcrRange(EcrRangeChange),
}

impl RunEvent {
    pub fn to_msg(self) -> DeviceMsg {
        match self {
            RunEvent::Gap(g) => DeviceMsg::Gap(g),
            RunEvent::EcrRange(e) => DeviceMsg::EcrRange(e),
        }
    }
}

/// An event as stored: its frame's sequence number, and the number of blocks stored before it
/// (it is sent after those blocks and before the next).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoredEvent {
    pub seq: u32,
    pub before_block: u32,
    pub event: RunEvent,
}

/// One item of a stored run, in the order it is sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    Header,
    Block(u32),
    /// Event `.0` of the run, in the order pushed.
    Event(u32),
    Result,
    End,
}

impl<'a> RunStore<'a> {
    /// A store over `counts` (block data) and `meta` (one entry per block slot; it needs no more than
    /// `counts.len() / (2 * BLOCK_LEN)` entries since every run has at least two channels).
    pub fn new(counts: &'a mut [u16], meta: &'a mut [BlockMeta]) -> Self {
        RunStore {
            counts,
            meta,
            header: None,
            result: None,
            end: None,
            channels: ChannelSet::EMPTY,
            slots: 0,
            blocks: 0,
            events: heapless::Vec::new(),
        }
    }

    /// Forgets the previous run and opens a new one.
    pub fn begin(&mut self, seq: u32, header: RunHeader) {
        let width = header.config.channels.len().max(1);
        self.channels = header.config.channels;
        self.slots = (self.counts.len() / (width * BLOCK_LEN)).min(self.meta.len());
        self.blocks = 0;
        self.header = Some((seq, header));
        self.result = None;
        self.end = None;
        self.events.clear();
    }

    pub fn run_id(&self) -> Option<u32> {
        self.header.as_ref().map(|h| h.1.run_id)
    }

    /// Blocks pushed so far (held or not).
    pub fn blocks(&self) -> u32 {
        self.blocks
    }

    /// Index of the oldest block still held.
    pub fn oldest_block(&self) -> u32 {
        self.blocks.saturating_sub(self.slots as u32)
    }

    /// How many blocks of this run the store can hold.
    pub fn capacity_blocks(&self) -> usize {
        self.slots
    }

    pub fn is_finished(&self) -> bool {
        self.end.is_some()
    }

    /// Stores a block (the next in order; others are refused).
    pub fn push_block(&mut self, seq: u32, b: &SampleBlock) -> bool {
        let width = self.channels.len();
        if self.header.is_none()
            || self.slots == 0
            || b.block != self.blocks
            || b.channels != self.channels
            || width == 0
        {
            return false;
        }
        let slot = (b.block as usize) % self.slots;
        let span = width * BLOCK_LEN;
        let n = b.counts.len().min(span);
        self.counts[slot * span..slot * span + n].copy_from_slice(&b.counts[..n]);
        self.meta[slot] = BlockMeta {
            seq,
            first_sample: b.first_sample,
            t_us: b.t_us,
            ecr_range: b.ecr_range,
            log10_ecr_ohm: b.log10_ecr_ohm,
            temp_c: b.temp_c,
            len: n as u16,
        };
        self.blocks += 1;
        true
    }

    pub fn set_result(&mut self, seq: u32, r: OnboardResult) {
        self.result = Some((seq, r));
    }

    pub fn set_end(&mut self, seq: u32, e: RunEnd) {
        self.end = Some((seq, e));
    }

    /// Block `k` as first sent, with its sequence number, if held.
    pub fn block(&self, k: u32) -> Option<(u32, SampleBlock)> {
        let (_, h) = self.header.as_ref()?;
        if k >= self.blocks || k < self.oldest_block() {
            return None;
        }
        let slot = (k as usize) % self.slots;
        let span = self.channels.len() * BLOCK_LEN;
        let m = self.meta[slot];
        let counts = Counts::from_slice(&self.counts[slot * span..slot * span + m.len as usize])?;
        Some((
            m.seq,
            SampleBlock {
                run_id: h.run_id,
                block: k,
                first_sample: m.first_sample,
                t_us: m.t_us,
                channels: self.channels,
                ecr_range: m.ecr_range,
                log10_ecr_ohm: m.log10_ecr_ohm,
                temp_c: m.temp_c,
                counts,
            },
        ))
    }

    /// The frame (sequence number and message) of `item`, if it exists yet.
    pub fn frame(&self, item: Item) -> Option<(u32, DeviceMsg)> {
        match item {
            Item::Header => self.header.map(|(s, h)| (s, DeviceMsg::RunStarted(h))),
            Item::Block(k) => self.block(k).map(|(s, b)| (s, DeviceMsg::Samples(b))),
            Item::Event(i) => self
                .events
                .get(i as usize)
                .map(|e| (e.seq, e.event.to_msg())),
            Item::Result => self.result.map(|(s, r)| (s, DeviceMsg::Result(r))),
            Item::End => self.end.map(|(s, e)| (s, DeviceMsg::RunEnded(e))),
        }
    }

    /// Stores an event of the run in progress, after the blocks stored so far. False (nothing
    /// stored) when no run is open or the event list is full.
    pub fn push_event(&mut self, seq: u32, event: RunEvent) -> bool {
        if self.header.is_none() || self.end.is_some() {
            return false;
        }
        self.events
            .push(StoredEvent {
                seq,
                before_block: self.blocks,
                event,
            })
            .is_ok()
    }

    /// Events stored for this run.
    pub fn events(&self) -> &[StoredEvent] {
        &self.events
    }

    /// Room left for events.
    pub fn events_free(&self) -> usize {
        MAX_EVENTS - self.events.len()
    }

    /// What to send next when blocks before `block` and events before `event` were sent: event
    /// `event` if it comes before block `block` (or before the oldest block still held), else that
    /// block, else the result and the end once they exist.
    pub fn next_item(&self, block: u32, event: u32) -> Option<Item> {
        let block = block.max(self.oldest_block());
        if let Some(e) = self.events.get(event as usize) {
            if e.before_block <= block {
                return Some(Item::Event(event));
            }
        }
        self.first_from(block)
    }

    /// The first item at or after block `k` that exists now.
    pub fn first_from(&self, k: u32) -> Option<Item> {
        let k = k.max(self.oldest_block());
        if k < self.blocks {
            Some(Item::Block(k))
        } else if self.result.is_some() {
            Some(Item::Result)
        } else if self.end.is_some() {
            Some(Item::End)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{Configure, SampleClock};

    fn header() -> RunHeader {
        RunHeader {
            run_id: 3,
            config: Configure::real_rig(0.3),
            temp_c: 25.0,
            t_us: 0,
            clock: SampleClock::exact(10_000),
        }
    }

    fn block(k: u32, first: u32) -> SampleBlock {
        let ch = Configure::real_rig(0.3).channels;
        let mut counts = Counts::default();
        for i in 0..ch.len() * 3 {
            let _ = counts.push(i as u16);
        }
        SampleBlock {
            run_id: 3,
            block: k,
            first_sample: first,
            t_us: first as u64 * 100,
            channels: ch,
            ecr_range: 1,
            log10_ecr_ohm: 7.0,
            temp_c: 25.0,
            counts,
        }
    }

    /// Everything a sender starting at (`block`, `event`) sends, in order.
    fn send_all(st: &RunStore, mut block: u32, mut event: u32) -> Vec<DeviceMsg> {
        let mut out = Vec::new();
        while let Some(item) = st.next_item(block, event) {
            out.push(st.frame(item).unwrap().1);
            match item {
                Item::Event(e) => event = e + 1,
                Item::Block(k) => block = k + 1,
                Item::Result | Item::End | Item::Header => break,
            }
        }
        out
    }

    #[test]
    fn events_keep_their_place_among_the_blocks_and_their_first_samples() {
        let mut c = vec![0u16; 10_000];
        let mut m = vec![BlockMeta::EMPTY; 40];
        let mut st = RunStore::new(&mut c, &mut m);
        assert!(!st.push_event(
            1,
            RunEvent::Gap(Gap {
                run_id: 3,
                first_sample: 0,
                count: 1
            })
        ));
        st.begin(10, header());
        let range = |first| {
            RunEvent::EcrRange(EcrRangeChange {
                run_id: 3,
                first_sample: first,
                range: 2,
                settling: 3,
            })
        };
        assert!(st.push_event(11, range(0)));
        assert!(st.push_block(12, &block(0, 0)));
        assert!(st.push_event(
            13,
            RunEvent::Gap(Gap {
                run_id: 3,
                first_sample: 3,
                count: 40
            })
        ));
        assert!(st.push_block(14, &block(1, 43)));
        assert!(st.push_event(15, range(50)));
        let order: Vec<String> = send_all(&st, 0, 0)
            .iter()
            .map(|m| match m {
                DeviceMsg::Samples(b) => format!("b{}@{}", b.block, b.first_sample),
                DeviceMsg::Gap(g) => format!("gap{}+{}", g.first_sample, g.count),
                DeviceMsg::EcrRange(e) => format!("r{}", e.first_sample),
                other => format!("{other:?}"),
            })
            .collect();
        assert_eq!(order, ["r0", "b0@0", "gap3+40", "b1@43", "r50"]);
        // A pull from block 1 still sends every event first that belongs before block 1.
        let from1 = send_all(&st, 1, 0);
        assert_eq!(from1.len(), 4);
        assert!(matches!(from1[2], DeviceMsg::Samples(ref b) if b.block == 1));
        // Sequence numbers are the ones the events were stored with.
        assert_eq!(st.frame(Item::Event(1)).map(|f| f.0), Some(13));
        // A new run forgets the old events.
        st.begin(20, header());
        assert!(st.events().is_empty() && st.next_item(0, 0).is_none());
        // A full list refuses, and says so.
        for i in 0..MAX_EVENTS as u32 {
            assert!(st.push_event(i, range(i)));
        }
        assert_eq!(st.events_free(), 0);
        assert!(!st.push_event(0, range(0)));
    }
}
