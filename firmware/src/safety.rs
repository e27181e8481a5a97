//! The rig's one safe state, as data: the register writes that take every output that can heat or
//! hold off the timers and drive it low, and zero the ECR source.
//!
//! The board (`firmware/board/src/safety.rs`) applies [`H743_SAFE_STATE`] with volatile
//! read-modify-writes from the panic handler, the HardFault handler and the watchdog task: no lock,
//! no allocation, nothing that can fail, callable from any context, and correct whatever state the
//! HAL left the peripherals in (a pin driven by a timer is taken back as a plain output, low).
//! Applying it twice changes nothing. Kept here, as data, so that the host tests and the on-target
//! tests (QEMU, against a RAM image of the registers) check it too.
//!
//! Order matters: each pin's output latch is cleared (BSRR) **before** the pin is switched from its
//! timer to a general-purpose output (MODER), so it never glitches high. Addresses are RM0433's
//! (STM32H743); the pin map is `firmware/README.md`'s.

/// One register update: `*addr = (*addr & !clear) | set` (for a write-only register such as BSRR,
/// which reads 0, a plain write of `set`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RegWrite {
    pub addr: u32,
    pub clear: u32,
    pub set: u32,
}

impl RegWrite {
    /// The register's new value from its old one.
    pub const fn apply_to(&self, old: u32) -> u32 {
        (old & !self.clear) | self.set
    }
}

/// STM32H743 register addresses (RM0433) used by the safe state.
pub mod h743 {
    pub const GPIOA: u32 = 0x5802_0000;
    pub const GPIOD: u32 = 0x5802_0C00;
    pub const GPIOE: u32 = 0x5802_1000;
    /// GPIO port mode register: two bits per pin, 00 input, 01 output, 10 alternate, 11 analog.
    pub const MODER: u32 = 0x00;
    /// GPIO output data register.
    pub const ODR: u32 = 0x14;
    /// GPIO bit set/reset register (write-only): bit n sets pin n, bit n+16 resets it.
    pub const BSRR: u32 = 0x18;
    pub const TIM1: u32 = 0x4001_0000;
    pub const TIM4: u32 = 0x4000_0800;
    /// Capture/compare register of channel 1 (channel n at +4(n−1)).
    pub const CCR1: u32 = 0x34;
    pub const CCR2: u32 = 0x38;
    /// Break and dead-time register (advanced timers): bit 15 MOE, main output enable.
    pub const BDTR: u32 = 0x44;
    pub const BDTR_MOE: u32 = 1 << 15;
    pub const DAC1: u32 = 0x4000_7400;
    /// DAC channel 1 12-bit right-aligned data holding register.
    pub const DHR12R1: u32 = 0x08;
    pub const IWDG1: u32 = 0x5800_4800;
    pub const RCC: u32 = 0x5802_4400;
    /// RCC reset status register.
    pub const RCC_RSR: u32 = 0x0D0;
    /// RMVF: write 1 to clear the reset flags.
    pub const RSR_RMVF: u32 = 1 << 16;
    pub const DBGMCU: u32 = 0x5C00_1000;
    /// DBGMCU APB4 peripheral freeze register: bit 18 stops IWDG1 while the core is halted.
    pub const DBGMCU_APB4FZ1: u32 = 0x54;
    pub const APB4FZ1_IWDG1: u32 = 1 << 18;

    /// The heater: PD12, TIM4 CH1.
    pub const HEATER: (u32, u32) = (GPIOD, 12);
    /// The magnet's H-bridge: PE9 (hold, TIM1 CH1) and PE11 (reverse, TIM1 CH2).
    pub const MAGNET_HOLD: (u32, u32) = (GPIOE, 9);
    pub const MAGNET_REVERSE: (u32, u32) = (GPIOE, 11);
    /// The ECR source: PA4, DAC1 OUT1.
    pub const ECR_SOURCE: (u32, u32) = (GPIOA, 4);
}

use h743::*;

const fn pin_low(port: u32, pin: u32) -> RegWrite {
    RegWrite {
        addr: port + BSRR,
        clear: u32::MAX,
        set: 1 << (pin + 16),
    }
}

const fn pin_output(port: u32, pin: u32) -> RegWrite {
    RegWrite {
        addr: port + MODER,
        clear: 0b11 << (2 * pin),
        set: 0b01 << (2 * pin),
    }
}

const fn zero(addr: u32) -> RegWrite {
    RegWrite {
        addr,
        clear: u32::MAX,
        set: 0,
    }
}

/// The safe state of the STM32H743 board, in the order it must be applied.
pub const H743_SAFE_STATE: [RegWrite; 10] = [
    // Output latches low first…
    pin_low(HEATER.0, HEATER.1),
    pin_low(MAGNET_HOLD.0, MAGNET_HOLD.1),
    pin_low(MAGNET_REVERSE.0, MAGNET_REVERSE.1),
    // …then the pins taken from their timers as plain outputs: heater MOSFET gate and both H-bridge
    // inputs low (coil off).
    pin_output(HEATER.0, HEATER.1),
    pin_output(MAGNET_HOLD.0, MAGNET_HOLD.1),
    pin_output(MAGNET_REVERSE.0, MAGNET_REVERSE.1),
    // The timers too, in case the pins are handed back to them: no duty, TIM1's outputs disabled.
    zero(TIM4 + CCR1),
    zero(TIM1 + CCR1),
    zero(TIM1 + CCR2),
    // ECR source to 0 V (the DAC output follows DHR within one APB clock, no trigger in use).
    zero(DAC1 + DHR12R1),
];

/// The last update: TIM1 main outputs off. Separate so that the table above stays plain data the
/// tests read pin by pin; applied after it.
pub const H743_TIM1_OUTPUTS_OFF: RegWrite = RegWrite {
    addr: TIM1 + BDTR,
    clear: BDTR_MOE,
    set: 0,
};

/// Applies the safe state through `rmw(addr, clear, set)` (the board: a volatile read-modify-write;
/// tests: a register image).
#[inline(always)]
pub fn apply(mut rmw: impl FnMut(u32, u32, u32)) {
    for w in H743_SAFE_STATE
        .iter()
        .chain(core::iter::once(&H743_TIM1_OUTPUTS_OFF))
    {
        rmw(w.addr, w.clear, w.set);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    /// A register image with GPIO semantics: BSRR reads 0 and a write to it sets/resets ODR bits.
    #[derive(Default)]
    struct Regs {
        r: BTreeMap<u32, u32>,
        /// (pin, MODER, ODR) after each write, to check what each pin did on the way.
        trace: Vec<BTreeMap<(u32, u32), (u32, u32)>>,
    }

    impl Regs {
        fn get(&self, a: u32) -> u32 {
            if a & 0xFF == BSRR {
                0
            } else {
                self.r.get(&a).copied().unwrap_or(0)
            }
        }
        fn rmw(&mut self, a: u32, clear: u32, set: u32) {
            let v = (self.get(a) & !clear) | set;
            if a & 0xFF == BSRR && [GPIOA, GPIOD, GPIOE].contains(&(a & !0xFF)) {
                let odr = a - BSRR + ODR;
                let o = self.get(odr);
                self.r.insert(odr, (o | (v & 0xFFFF)) & !(v >> 16));
            } else {
                self.r.insert(a, v);
            }
            let mut snap = BTreeMap::new();
            for (port, pin) in [HEATER, MAGNET_HOLD, MAGNET_REVERSE] {
                let m = (self.get(port + MODER) >> (2 * pin)) & 3;
                let o = (self.get(port + ODR) >> pin) & 1;
                snap.insert((port, pin), (m, o));
            }
            self.trace.push(snap);
        }
        fn pin(&self, (port, pin): (u32, u32)) -> (u32, u32) {
            (
                (self.get(port + MODER) >> (2 * pin)) & 3,
                (self.get(port + ODR) >> pin) & 1,
            )
        }
    }

    /// The registers as the running firmware leaves them: heater and magnet pins on their timers
    /// (alternate function) with their latches high, duties non-zero, TIM1 outputs on, the DAC at
    /// full scale, and unrelated pins in various modes.
    fn running() -> Regs {
        let mut g = Regs::default();
        g.r.insert(GPIOD + MODER, 0xAAAA_AAAA);
        g.r.insert(
            GPIOE + MODER,
            (0x5555_AAAA & !(0b11 << 18 | 0b11 << 22)) | 0b10 << 18 | 0b10 << 22,
        );
        g.r.insert(GPIOD + ODR, 0xFFFF);
        g.r.insert(GPIOE + ODR, 0xFFFF);
        g.r.insert(TIM4 + CCR1, 700);
        g.r.insert(TIM1 + CCR1, 600);
        g.r.insert(TIM1 + CCR2, 300);
        g.r.insert(TIM1 + BDTR, BDTR_MOE | 0x0C00);
        g.r.insert(DAC1 + DHR12R1, 4095);
        g
    }

    #[test]
    fn every_output_ends_low_and_off_its_timer() {
        let mut g = running();
        let before = g.r.clone();
        apply(|a, c, s| g.rmw(a, c, s));
        for p in [HEATER, MAGNET_HOLD, MAGNET_REVERSE] {
            assert_eq!(
                g.pin(p),
                (0b01, 0),
                "pin {p:x?}: general-purpose output, low"
            );
        }
        assert_eq!(g.get(TIM4 + CCR1), 0);
        assert_eq!(g.get(TIM1 + CCR1), 0);
        assert_eq!(g.get(TIM1 + CCR2), 0);
        assert_eq!(g.get(TIM1 + BDTR), 0x0C00, "MOE cleared, dead time kept");
        assert_eq!(g.get(DAC1 + DHR12R1), 0);
        // Nothing else changed: other pins keep their modes and levels.
        for (a, v) in before {
            let mask = match a {
                x if x == GPIOD + MODER => !(0b11 << 24),
                x if x == GPIOE + MODER => !(0b11 << 18 | 0b11 << 22),
                x if x == GPIOD + ODR => !(1 << 12),
                x if x == GPIOE + ODR => !(1 << 9 | 1 << 11),
                _ => 0,
            };
            assert_eq!(g.get(a) & mask, v & mask, "register {a:#x}");
        }
    }

    #[test]
    fn no_pin_is_ever_a_high_output_on_the_way() {
        let mut g = running();
        apply(|a, c, s| g.rmw(a, c, s));
        for (i, snap) in g.trace.iter().enumerate() {
            for (p, (mode, level)) in snap {
                assert!(
                    !(*mode == 0b01 && *level == 1),
                    "step {i}: pin {p:x?} a high output"
                );
            }
        }
    }

    #[test]
    fn applying_it_again_changes_nothing_and_it_works_from_the_reset_state() {
        let mut g = running();
        apply(|a, c, s| g.rmw(a, c, s));
        let once = g.r.clone();
        apply(|a, c, s| g.rmw(a, c, s));
        assert_eq!(g.r, once);
        // From reset (GPIO in analog mode, MODER all ones; latches low): low outputs all the same.
        let mut g = Regs::default();
        g.r.insert(GPIOD + MODER, 0xFFFF_FFFF);
        g.r.insert(GPIOE + MODER, 0xFFFF_FFFF);
        apply(|a, c, s| g.rmw(a, c, s));
        for p in [HEATER, MAGNET_HOLD, MAGNET_REVERSE] {
            assert_eq!(g.pin(p), (0b01, 0));
        }
    }
}
