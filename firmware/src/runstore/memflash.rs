//! An in-memory flash with the rules of the STM32H7's: erase by sector (to 0xFF), program whole
//! 32-byte words only once after an erase, nothing else while an operation runs, and operations
//! that take time. Used by the host tests and by the virtual rig, whose copy survives a rig reset
//! ("power loss"), torn operation included ([`MemFlash::power_cut`]).

use crate::hal::{FlashGeometry, RunFlash, FLASH_MAX_PROGRAM, FLASH_WORD};

/// Typical sector erase time of the STM32H743 (128 KiB, 32-bit parallelism): 1.1 s (datasheet:
/// 2.2 s at most).
pub const H743_ERASE_US: u64 = 1_100_000;
/// Assumed time to program one 256-bit flash word (the datasheet gives tens of µs).
pub const H743_WORD_US: u64 = 20;

/// Most sectors the model counts erases for.
const MAX_SECTORS: usize = 64;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pending {
    Erase { sector: u32 },
    Program { offset: u32, len: u32 },
}

/// The model (see the module docs). `B` holds the bytes: a `Vec<u8>`, a boxed or borrowed slice.
#[derive(Debug, Clone)]
pub struct MemFlash<B> {
    mem: B,
    geometry: FlashGeometry,
    now_us: u64,
    busy_until: u64,
    pending: Option<Pending>,
    error: bool,
    fail_next: bool,
    erase_us: u64,
    word_us: u64,
    erases: [u32; MAX_SECTORS],
    violations: u32,
    programmed_words: u64,
}

impl<B: AsRef<[u8]> + AsMut<[u8]>> MemFlash<B> {
    /// A flash over `mem` (its length must be `geometry.bytes()`; a shorter buffer limits the
    /// geometry to whole sectors of it), erased, whose operations finish at once.
    pub fn new(mut mem: B, geometry: FlashGeometry) -> Self {
        let have = mem.as_ref().len() as u32 / geometry.sector_bytes.max(1);
        let geometry = FlashGeometry {
            sector_bytes: geometry.sector_bytes,
            sectors: geometry.sectors.min(have).min(MAX_SECTORS as u32),
        };
        mem.as_mut().fill(0xFF);
        MemFlash {
            mem,
            geometry,
            now_us: 0,
            busy_until: 0,
            pending: None,
            error: false,
            fail_next: false,
            erase_us: 0,
            word_us: 0,
            erases: [0; MAX_SECTORS],
            violations: 0,
            programmed_words: 0,
        }
    }

    /// Operations take `erase_us` per sector and `word_us` per flash word of device time.
    pub fn with_timing(mut self, erase_us: u64, word_us: u64) -> Self {
        self.erase_us = erase_us;
        self.word_us = word_us;
        self
    }

    /// The STM32H743's typical timings ([`H743_ERASE_US`], [`H743_WORD_US`]).
    pub fn with_h743_timing(self) -> Self {
        self.with_timing(H743_ERASE_US, H743_WORD_US)
    }

    /// Device time is now `now_us` (operations finish by it).
    pub fn advance(&mut self, now_us: u64) {
        self.now_us = self.now_us.max(now_us);
        if self.now_us >= self.busy_until {
            self.pending = None;
        }
    }

    /// The power goes now: an operation under way is torn (half a sector erased, the last word of a
    /// program half written), and none is pending after.
    pub fn power_cut(&mut self) {
        if self.now_us < self.busy_until {
            match self.pending {
                Some(Pending::Erase { sector }) => {
                    let sb = self.geometry.sector_bytes as usize;
                    let start = sector as usize * sb;
                    // The half not yet erased holds garbage (the erase pulses were under way).
                    let mut x = 0x1234_5678u32 ^ sector;
                    for b in &mut self.mem.as_mut()[start + sb / 2..start + sb] {
                        x ^= x << 13;
                        x ^= x >> 17;
                        x ^= x << 5;
                        *b = x as u8;
                    }
                }
                Some(Pending::Program { offset, len }) => {
                    let last = (offset + len) as usize - FLASH_WORD;
                    for b in &mut self.mem.as_mut()[last + FLASH_WORD / 2..last + FLASH_WORD] {
                        *b = 0xFF;
                    }
                    // And a bit the ECC would have caught.
                    self.mem.as_mut()[last] ^= 0x10;
                }
                None => {}
            }
        }
        self.busy_until = self.now_us;
        self.pending = None;
        self.error = false;
    }

    /// The next erase or program will report a failure (and do nothing).
    pub fn fail_next_operation(&mut self) {
        self.fail_next = true;
    }

    /// The bytes of the flash.
    pub fn bytes(&self) -> &[u8] {
        &self.mem.as_ref()[..self.geometry.bytes() as usize]
    }

    /// Mutable bytes (to damage them on purpose).
    pub fn bytes_mut(&mut self) -> &mut [u8] {
        let n = self.geometry.bytes() as usize;
        &mut self.mem.as_mut()[..n]
    }

    /// Times sector `s` was erased.
    pub fn erase_count(&self, s: u32) -> u32 {
        self.erases.get(s as usize).copied().unwrap_or(0)
    }

    /// Calls that broke the flash's rules (programming a word twice, misaligned, across a
    /// sector…): the store must make none.
    pub fn violations(&self) -> u32 {
        self.violations
    }

    /// Flash words programmed so far.
    pub fn programmed_words(&self) -> u64 {
        self.programmed_words
    }

    fn refuse(&mut self) -> bool {
        self.violations += 1;
        false
    }

    fn busy(&self) -> bool {
        self.now_us < self.busy_until
    }
}

impl<B: AsRef<[u8]> + AsMut<[u8]>> RunFlash for MemFlash<B> {
    fn flash_geometry(&self) -> FlashGeometry {
        self.geometry
    }

    fn flash_busy(&mut self) -> bool {
        self.busy()
    }

    fn flash_erase(&mut self, sector: u32) -> bool {
        if self.busy() {
            return false;
        }
        if sector >= self.geometry.sectors {
            return self.refuse();
        }
        if core::mem::take(&mut self.fail_next) {
            self.error = true;
            return true;
        }
        let sb = self.geometry.sector_bytes as usize;
        let start = sector as usize * sb;
        self.mem.as_mut()[start..start + sb].fill(0xFF);
        self.erases[sector as usize] += 1;
        self.busy_until = self.now_us + self.erase_us;
        self.pending = Some(Pending::Erase { sector });
        true
    }

    fn flash_program(&mut self, offset: u32, data: &[u8]) -> bool {
        if self.busy() {
            return false;
        }
        let w = FLASH_WORD as u32;
        let len = data.len() as u32;
        let sb = self.geometry.sector_bytes;
        if !offset.is_multiple_of(w)
            || !len.is_multiple_of(w)
            || len == 0
            || len as usize > FLASH_MAX_PROGRAM
            || offset
                .checked_add(len)
                .is_none_or(|e| e > self.geometry.bytes())
            || offset / sb != (offset + len - 1) / sb
        {
            return self.refuse();
        }
        let range = offset as usize..(offset + len) as usize;
        if self.mem.as_ref()[range.clone()].iter().any(|&b| b != 0xFF) {
            // Not erased since last programmed: the H7 would leave words with broken ECC.
            return self.refuse();
        }
        if core::mem::take(&mut self.fail_next) {
            self.error = true;
            return true;
        }
        self.mem.as_mut()[range].copy_from_slice(data);
        self.programmed_words += (len / w) as u64;
        self.busy_until = self.now_us + self.word_us * (len / w) as u64;
        self.pending = Some(Pending::Program { offset, len });
        true
    }

    fn flash_read(&mut self, offset: u32, out: &mut [u8]) -> bool {
        if self.busy() {
            return false;
        }
        let Some(end) = offset.checked_add(out.len() as u32) else {
            return false;
        };
        if end > self.geometry.bytes() {
            return false;
        }
        out.copy_from_slice(&self.mem.as_ref()[offset as usize..end as usize]);
        true
    }

    fn flash_take_error(&mut self) -> bool {
        core::mem::take(&mut self.error)
    }
}
