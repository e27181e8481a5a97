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
        match self.flash.region.try_lock() {
            Ok(mut region) => region.blocking_read(offset, out).is_ok(),
            Err(_) => false,
        }
    }
    fn flash_take_error(&mut self) -> bool {
        self.flash.failed.swap(false, Ordering::AcqRel)
    }
}

/// Runs the application's flash operations on bank 2, one at a time.
#[embassy_executor::task]
pub(super) async fn flash_task(link: &'static FlashLink) {
    pub(super) const SECTOR: u32 = FlashGeometry::H743_BANK2.sector_bytes;
    loop {
        let op = link.op.wait().await;
        let ok = {
            let mut region = link.region.lock().await;
            match op {
                FlashOp::Erase { sector } => region
                    .erase(sector * SECTOR, (sector + 1) * SECTOR)
                    .await
                    .is_ok(),
                FlashOp::Program { offset, len, data } => {
                    region.write(offset, &data[..len]).await.is_ok()
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
