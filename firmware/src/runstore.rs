//! The whole run, kept: every frame of the last run in RAM and in flash, so that a host that lost
//! the cable, crashed, or found the rig power-cycled can still pull all of it.
//!
//! # What is kept, where
//!
//! A run is a sequence of *records*, each one wire frame exactly as it was (or will be) sent, with
//! its sequence number: the header, then the compressed sample blocks and the run's events (gaps,
//! ECR range changes) in the order they happened, then the result and the end. A record is the
//! frame's length (u16, little-endian) followed by the frame; the frame's own CRC-32 checks it.
//!
//! * **RAM**: a ring over a few large buffers (on the board: AXI SRAM, SRAM1–2, DTCM) holds the most
//!   recent records, the header, result and end are also kept apart. The live stream and pulls are
//!   sent from here, byte for byte.
//! * **Flash** (bank 2 on the board, behind [`RunFlash`]): the same records, written as they
//!   complete, in 32-byte flash words. A sector is erased just before the run needs it (erasing all
//!   of bank 2 takes ~9 s), and each run starts at the sector after the previous run's last one, so
//!   the wear is spread over the bank. When a run outgrows the flash, the flash keeps its beginning
//!   (a cut) and always its result and end (room is reserved for them); the RAM ring keeps its most
//!   recent part, and only records the ring had to drop before the flash took them are lost (each
//!   pull says which blocks it could not send). The cut's last partial flash word is kept aside,
//!   so the run may go on long after it (60 s at 20 kS/s fills the bank in ~18 s) and its flash
//!   copy still ends cleanly. A flash slower than the run (its unwritten bytes filling ¾ of the
//!   ring) is cut early the same way, at the first record it has not begun, rather than fail.
//! * **Run numbers**: between runs (a copy done, failed or off, and after a boot) the store erases
//!   the sector the next run starts at ahead of it, and the application sends `RunStarted` only
//!   once the header's flash words are programmed ([`RunStore::header_durable`]): a poll after the
//!   release (a release within 1.1 s of a boot waits for that erase). A number the host has seen is
//!   in flash, so no power cut, however many in a row, lets the rig give it again. Flash reads
//!   (pulls of a run held in flash only) wait while the erase ahead runs.
//! * **After a power loss** [`RunStore::recover`] finds the newest run in flash (the highest run id
//!   among the sectors that open with a valid header) and reads it back record by record, each frame
//!   checked (CRC, decoding, run id, block order); a torn or foreign record ends it there. The run is
//!   then served from flash.
//!
//! The application ([`crate::app`]) encodes each frame once, stores it here, and sends from here;
//! [`RunStore::service`] moves the flash along one operation per poll.

use crate::hal::{FlashGeometry, RunFlash, FLASH_MAX_PROGRAM, FLASH_WORD};
use crate::wire::frame::{decode_one, MAX_FRAME};
use crate::wire::{DeviceMsg, BLOCK_LEN};

mod flash;
pub mod memflash;
mod recover;
mod ring;

use flash::{read_image, Op, Writer};
use ring::Ring;

/// The RAM ring on the board, by buffer: 384 KiB of the AXI SRAM, SRAM1 and SRAM2 (128 KiB each),
/// and the 48 KiB of the DTCM the block index leaves (see `firmware/README.md` for the memory map).
/// 688 KiB: the last ~25 s of a five-channel run at 10 kS/s, and far more than the 2.2 s of data a
/// sector erase (at most) keeps waiting.
pub const BOARD_RING_BYTES: [usize; 4] = [384 * 1024, 128 * 1024, 128 * 1024, 48 * 1024];

/// Largest header, result or end frame (they are ~100 bytes).
pub const SLOT: usize = 256;
/// Blocks of the longest run the protocol allows (60 s at 20 kS/s): what the block index must hold.
pub const MAX_RUN_BLOCKS: usize = 60 * 20_000 / BLOCK_LEN + 1;
/// Bytes of a record's length prefix.
const LEN_BYTES: u32 = 2;
/// Flash room always kept free for the result and end records (and the last word's padding).
pub const FLASH_RESERVE: u32 = 2 * (LEN_BYTES + SLOT as u32) + FLASH_WORD as u32;

type Slot = heapless::Vec<u8, SLOT>;

/// What [`RunStore::read`] found at a position of the run's stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Read {
    /// A frame of `len` bytes was copied; the next record starts at `next`.
    Frame { len: usize, next: u32 },
    /// Held in flash only, and the flash is busy: ask again later.
    Busy,
    /// Neither in RAM nor in flash any more; `next` is the oldest position still held after it.
    Lost { next: u32 },
    /// Past the last record (so far).
    End,
}

/// What [`RunStore::recover`] found in flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Recovered {
    pub run_id: u32,
    pub blocks: u32,
    pub events: u32,
    /// The result and end records were there (the run finished before the power went).
    pub finished: bool,
}

/// How the flash copy of the current run is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FlashState {
    /// No run, or the flash has no room at all.
    Off,
    /// Records are being written as they come.
    Writing,
    /// Everything of the run that the flash keeps is written.
    Done,
    /// An erase or program failed, or the writer fell so far behind that the RAM ring had to drop
    /// records it had not written: nothing more of this run goes to flash.
    Failed,
}

/// The last run (see the module docs).
pub struct RunStore<'a> {
    ring: Ring<'a>,
    /// Stream position of each block's record.
    index: &'a mut [u32],
    header: Slot,
    result: Slot,
    end: Slot,
    run_id: Option<u32>,
    blocks: u32,
    events: u32,
    /// Blocks refused because the index was full (never the case with [`MAX_RUN_BLOCKS`]).
    refused: u32,
    writer: Writer,
    /// The sector of flash `.0` the next run starts at, erased ahead (`.2`: the erase is done),
    /// so that the run's header, and with it its number, is in flash within a poll or two of the
    /// release.
    ahead: Option<(FlashGeometry, u32, bool)>,
}

impl<'a> RunStore<'a> {
    /// A store over RAM `buffers` (taken as one ring) and a block `index` of [`MAX_RUN_BLOCKS`]
    /// entries (a shorter index keeps fewer blocks of a long run). The ring must hold what arrives
    /// while a sector is erased (up to 2.2 s of the stream), and at least two frames and a flash
    /// word, or the flash copy stops ([`FlashState::Failed`]) and the run lives in RAM only.
    pub fn new(buffers: impl IntoIterator<Item = &'a mut [u8]>, index: &'a mut [u32]) -> Self {
        RunStore {
            ring: Ring::new(buffers),
            index,
            header: Slot::new(),
            result: Slot::new(),
            end: Slot::new(),
            run_id: None,
            blocks: 0,
            events: 0,
            refused: 0,
            writer: Writer::OFF,
            ahead: None,
        }
    }

    /// Bytes of RAM the ring has.
    pub fn ram_capacity(&self) -> u32 {
        self.ring.cap
    }

    pub fn run_id(&self) -> Option<u32> {
        self.run_id
    }

    /// Blocks stored so far.
    pub fn blocks(&self) -> u32 {
        self.blocks
    }

    /// Events stored so far.
    pub fn events(&self) -> u32 {
        self.events
    }

    pub fn is_finished(&self) -> bool {
        !self.end.is_empty()
    }

    pub fn flash_state(&self) -> FlashState {
        self.writer.state
    }

    /// A sector of flash `g` that the held run's flash copy does not occupy and that the next
    /// run reaches last (the sector before the copy's first; the last sector when no run is
    /// held), for the self-test to erase and program; `None` when the copy fills every sector.
    pub fn spare_sector(&self, g: FlashGeometry) -> Option<u32> {
        if g.sectors == 0 {
            return None;
        }
        let (used, spare) = if self.writer.geometry != g {
            // No copy in this flash: the next run starts at sector 0.
            (0, g.sectors - 1)
        } else {
            (
                self.writer.sectors_used().max(self.writer.erased),
                (self.writer.start + g.sectors - 1) % g.sectors,
            )
        };
        // Nor the sector erased ahead for the next run.
        let ahead = self.ahead.is_some_and(|(ag, s, _)| ag == g && s == spare);
        (used < g.sectors && !ahead).then_some(spare)
    }

    /// Whether the run's header (and with it its run number) is in flash, or never will be (no
    /// usable flash, or the flash failed). The application holds `RunStarted` back until then, so
    /// that a number the host has seen survives any power cut and is never given again.
    pub fn header_durable(&self) -> bool {
        match self.writer.state {
            FlashState::Writing => self.writer.written >= self.first_pos(),
            _ => true,
        }
    }

    /// The header frame, if a run is held.
    pub fn header(&self) -> Option<&[u8]> {
        (!self.header.is_empty()).then_some(&self.header[..])
    }

    pub fn result(&self) -> Option<&[u8]> {
        (!self.result.is_empty()).then_some(&self.result[..])
    }

    pub fn end(&self) -> Option<&[u8]> {
        (!self.end.is_empty()).then_some(&self.end[..])
    }

    /// Stream position just past the last block or event.
    pub fn end_pos(&self) -> u32 {
        self.ring.hi
    }

    /// Stream position of the first record after the header.
    pub fn first_pos(&self) -> u32 {
        LEN_BYTES + self.header.len() as u32
    }

    /// Stream position of block `k`'s record.
    pub fn block_pos(&self, k: u32) -> Option<u32> {
        (k < self.blocks).then(|| self.index.get(k as usize).copied())?
    }

    /// The flash image end: where stream records stop being written (the cut) or the stream end.
    fn base(&self) -> u32 {
        self.writer.cut.unwrap_or(self.ring.hi)
    }

    /// The first record boundary at or after stream position `q` (the stream end if none): the
    /// start of the first block recorded there (events between blocks are not indexed; a block is
    /// never far).
    fn record_at_or_after(&self, q: u32) -> u32 {
        let n = self.blocks.min(self.index.len() as u32);
        let (mut lo, mut hi) = (0u32, n);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.index[mid as usize] >= q {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        if lo < n {
            self.index[lo as usize]
        } else {
            self.ring.hi
        }
    }

    /// Blocks whose record is in flash now (they survive a power loss).
    pub fn durable_blocks(&self) -> u32 {
        let limit = self.writer.written.min(self.base());
        // Blocks are in stream order: count those that end within the written image.
        let (mut lo, mut hi) = (0u32, self.blocks);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            let end = self
                .index
                .get(mid as usize + 1)
                .copied()
                .filter(|_| mid + 1 < self.blocks)
                .unwrap_or(self.ring.hi);
            if end <= limit {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// The first block whose record is still in RAM (`blocks()` if none).
    pub fn first_block_in_ram(&self) -> u32 {
        let (mut lo, mut hi) = (0u32, self.blocks);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self
                .index
                .get(mid as usize)
                .is_some_and(|&p| p >= self.ring.lo)
            {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        lo
    }

    /// Forgets the previous run (RAM and, sector by sector as the new one needs them, flash) and
    /// opens a new one with its header frame. False if the frame does not fit a slot.
    pub fn begin<F: RunFlash>(&mut self, flash: &F, run_id: u32, header: &[u8]) -> bool {
        let Ok(slot) = Slot::from_slice(header) else {
            return false;
        };
        let g = flash.flash_geometry();
        let usable = g.sector_bytes >= FLASH_WORD as u32
            && g.sector_bytes.is_multiple_of(FLASH_WORD as u32)
            && g.sectors > 0
            && g.bytes() > FLASH_RESERVE + 2 * MAX_FRAME as u32;
        let start = self.next_start(g);
        // The sector erased ahead counts as erased (or, its erase still running, as this run's).
        let ahead = self
            .ahead
            .take()
            .filter(|&(ag, s, _)| ag == g && s == start);
        let (erased, ahead_running) = match ahead {
            Some((_, _, true)) => (1, false),
            Some((_, _, false)) => (0, true),
            None => (0, false),
        };
        self.header = slot;
        self.result.clear();
        self.end.clear();
        self.run_id = Some(run_id);
        self.blocks = 0;
        self.events = 0;
        self.refused = 0;
        self.ring.reset(0);
        let inflight = self.writer.inflight.map(|op| match op {
            Op::Ahead if ahead_running => Op::Erase,
            _ => Op::Stale,
        });
        self.writer = Writer {
            geometry: g,
            start,
            state: if usable {
                FlashState::Writing
            } else {
                FlashState::Off
            },
            inflight,
            erased,
            ..Writer::OFF
        };
        // The header is the stream's first record.
        let mut rec = [0u8; LEN_BYTES as usize + SLOT];
        let n = self.header.len();
        rec[..2].copy_from_slice(&(n as u16).to_le_bytes());
        rec[2..2 + n].copy_from_slice(&self.header);
        self.make_room(2 + n as u32);
        self.ring.append(&rec[..2 + n]);
        true
    }

    /// The sector of flash `g` the next run's image starts at: after the sectors the held run's
    /// image used (wear spread over the bank), 0 with no run held in `g`.
    fn next_start(&self, g: FlashGeometry) -> u32 {
        if self.writer.geometry == g && g.sectors > 0 {
            (self.writer.start + self.writer.sectors_used()) % g.sectors
        } else {
            0
        }
    }

    /// Stores the next block's frame. False if it is not the next block or no run is open.
    pub fn push_block(&mut self, block: u32, frame: &[u8]) -> bool {
        if self.run_id.is_none() || self.is_finished() || block != self.blocks {
            return false;
        }
        let pos = self.ring.hi;
        if block as usize >= self.index.len() {
            self.refused += 1;
            return false;
        }
        if !self.push_record(frame) {
            return false;
        }
        self.index[block as usize] = pos;
        self.blocks += 1;
        true
    }

    /// Stores an event frame (gap, ECR range change, …) after the blocks stored so far.
    pub fn push_event(&mut self, frame: &[u8]) -> bool {
        if self.run_id.is_none() || self.is_finished() || !self.push_record(frame) {
            return false;
        }
        self.events += 1;
        true
    }

    /// Stores the result frame (once, before the end).
    pub fn set_result(&mut self, frame: &[u8]) -> bool {
        if self.run_id.is_none() || !self.result.is_empty() || self.is_finished() {
            return false;
        }
        match Slot::from_slice(frame) {
            Ok(s) => {
                self.result = s;
                true
            }
            Err(_) => false,
        }
    }

    /// Stores the end frame: the run is complete, and its flash image can be finished.
    pub fn set_end(&mut self, frame: &[u8]) -> bool {
        if self.run_id.is_none() || self.is_finished() {
            return false;
        }
        match Slot::from_slice(frame) {
            Ok(s) => {
                self.end = s;
                true
            }
            Err(_) => false,
        }
    }

    fn push_record(&mut self, frame: &[u8]) -> bool {
        if frame.is_empty()
            || frame.len() > MAX_FRAME
            || frame.len() as u32 + LEN_BYTES > self.ring.cap
        {
            return false;
        }
        let mut len = [0u8; 2];
        len.copy_from_slice(&(frame.len() as u16).to_le_bytes());
        // The flash keeps the run's beginning: once a record would eat into the room kept for the
        // result and end, the flash image stops before it.
        let need = LEN_BYTES + frame.len() as u32;
        let pos = self.ring.hi;
        if self.writer.cut.is_none() && pos + need + FLASH_RESERVE > self.writer.capacity() {
            self.set_cut(pos);
        }
        // A flash slower than the run: once the bytes it has not written fill ¾ of the ring, the
        // copy stops at the first record it has not begun, so that it ends cleanly (its beginning,
        // result and end) before the ring would drop what it still needs. The last quarter of the
        // ring is the room for that record and a sector erase (1.1 s of the stream at 57 kB/s is
        // 63 kB; the board's ring's quarter is 172 KiB).
        if self.writer.cut.is_none()
            && self.writer.state == FlashState::Writing
            && pos + need - self.writer.written > self.ring.cap / 4 * 3
        {
            let begun = self.writer.written
                + match self.writer.inflight {
                    Some(Op::Program { len }) => len,
                    _ => 0,
                };
            self.set_cut(self.record_at_or_after(begun));
        }
        self.make_room(need);
        self.ring.append(&len);
        self.ring.append(frame);
        true
    }

    /// Drops the oldest records until `need` more bytes fit.
    fn make_room(&mut self, need: u32) {
        while self.ring.hi - self.ring.lo + need > self.ring.cap {
            let Some(len) = self.ring.read_len(self.ring.lo) else {
                self.ring.lo = self.ring.hi;
                return;
            };
            let end = self.ring.lo + LEN_BYTES + len;
            // Bytes the flash still needs from RAM: `written..ram_image_end()`.
            let needed = self.writer.written..self.ram_image_end();
            let unwritten = !needed.is_empty() && end > needed.start && self.ring.lo < needed.end;
            if unwritten && self.writer.state == FlashState::Writing {
                // The flash fell behind by a whole ring: it will never catch up with this run.
                self.writer.state = FlashState::Failed;
            }
            self.ring.lo = end.min(self.ring.hi);
        }
    }

    /// Copies the record at stream position `pos` into `out` (from RAM if held there, else from
    /// flash).
    pub fn read<F: RunFlash>(&self, flash: &mut F, pos: u32, out: &mut [u8]) -> Read {
        if self.run_id.is_none() || pos >= self.ring.hi {
            return Read::End;
        }
        if let Some(len) = self.ring.read_len(pos) {
            let (len, next) = (len as usize, pos + LEN_BYTES + len);
            if len > out.len() || !self.ring.holds(pos, LEN_BYTES + len as u32) {
                return Read::Lost {
                    next: self.ring.lo.max(pos + 1),
                };
            }
            self.ring.read(pos + LEN_BYTES, &mut out[..len]);
            return Read::Frame { len, next };
        }
        // Not in RAM: in flash if the image holds it whole.
        let limit = self.writer.written.min(self.base());
        if pos + LEN_BYTES > limit {
            return Read::Lost {
                next: self.ring.lo.max(pos + 1),
            };
        }
        if flash.flash_busy() {
            return Read::Busy;
        }
        let mut b = [0u8; 2];
        if !read_image(flash, &self.writer, pos, &mut b) {
            return Read::Busy;
        }
        let len = u16::from_le_bytes(b) as usize;
        let next = pos + LEN_BYTES + len as u32;
        if len > out.len() || next > limit {
            return Read::Lost {
                next: self.ring.lo.max(pos + 1),
            };
        }
        if !read_image(flash, &self.writer, pos + LEN_BYTES, &mut out[..len]) {
            return Read::Busy;
        }
        Read::Frame { len, next }
    }

    /// Where a pull from block `k` starts: just after block `k − 1`, so that the events between the
    /// two come along. `None` while the flash that holds that block is busy.
    pub fn start_of_block<F: RunFlash>(&self, flash: &mut F, k: u32) -> Option<u32> {
        if k == 0 {
            return Some(self.first_pos());
        }
        let Some(prev) = self.block_pos(k - 1) else {
            return Some(self.ring.hi);
        };
        let mut buf = [0u8; MAX_FRAME];
        match self.read(flash, prev, &mut buf) {
            Read::Frame { next, .. } => Some(next),
            Read::Busy => None,
            Read::Lost { .. } | Read::End => Some(self.block_pos(k).unwrap_or(self.ring.hi)),
        }
    }
}

#[cfg(test)]
mod tests;
