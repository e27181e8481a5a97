//! Bank 2 for the run store: the application asks ([`RunFlash`] on [`BoardHw`]), the flash task
//! erases and programs, one operation at a time, awaiting the flash interrupt ([`FlashLink`]).

use super::*;

/// An operation on bank 2, asked by the application, run by the flash task.
// The program variant carries its bytes: the op lives in one static signal slot, and there is no
// heap to box into, so the slot is the size of the largest variant either way.
#[allow(clippy::large_enum_variant)]
#[derive(Clone)]
pub(super) enum FlashOp {
    Erase {
        sector: u32,
    },
    Program {
        offset: u32,
        len: usize,
        data: [u8; FLASH_MAX_PROGRAM],
    },
}

/// Bank 2 between the application (which asks and reads) and the flash task (which erases and
/// programs, awaiting the flash interrupt).
pub(super) struct FlashLink {
    pub(super) region: embassy_sync::mutex::Mutex<Cs, Bank2Region<'static, Async>>,
    pub(super) op: Signal<Cs, FlashOp>,
    /// An operation was asked and is not finished.
    pub(super) busy: AtomicBool,
    pub(super) failed: AtomicBool,
    /// FLASH_SR2 as each operation left it, OR-ed, since the self-test last took them.
    pub(super) flags: AtomicU32,
}

impl RunFlash for BoardHw {
    fn flash_geometry(&self) -> FlashGeometry {
        FlashGeometry::H743_BANK2
    }
    fn flash_busy(&mut self) -> bool {
        self.flash.busy.load(Ordering::Acquire)
    }
    fn flash_erase(&mut self, sector: u32) -> bool {
        if self.flash_busy() || sector >= FlashGeometry::H743_BANK2.sectors {
            return false;
        }
        self.flash.busy.store(true, Ordering::Release);
        self.flash.op.signal(FlashOp::Erase { sector });
        true
    }
    fn flash_program(&mut self, offset: u32, data: &[u8]) -> bool {
        let g = FlashGeometry::H743_BANK2;
        let w = FLASH_WORD as u32;
        let len = data.len() as u32;
        if self.flash_busy()
            || !offset.is_multiple_of(w)
            || len == 0
            || !len.is_multiple_of(w)
            || data.len() > FLASH_MAX_PROGRAM
            || offset + len > g.bytes()
            || offset / g.sector_bytes != (offset + len - 1) / g.sector_bytes
        {
            return false;
        }
        let mut buf = [0xFF; FLASH_MAX_PROGRAM];
        buf[..data.len()].copy_from_slice(data);
        self.flash.busy.store(true, Ordering::Release);
        self.flash.op.signal(FlashOp::Program {
            offset,
            len: data.len(),
            data: buf,
        });
        true
    }
    fn flash_read(&mut self, offset: u32, out: &mut [u8]) -> bool {
        // Never while bank 2 is erased or programmed: the read would stall the CPU until it ends.
        if self.flash_busy() {
            return false;
        }
        let Ok(mut region) = self.flash.region.try_lock() else {
            return false;
        };
        if !self.recovering {
            return region.blocking_read(offset, out).is_ok();
        }
        // The boot recovery: each piece read within one sector, the marker naming it first, so that
        // if a torn word's ECC faults the read, the next boot knows which sector to erase
        // (`tribo_firmware::reset::boot_recovery`).
        let sector = FlashGeometry::H743_BANK2.sector_bytes;
        let mut at = offset;
        let mut rest = &mut out[..];
        while !rest.is_empty() {
            let n = ((sector - at % sector) as usize).min(rest.len());
            let (piece, tail) = rest.split_at_mut(n);
            safety::recovering(Some(at));
            if region.blocking_read(at, piece).is_err() {
                return false;
            }
            at += n as u32;
            rest = tail;
        }
        true
    }
    fn flash_take_error(&mut self) -> bool {
        self.flash.failed.swap(false, Ordering::AcqRel)
    }
    fn flash_take_flags(&mut self) -> Option<u32> {
        Some(self.flash.flags.swap(0, Ordering::AcqRel))
    }
}

/// embassy-stm32 0.6's H7 flash driver around each of its calls, for bank 2 (RM0433 §4.9):
///
/// * its `clear_all_err` rewrites FLASH_SR2, which is read-only on the H7: the error flags clear
///   only through FLASH_CCR2. A flag left set (e.g. a corrected ECC event during a pull's read)
///   would fail every later erase and program (the driver checks SR2's flags after each), so every
///   flag is cleared here before each operation, and after it (what it raised is returned, to log);
/// * its `write` ends with `CR2 = PG off`, a whole-register write that zeroes PSIZE, and its erase
///   keeps whatever PSIZE holds: erases after a program would run at ×8 parallelism, several times
///   slower than the erase times `firmware/README.md` plans with. PSIZE is set to ×64 (0b11, the
///   NUCLEO's 3.3 V supply) before each operation, which is what erases run at; programs run at
///   ×32, because the driver's `write` sets PSIZE to 0b10 itself. CR2 is writable only unlocked:
///   the bank is unlocked here first (the driver unlocks only a locked bank, and locks it again
///   when done);
/// * its interrupt handler clears OPERR before the driver reads SR2 for the result, so a failed
///   operation would be reported as done: `crate::irqs::KeepFlashFlags` runs first in the same
///   interrupt and keeps SR2, and the flags it kept count here with those SR2 still shows;
/// * its `write` polls SR2 right after each word's store with no DSB between: the status read
///   (AHB) can overtake the last word's store (AXI), see the bank idle before the 256-bit word is
///   even queued, and end the write (`PG` off) while the word is programming. After the driver
///   returns, a DSB makes sure every store reached the flash interface and the bank is awaited
///   idle (BSY, QW, WBNE clear) before its flags are read; and what was programmed is read back
///   and compared, so that a program the bank did not complete fails instead of passing. The
///   driver itself is not patched (it is embassy-stm32's): the argument for the race is RM0433's
///   bus architecture, not a test on a chip.
///
/// No `unsafe`: the PAC's register accessors are safe; the flash task is the only one that runs
/// flash operations (the application only reads, never while one runs), so nothing else writes
/// these registers meanwhile.
mod bank2 {
    use embassy_stm32::pac;

    /// Every "clear" bit of FLASH_CCR2 set: all of SR2's status and error flags cleared. Returns
    /// SR2 as it was.
    pub(super) fn clear_flags() -> u32 {
        let bank = pac::FLASH.bank(1);
        let sr = bank.sr().read().0;
        bank.ccr().write(|w| {
            w.set_clr_eop(true);
            w.set_clr_wrperr(true);
            w.set_clr_pgserr(true);
            w.set_clr_strberr(true);
            w.set_clr_incerr(true);
            w.set_clr_operr(true);
            w.set_clr_rdperr(true);
            w.set_clr_rdserr(true);
            w.set_clr_sneccerr(true);
            w.set_clr_dbeccerr(true);
            w.set_clr_crcend(true);
            w.set_clr_crcrderr(true);
        });
        sr
    }

    /// A DSB (every store of the operation reached the flash interface), then waits until bank 2
    /// is idle: nothing queued or being written (BSY, QW, WBNE clear).
    pub(super) async fn settle() {
        cortex_m::asm::dsb();
        let bank = pac::FLASH.bank(1);
        loop {
            let sr = bank.sr().read();
            if !sr.bsy() && !sr.qw() && !sr.wbne() {
                return;
            }
            embassy_futures::yield_now().await;
        }
    }

    /// Unlocks bank 2 (if locked) and sets PSIZE to ×64, then clears its flags.
    pub(super) fn prepare() {
        let bank = pac::FLASH.bank(1);
        if bank.cr().read().lock() {
            bank.keyr().write_value(0x4567_0123);
            bank.keyr().write_value(0xCDEF_89AB);
        }
        bank.cr().modify(|w| w.set_psize(0b11));
        clear_flags();
    }
}

const SECTOR: u32 = FlashGeometry::H743_BANK2.sector_bytes;

/// Erases one sector of bank 2 with the driver, flags cleared and PSIZE ×64 around it (what it
/// raised is added to `flags`).
pub(super) async fn erase_sector(
    region: &mut Bank2Region<'static, Async>,
    sector: u32,
    flags: &AtomicU32,
) -> bool {
    bank2::prepare();
    crate::irqs::FLASH_IRQ_SR2.store(0, Ordering::Release);
    let ok = region
        .erase(sector * SECTOR, (sector + 1) * SECTOR)
        .await
        .is_ok();
    bank2::settle().await;
    let sr = bank2::clear_flags() | crate::irqs::FLASH_IRQ_SR2.swap(0, Ordering::AcqRel);
    note_flags(sr, "erase", flags);
    ok && sr & OP_ERRORS == 0
}

/// FLASH_SR2's flags in bits 17..=28 (errors, ECC events, CRC end), logged when set.
const SR_ERRORS: u32 = tribo_firmware::selftest::FLASH_SR2_FLAGS;
/// Of them, those that say an erase or program failed (RM0433 §4.9: WRPERR 17, PGSERR 18,
/// STRBERR 19, INCERR 21, OPERR 22); the ECC flags come from reads, which do not run during an
/// operation.
const OP_ERRORS: u32 = 1 << 17 | 1 << 18 | 1 << 19 | 1 << 21 | 1 << 22;

/// Programs `data` at `offset` of bank 2 with the driver, flags cleared around it.
async fn program(
    region: &mut Bank2Region<'static, Async>,
    offset: u32,
    data: &[u8],
    flags: &AtomicU32,
) -> bool {
    bank2::prepare();
    crate::irqs::FLASH_IRQ_SR2.store(0, Ordering::Release);
    let ok = region.write(offset, data).await.is_ok();
    bank2::settle().await;
    let sr = bank2::clear_flags() | crate::irqs::FLASH_IRQ_SR2.swap(0, Ordering::AcqRel);
    note_flags(sr, "program", flags);
    ok && sr & OP_ERRORS == 0 && programmed_as(region, offset, data)
}

/// Whether bank 2 reads back `data` at `offset` (after a program; the bank is idle), compared in
/// pieces of a flash word.
fn programmed_as(region: &mut Bank2Region<'static, Async>, offset: u32, data: &[u8]) -> bool {
    let mut back = [0u8; FLASH_WORD];
    data.chunks(FLASH_WORD).enumerate().all(|(i, want)| {
        let at = offset + (i * FLASH_WORD) as u32;
        region.blocking_read(at, &mut back[..want.len()]).is_ok() && back[..want.len()] == *want
    })
}

/// Logs the error flags (FLASH_SR2 bits 17..=28) an operation left, and keeps SR2 for the
/// self-test (`flags`).
fn note_flags(sr: u32, what: &str, flags: &AtomicU32) {
    flags.fetch_or(sr, Ordering::AcqRel);
    let errors = sr & SR_ERRORS;
    if errors != 0 {
        defmt::warn!(
            "bank 2 {}: FLASH_SR2 error flags {=u32:#010x}, cleared",
            what,
            errors
        );
    }
}

/// Runs the application's flash operations on bank 2, one at a time.
#[embassy_executor::task]
pub(super) async fn flash_task(link: &'static FlashLink) {
    loop {
        let op = link.op.wait().await;
        let ok = {
            let mut region = link.region.lock().await;
            match op {
                FlashOp::Erase { sector } => erase_sector(&mut region, sector, &link.flags).await,
                FlashOp::Program { offset, len, data } => {
                    program(&mut region, offset, &data[..len], &link.flags).await
                }
            }
        };
        if !ok {
            defmt::warn!("bank 2 operation failed");
            link.failed.store(true, Ordering::Release);
        }
        link.busy.store(false, Ordering::Release);
    }
}
