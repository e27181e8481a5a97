//! The flash copy of the run: its image (the stream's records up to the cut, then the result and
//! end records) laid out sector by sector on bank 2, and the writer that moves it along one
//! erase or program per poll.

use super::*;

/// The operation the flash is running for the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Op {
    Erase,
    Program {
        len: u32,
    },
    /// Started for an earlier run: its outcome no longer matters.
    Stale,
    /// The erase ahead of the sector the next run starts at (see [`super::RunStore::service`]).
    Ahead,
}

/// The run's flash image: the stream's records up to `cut` (all of them if none), then the result
/// and end records, laid out from sector `start` on, wrapping around the bank.
#[derive(Debug, Clone, Copy)]
pub(super) struct Writer {
    pub(super) geometry: FlashGeometry,
    pub(super) start: u32,
    /// Sectors of the image erased so far.
    pub(super) erased: u32,
    /// Bytes of the image programmed so far (whole words, except after recovery).
    pub(super) written: u32,
    pub(super) cut: Option<u32>,
    /// The cut's last, partial flash word (the image bytes from the word boundary below the cut
    /// to the cut), kept here when the cut is taken: RAM may drop the records around the cut
    /// long before the run ends and the word can be programmed.
    pub(super) cut_word: [u8; FLASH_WORD],
    pub(super) state: FlashState,
    pub(super) inflight: Option<Op>,
}

impl Writer {
    pub(super) const OFF: Writer = Writer {
        geometry: FlashGeometry {
            sector_bytes: 0,
            sectors: 0,
        },
        start: 0,
        erased: 0,
        written: 0,
        cut: None,
        cut_word: [0xFF; FLASH_WORD],
        state: FlashState::Off,
        inflight: None,
    };

    pub(super) fn capacity(&self) -> u32 {
        self.geometry.bytes()
    }

    /// Flash offset of image position `q`.
    pub(super) fn phys(&self, q: u32) -> u32 {
        let sb = self.geometry.sector_bytes.max(1);
        let sectors = self.geometry.sectors.max(1);
        ((self.start + q / sb) % sectors) * sb + q % sb
    }

    /// Sectors the image occupies once `written` bytes are in.
    pub(super) fn sectors_used(&self) -> u32 {
        self.written.div_ceil(self.geometry.sector_bytes.max(1))
    }
}

/// Reads image bytes `q..` from flash, across the wrap of the bank.
pub(super) fn read_image<F: RunFlash>(flash: &mut F, w: &Writer, q: u32, out: &mut [u8]) -> bool {
    let sb = w.geometry.sector_bytes;
    if sb == 0 {
        return false;
    }
    let mut done = 0;
    while done < out.len() {
        let at = q + done as u32;
        let n = ((sb - at % sb) as usize).min(out.len() - done);
        if !flash.flash_read(w.phys(at), &mut out[done..done + n]) {
            return false;
        }
        done += n;
    }
    true
}

impl RunStore<'_> {
    /// Bytes of the flash image: the stream up to the cut, then the result and end records.
    pub(super) fn image_len(&self) -> u32 {
        let tail = if self.is_finished() {
            2 * LEN_BYTES + self.result.len() as u32 + self.end.len() as u32
        } else {
            0
        };
        self.base() + tail
    }

    /// Ends the flash image's stream at `pos`, a record boundary at or after every byte the flash
    /// has programmed or is programming, whose records are in RAM: the flash keeps the records
    /// before it, then the result and end. The cut's partial last word is kept aside
    /// ([`Writer::cut_word`]).
    pub(super) fn set_cut(&mut self, pos: u32) {
        self.writer.cut = Some(pos);
        let floor = self.ram_image_end();
        let mut word = [0xFF; FLASH_WORD];
        let n = pos - floor;
        if n == 0 {
            // The cut is on a word boundary: nothing to keep aside.
        } else if self.ring.holds(floor, n) {
            self.ring.read(floor, &mut word[..n as usize]);
        } else if self.writer.state == FlashState::Writing {
            // Cannot happen while the copy is on (RAM drops no byte the flash still needs without
            // stopping it); were it so, the image would have a hole: stop rather than write one.
            self.writer.state = FlashState::Failed;
        }
        self.writer.cut_word = word;
    }

    /// End of the image bytes that only RAM holds until the flash has them: the stream end, or
    /// the word boundary below the cut (the rest of that word is in [`Writer::cut_word`]).
    pub(super) fn ram_image_end(&self) -> u32 {
        match self.writer.cut {
            Some(c) => c / FLASH_WORD as u32 * FLASH_WORD as u32,
            None => self.ring.hi,
        }
    }

    /// Copies image bytes `q..q + out.len()` (0xFF past its end). False if some are not in RAM.
    pub(super) fn image_bytes(&self, q: u32, out: &mut [u8]) -> bool {
        let base = self.base();
        let word_at = self.ram_image_end();
        let mut done = 0usize;
        while done < out.len() {
            let at = q + done as u32;
            if at < base && at >= word_at {
                // The cut's last word, kept aside.
                let (o, n) = (
                    (at - word_at) as usize,
                    ((base - at) as usize).min(out.len() - done),
                );
                out[done..done + n].copy_from_slice(&self.writer.cut_word[o..o + n]);
                done += n;
            } else if at < base {
                let n = ((word_at - at) as usize).min(out.len() - done);
                if !self.ring.holds(at, n as u32) {
                    return false;
                }
                self.ring.read(at, &mut out[done..done + n]);
                done += n;
            } else {
                // The tail: [len][result][len][end].
                let r = self.result.len();
                let e = self.end.len();
                let off = (at - base) as usize;
                out[done] = match off {
                    0 | 1 => (r as u16).to_le_bytes()[off],
                    o if o < 2 + r => self.result[o - 2],
                    o if o < 4 + r => (e as u16).to_le_bytes()[o - 2 - r],
                    o if o < 4 + r + e => self.end[o - 4 - r],
                    _ => 0xFF,
                };
                done += 1;
            }
        }
        true
    }

    /// Between runs (the copy done, failed or off), erases the sector the next run starts at, so
    /// that the run's header reaches flash a poll or two after the release rather than a sector
    /// erase (1.1 s) later: `RunStarted` waits for it ([`super::RunStore::header_durable`]).
    fn erase_ahead<F: RunFlash>(&mut self, flash: &mut F) {
        let g = flash.flash_geometry();
        let usable = g.sector_bytes >= FLASH_WORD as u32
            && g.sector_bytes.is_multiple_of(FLASH_WORD as u32)
            && g.sectors > 0;
        if !usable || self.writer.inflight.is_some() {
            return;
        }
        // Never a sector the held run's copy occupies (a copy that fills the bank: the next run
        // erases it when it starts, and its RunStarted waits for that erase).
        if self.writer.geometry == g
            && self.writer.sectors_used().max(self.writer.erased) >= g.sectors
        {
            return;
        }
        let sector = self.next_start(g);
        if self.ahead.is_some_and(|(ag, s, _)| ag == g && s == sector) {
            return;
        }
        if flash.flash_erase(sector) {
            self.ahead = Some((g, sector, false));
            self.writer.inflight = Some(Op::Ahead);
        } else {
            self.ahead = None;
        }
    }

    /// Moves the flash copy along: at most one erase or program is started per call.
    pub fn service<F: RunFlash>(&mut self, flash: &mut F) {
        if flash.flash_busy() {
            return;
        }
        if let Some(op) = self.writer.inflight.take() {
            let failed = flash.flash_take_error();
            match op {
                Op::Stale => {}
                // An erase ahead that failed is only not ahead: the run erases it again.
                Op::Ahead => {
                    self.ahead = self.ahead.filter(|_| !failed).map(|(g, s, _)| (g, s, true))
                }
                _ if failed => {
                    self.writer.state = FlashState::Failed;
                    return;
                }
                Op::Erase => self.writer.erased += 1,
                Op::Program { len } => self.writer.written += len,
            }
        }
        if self.writer.state != FlashState::Writing {
            self.erase_ahead(flash);
            return;
        }
        let w = FLASH_WORD as u32;
        let image = self.image_len();
        let avail = if self.is_finished() {
            image.div_ceil(w) * w
        } else {
            image / w * w
        };
        let written = self.writer.written;
        if written >= avail {
            if self.is_finished() {
                self.writer.state = FlashState::Done;
            }
            return;
        }
        let sb = self.writer.geometry.sector_bytes;
        let sector = written / sb;
        if sector >= self.writer.geometry.sectors {
            // Cannot happen (the cut keeps the image inside the bank); stop rather than wrap.
            self.writer.state = FlashState::Failed;
            return;
        }
        if sector >= self.writer.erased {
            let phys = (self.writer.start + self.writer.erased) % self.writer.geometry.sectors;
            if flash.flash_erase(phys) {
                self.writer.inflight = Some(Op::Erase);
            } else {
                self.writer.state = FlashState::Failed;
            }
            return;
        }
        let n = (avail - written)
            .min((sector + 1) * sb - written)
            .min(FLASH_MAX_PROGRAM as u32);
        let mut buf = [0xFFu8; FLASH_MAX_PROGRAM];
        if !self.image_bytes(written, &mut buf[..n as usize]) {
            self.writer.state = FlashState::Failed;
            return;
        }
        if flash.flash_program(self.writer.phys(written), &buf[..n as usize]) {
            self.writer.inflight = Some(Op::Program { len: n });
        } else {
            self.writer.state = FlashState::Failed;
        }
    }
}
