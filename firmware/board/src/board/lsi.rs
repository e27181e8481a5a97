//! The HSE against an independent clock: TIM16 counts at a rate derived from the HSE (APB2 timer
//! clock, 200 MHz from PLL1 on the 8 MHz HSE, /8 by its prescaler: 25 MHz) and captures its
//! counter on every 8th rising edge of the LSI (the 32 kHz RC oscillator inside the chip, which
//! nothing derives from the HSE). The self-test (`tribo_firmware::selftest::ClockProbe`) measures
//! one interval between two consecutive captures per poll, and the host judges the LSI's
//! frequency, as the timer reads it, against the LSI's datasheet limits.
//!
//! RM0433, TIM16: TIM16_TISEL (offset 0x68) TI1SEL[3:0] = 0001 routes TI1 to the LSI (ST's
//! STM32H7 HAL names the value `TIM_TIM16_TI1_RCC_LSI`; the PAC maps TISEL at 0x68); CCMR1
//! CC1S = 01 (IC1 on TI1), IC1PSC = 11 (a capture every 8 edges), CCER CC1E with CC1P/CC1NP = 0
//! (rising edges). A capture sets CC1IF (cleared by reading CCR1); a capture while CC1IF is still
//! set overwrites CCR1 and sets CC1OF.
//!
//! Ticks per interval at the nominal clocks: 25 MHz × 8 / 32 kHz = 6250 (a resolution of 160 ppm
//! per interval, against an LSI spread of several percent). The counter wraps at 65 536 ticks, so
//! an interval reads right up to a timer clock 10.5 times its nominal: an HSE more than ten times
//! its 8 MHz, beyond the H743's HSE input range.
//!
//! No `unsafe`: the PAC's register accessors are safe; this module owns TIM16 (its singleton is
//! taken at start-up, nothing else uses it: embassy's time driver runs on TIM2) and only reads
//! RCC_CSR's LSI bits and sets LSION, which the IWDG (running since reset) forces on anyway.

use super::*;
use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM16;
use tribo_firmware::hal::{ClockCheck, LsiInterval, LsiTimer};

/// TIM16's prescaler: the 200 MHz timer clock / 8 = 25 MHz ticks.
const PSC: u16 = 7;
/// LSI periods per capture (IC1PSC = 0b11).
const PERIODS_PER_CAPTURE: u8 = 8;
/// Longest wait for one capture, µs of the time base: ~11 capture periods at the LSI's slowest
/// (269 µs at 29.76 kHz), so that even a time base running several times fast (an HSE far off)
/// leaves one whole capture period. Only a missing LSI waits this long (twice per interval, at most
/// `CLOCK_MAX_TIMEOUTS` times per check).
const WAIT_US: u64 = 3_000;

/// TIM16 and the LSI, for the clock check.
pub(super) struct LsiCapture {
    _tim: embassy_stm32::Peri<'static, TIM16>,
    /// LSION as the check found it (restored at the end).
    lsion_before: bool,
    running: bool,
}

impl LsiCapture {
    pub(super) fn new(tim: embassy_stm32::Peri<'static, TIM16>) -> Self {
        LsiCapture {
            _tim: tim,
            lsion_before: false,
            running: false,
        }
    }

    /// Waits for CC1IF until `WAIT_US` have passed.
    fn wait_capture(&self) -> bool {
        let t = pac::TIM16;
        let deadline = Instant::now() + Duration::from_micros(WAIT_US);
        loop {
            if t.sr().read().ccif(0) {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
        }
    }

    /// Clears CC1OF alone (the status flags are rc_w0: a 1 leaves a flag as it is).
    fn clear_overcapture(&self) {
        let mut v = pac::timer::regs::Sr1chCmp(0xFFFF_FFFF);
        v.set_ccof(0, false);
        pac::TIM16.sr().write_value(v);
    }
}

impl ClockCheck for LsiCapture {
    fn lsi_start(&mut self) -> Option<LsiTimer> {
        let rcc = pac::RCC;
        if !self.running {
            self.lsion_before = rcc.csr().read().lsion();
        }
        rcc.csr().modify(|w| w.set_lsion(true));
        embassy_stm32::rcc::enable_and_reset::<TIM16>();
        let kernel_hz = embassy_stm32::rcc::frequency::<TIM16>().0;
        let t = pac::TIM16;
        t.cr1().write(|w| w.set_cen(false));
        t.psc().write_value(PSC);
        t.arr().write(|w| w.set_arr(0xFFFF));
        // Load the prescaler now (an update event), then clear every flag it set.
        t.egr().write(|w| w.set_ug(true));
        // TI1SEL = 0001: TI1 is the LSI (RM0433, TIM16_TISEL).
        t.tisel().write(|w| w.set_tisel(0, 0b0001));
        t.ccmr_input(0).write(|w| {
            // CC1S = 01: IC1 mapped on TI1 (the PAC calls this encoding `TI4`).
            w.set_ccs(0, pac::timer::vals::CcmrInputCcs::from_bits(0b01));
            w.set_icpsc(0, 0b11);
        });
        t.ccer().write(|w| w.set_cce(0, true));
        t.sr().write_value(pac::timer::regs::Sr1chCmp(0));
        t.cr1().write(|w| w.set_cen(true));
        self.running = true;
        Some(LsiTimer {
            timer_hz: kernel_hz / (PSC as u32 + 1),
            periods_per_capture: PERIODS_PER_CAPTURE,
        })
    }

    fn lsi_ready(&mut self) -> bool {
        pac::RCC.csr().read().lsirdy()
    }

    fn lsi_interval(&mut self) -> LsiInterval {
        if !self.running {
            return LsiInterval::Timeout;
        }
        let t = pac::TIM16;
        // The first capture: the latest one if one is pending (captures come every ~250 µs, polls
        // every 0.5–1 ms: earlier ones were overwritten, which does not matter for this one), else
        // the next. Reading CCR1 clears CC1IF; CC1OF is cleared after, so that it flags only an
        // overwrite between this capture and the next.
        if !self.wait_capture() {
            return LsiInterval::Timeout;
        }
        let first = t.ccr(0).read().ccr();
        self.clear_overcapture();
        // A capture that came between the read and the clear set CC1IF again (not CC1OF, since
        // CC1IF was clear): it is the next one, read at once below.
        if !self.wait_capture() {
            return LsiInterval::Timeout;
        }
        let second = t.ccr(0).read().ccr();
        // CC1OF now: a capture overwrote CCR1 while CC1IF was set, between `first` and the read of
        // `second`: `second` is not the capture after `first`.
        if t.sr().read().ccof(0) {
            self.clear_overcapture();
            return LsiInterval::Overcapture;
        }
        LsiInterval::Ticks(second.wrapping_sub(first) as u32)
    }

    fn lsi_stop(&mut self) {
        if !self.running {
            return;
        }
        let t = pac::TIM16;
        t.cr1().write(|w| w.set_cen(false));
        t.ccer().write(|w| w.set_cce(0, false));
        embassy_stm32::rcc::disable::<TIM16>();
        if !self.lsion_before {
            // While the IWDG runs the LSI stays on whatever LSION says (RM0433, IWDG).
            pac::RCC.csr().modify(|w| w.set_lsion(false));
        }
        self.running = false;
    }
}
