//! The interrupts the board's drivers take, bound once (USB, the flash bank-2 writer, the sampler's
//! DMA stream).

use core::sync::atomic::{AtomicU32, Ordering};

use embassy_stm32::interrupt::typelevel::{Handler, FLASH as FlashIrq};
use embassy_stm32::peripherals::{DMA1_CH0, USB_OTG_FS};
use embassy_stm32::{bind_interrupts, dma, pac, usb};

bind_interrupts!(pub(crate) struct Irqs {
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
    // `KeepFlashFlags` first: embassy-stm32's handler clears OPERR before its driver reads the
    // result.
    FLASH => KeepFlashFlags, embassy_stm32::flash::InterruptHandler;
    DMA1_STREAM0 => dma::InterruptHandler<DMA1_CH0>;
});

/// FLASH_SR2 as the flash interrupt found it, OR-ed since the flash task last took it
/// (`board::flash`).
pub(crate) static FLASH_IRQ_SR2: AtomicU32 = AtomicU32::new(0);

/// Keeps bank 2's status before embassy-stm32 0.6's flash interrupt handler runs: that handler
/// clears EOP and OPERR (through CCR) and only then wakes the driver, which reads SR2 for the
/// result, so an operation error (OPERR: a program or erase that failed) was reported as success.
pub(crate) struct KeepFlashFlags;

// The trait's method is `unsafe fn` (an interrupt handler must only be called from its
// interrupt); its body reads one register through the PAC's safe accessor.
#[allow(unsafe_code)]
impl Handler<FlashIrq> for KeepFlashFlags {
    unsafe fn on_interrupt() {
        let sr = pac::FLASH.bank(1).sr().read().0;
        FLASH_IRQ_SR2.fetch_or(sr, Ordering::AcqRel);
    }
}
