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
    ChannelSet, Counts, DeviceMsg, OnboardResult, RunEnd, RunHeader, SampleBlock, SamplesRef,
    BLOCK_LEN,
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
}

/// One item of a stored run, in the order it is sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Item {
    Header,
    Block(u32),
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
                first_sample: k * BLOCK_LEN as u32,
                t_us: m.t_us,
                channels: self.channels,
                ecr_range: m.ecr_range,
                log10_ecr_ohm: m.log10_ecr_ohm,
                temp_c: m.temp_c,
                counts,
            },
        ))
    }

    /// Block `k` as [`RunStore::block`] gives it, borrowed: it frames to the same bytes without
    /// copying the counts out of the store (what the application sends).
    pub fn samples_ref(&self, k: u32) -> Option<(u32, SamplesRef<'_>)> {
        let (_, h) = self.header.as_ref()?;
        if k >= self.blocks || k < self.oldest_block() {
            return None;
        }
        let slot = (k as usize) % self.slots;
        let span = self.channels.len() * BLOCK_LEN;
        let m = self.meta.get(slot)?;
        let counts = self.counts.get(slot * span..slot * span + m.len as usize)?;
        Some((
            m.seq,
            SamplesRef {
                run_id: h.run_id,
                block: k,
                first_sample: k * BLOCK_LEN as u32,
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
            Item::Result => self.result.map(|(s, r)| (s, DeviceMsg::Result(r))),
            Item::End => self.end.map(|(s, e)| (s, DeviceMsg::RunEnded(e))),
        }
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
