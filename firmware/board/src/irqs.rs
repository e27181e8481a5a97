//! The interrupts the board's drivers take, bound once (USB, the flash bank-2 writer, the sampler's
//! DMA stream).

use embassy_stm32::peripherals::{DMA1_CH0, USB_OTG_FS};
use embassy_stm32::{bind_interrupts, dma, usb};

bind_interrupts!(pub(crate) struct Irqs {
    OTG_FS => usb::InterruptHandler<USB_OTG_FS>;
    FLASH => embassy_stm32::flash::InterruptHandler;
    DMA1_STREAM0 => dma::InterruptHandler<DMA1_CH0>;
});
