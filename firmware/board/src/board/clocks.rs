//! The clock tree.

use super::*;

/// The core clock [`clocks`] sets: 8 MHz / 4 × 400 / 2 (PLL1 P). Busy-waits count cycles of it
/// (the MAX31856's chip-select delays); before the PLL runs the core is slower (HSI, 64 MHz), which
/// only lengthens them.
pub(super) const CORE_HZ: u32 = 8_000_000 / 4 * 400 / 2;

/// The clock tree (written down in `firmware/README.md`): HSE in bypass from the ST-LINK's 8 MHz
/// MCO (crystal-accurate) → PLL1 400 MHz core, PLL2P 25 MHz ADC kernel clock; AHB 200 MHz, APB
/// 100 MHz, so the APB1 timers (TIM6: the sample clock) run at 200 MHz; HSI48 synchronised on the
/// USB SOF by the CRS for USB.
pub(super) fn clocks() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse {
        freq: Hertz(8_000_000),
        mode: HseMode::Bypass,
    });
    config.rcc.hsi = Some(HSIPrescaler::DIV1);
    config.rcc.csi = true;
    config.rcc.hsi48 = Some(Hsi48Config {
        sync_from_usb: true,
    });
    // 8 MHz / 4 × 400 = 800 MHz VCO: 400 MHz core (P / 2), 100 MHz for SPI1 (Q / 8).
    config.rcc.pll1 = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL400,
        fracn: None,
        divp: Some(PllDiv::DIV2),
        divq: Some(PllDiv::DIV8),
        divr: None,
    });
    // 8 MHz / 4 × 200 = 400 MHz VCO / 16: 25 MHz ADC kernel clock.
    config.rcc.pll2 = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV4,
        mul: PllMul::MUL200,
        fracn: None,
        divp: Some(PllDiv::DIV16),
        divq: None,
        divr: None,
    });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = AHBPrescaler::DIV2;
    config.rcc.apb1_pre = APBPrescaler::DIV2;
    config.rcc.apb2_pre = APBPrescaler::DIV2;
    config.rcc.apb3_pre = APBPrescaler::DIV2;
    config.rcc.apb4_pre = APBPrescaler::DIV2;
    config.rcc.voltage_scale = VoltageScale::Scale1;
    config.rcc.mux.usbsel = mux::Usbsel::HSI48;
    config.rcc.mux.adcsel = mux::Adcsel::PLL2_P;
    config
}
