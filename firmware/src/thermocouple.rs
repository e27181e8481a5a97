//! The plate's thermocouple converter, a MAX31856, and when to trust what it says.
//!
//! The board only moves bytes: at start-up (and whenever [`config_ok`] says the configuration did not
//! read back) it writes [`CONFIG_WRITES`]; every 100 ms it reads the whole register file (16
//! registers, one burst from address 0) and hands the bytes, with their age, to the application
//! ([`crate::hal::Thermocouple`]). Everything else is here, testable on the host and in QEMU:
//!
//! * the configuration reads back on **every** read (registers 0x00–0x09): a converter that was
//!   reset (brown-out, ESD) or is not there shows at once;
//! * a burst of all zeros or all ones (MISO stuck low or high, converter absent) and temperature words
//!   of all zeros or all ones are garbage, not 0 °C;
//! * the fault status register on every read: open thermocouple, over/under voltage (thermocouple
//!   shorted to a supply or to ground), thermocouple range, cold-junction range;
//! * the cold-junction temperature must be plausible ([`limits::COLD_JUNCTION_C`], 5–50 °C) and the
//!   plate not implausibly cold ([`limits::PLATE_MIN_C`]);
//! * a reading older than [`limits::TC_MAX_AGE_MS`] is missing.
//!
//! One bad read is not a fault yet (the heater only stays off for it, see [`crate::heater`]);
//! [`limits::TC_BAD_READS`] in a row are.

use crate::wire::{limits, HeaterFault};

/// Registers read in one burst, from address 0x00 (CR0) to 0x0F (SR).
pub const REGISTERS: usize = 16;

/// The converter's register file, as read.
pub type Registers = [u8; REGISTERS];

/// Register addresses (datasheet table 2); add 0x80 to write.
pub mod reg {
    pub const CR0: u8 = 0x00;
    pub const CR1: u8 = 0x01;
    pub const MASK: u8 = 0x02;
    pub const CJTH: u8 = 0x0A;
    pub const CJTL: u8 = 0x0B;
    pub const LTCBH: u8 = 0x0C;
    pub const LTCBM: u8 = 0x0D;
    pub const LTCBL: u8 = 0x0E;
    pub const SR: u8 = 0x0F;
}

/// Bits of the fault status register (SR, 0x0F).
pub mod sr {
    /// Cold-junction temperature outside the converter's range.
    pub const CJ_RANGE: u8 = 1 << 7;
    /// Thermocouple input outside the range of its type.
    pub const TC_RANGE: u8 = 1 << 6;
    pub const CJ_HIGH: u8 = 1 << 5;
    pub const CJ_LOW: u8 = 1 << 4;
    pub const TC_HIGH: u8 = 1 << 3;
    pub const TC_LOW: u8 = 1 << 2;
    /// Input over or under voltage: the thermocouple touches a supply or ground.
    pub const OVUV: u8 = 1 << 1;
    /// Open thermocouple.
    pub const OPEN: u8 = 1 << 0;
}

/// CR0: automatic conversions (bit 7), open-circuit detection for a thermocouple under 5 kΩ
/// (OCFAULT = 01, bits 5:4), comparator fault mode, 50 Hz mains rejection (bit 0).
pub const CR0: u8 = 0x91;
/// CR1: one sample per conversion, type K.
pub const CR1: u8 = 0x03;

/// The writes that configure the converter, in order: the filter is chosen while conversions are
/// off (the datasheet forbids changing it in automatic mode), then the type, then conversions start.
/// Each is `(register, value)`; the board sends `[0x80 | register, value]`.
pub const CONFIG_WRITES: [(u8, u8); 3] =
    [(reg::CR0, CR0 & !0x80), (reg::CR1, CR1), (reg::CR0, CR0)];

/// What registers 0x00–0x09 read once configured: CR0, CR1, then the power-on defaults of the mask
/// and the threshold registers (left as they are) and of the cold-junction offset.
pub const CONFIG_READBACK: [u8; 10] = [CR0, CR1, 0xFF, 0x7F, 0xC0, 0x7F, 0xFF, 0x80, 0x00, 0x00];

/// The MAX31856's serial-interface minimums (datasheet, "Serial-Interface Timing"), in ns: chip
/// select low to the first SCK edge (t_CC), the last SCK edge to chip select high (t_CCH), and chip
/// select high between two transfers (t_CWH). Without the last, back-to-back register writes can
/// merge into one burst on the chip (the pin toggles in a few core cycles, ~30 ns at 400 MHz).
pub const T_CC_NS: u32 = 100;
pub const T_CCH_NS: u32 = 100;
pub const T_CWH_NS: u32 = 400;

/// Each delay is this many times its datasheet minimum: the margin covers the GPIO write's path
/// through the bus matrix (the store can reach the pin some bus cycles after the core retires it).
pub const CS_MARGIN: u32 = 2;

/// The chip-select delays in core cycles, for a busy-wait that lasts at least as many cycles as it
/// is given (`cortex_m::asm::delay`: one cycle or more per count on a Cortex-M7; interrupts only
/// lengthen it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CsDelays {
    /// After chip select goes low, before the transfer starts (t_CC).
    pub setup: u32,
    /// After the transfer, before chip select goes high (t_CCH).
    pub hold: u32,
    /// After chip select goes high, before anything can take it low again (t_CWH).
    pub inactive: u32,
}

/// Core cycles that last at least `ns` at `core_hz` (rounded up).
pub const fn cycles_at_least(ns: u32, core_hz: u32) -> u32 {
    let c = (ns as u64 * core_hz as u64).div_ceil(1_000_000_000);
    if c > u32::MAX as u64 {
        u32::MAX
    } else {
        c as u32
    }
}

/// The chip-select delays at a core clock of `core_hz`, each [`CS_MARGIN`] times its minimum. A
/// core slower than `core_hz` only lengthens them.
pub const fn cs_delays(core_hz: u32) -> CsDelays {
    CsDelays {
        setup: cycles_at_least(T_CC_NS * CS_MARGIN, core_hz),
        hold: cycles_at_least(T_CCH_NS * CS_MARGIN, core_hz),
        inactive: cycles_at_least(T_CWH_NS * CS_MARGIN, core_hz),
    }
}

/// Whether the register file shows the converter configured as [`CONFIG_WRITES`] leave it.
pub fn config_ok(regs: &Registers) -> bool {
    regs[..CONFIG_READBACK.len()] == CONFIG_READBACK
}

/// A trusted reading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Plate (hot-junction) temperature, °C, 1/128 °C resolution.
    pub plate_c: f32,
    /// Cold-junction (converter board) temperature, °C, 1/64 °C resolution.
    pub cold_junction_c: f32,
}

/// Why a read is not trusted.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BadRead {
    /// No reading, or one older than [`limits::TC_MAX_AGE_MS`] (age in ms, `u32::MAX` for none).
    Missing { age_ms: u32 },
    /// Every byte of the burst read 0x00 (MISO stuck low, converter unpowered).
    AllZero,
    /// Every byte of the burst read 0xFF (MISO stuck high, converter absent).
    AllOnes,
    /// The configuration does not read back (the converter was reset, or is another chip).
    Config,
    /// A temperature word of all zeros or all ones.
    StuckWord,
    /// SR: open thermocouple.
    Open,
    /// SR: input over or under voltage.
    OverUnderVoltage,
    /// SR: thermocouple out of range (or high/low threshold).
    ThermocoupleRange,
    /// SR: cold junction out of range (or high/low threshold).
    ColdJunctionRange,
    /// Cold junction outside [`limits::COLD_JUNCTION_C`] (°C).
    ColdJunctionImplausible(f32),
    /// Plate below [`limits::PLATE_MIN_C`] (°C).
    PlateImplausible(f32),
}

impl BadRead {
    /// The heater fault this bad read becomes when it repeats.
    pub fn fault(self) -> HeaterFault {
        match self {
            BadRead::Missing { .. } => HeaterFault::NoReading,
            BadRead::AllZero | BadRead::AllOnes | BadRead::Config | BadRead::StuckWord => {
                HeaterFault::BadConverterData
            }
            BadRead::Open => HeaterFault::OpenThermocouple,
            BadRead::OverUnderVoltage => HeaterFault::ShortedThermocouple,
            BadRead::ThermocoupleRange | BadRead::PlateImplausible(_) => {
                HeaterFault::ThermocoupleRange
            }
            BadRead::ColdJunctionRange | BadRead::ColdJunctionImplausible(_) => {
                HeaterFault::ColdJunction
            }
        }
    }
}

/// Plate temperature word: 19-bit two's complement, 1/128 °C, left-aligned in LTCBH:LTCBM:LTCBL.
fn plate_word(regs: &Registers) -> (u32, f32) {
    let raw = (regs[reg::LTCBH as usize] as u32) << 16
        | (regs[reg::LTCBM as usize] as u32) << 8
        | regs[reg::LTCBL as usize] as u32;
    let signed = ((raw << 8) as i32) >> 13;
    (raw >> 5, signed as f32 / 128.0)
}

/// Cold-junction word: 14-bit two's complement, 1/64 °C, left-aligned in CJTH:CJTL.
fn cold_junction_word(regs: &Registers) -> (u16, f32) {
    let raw = (regs[reg::CJTH as usize] as u16) << 8 | regs[reg::CJTL as usize] as u16;
    let signed = (raw as i16) >> 2;
    (raw >> 2, signed as f32 / 64.0)
}

/// Decodes and checks one read of the converter (`None`: it did not answer), `age_us` old.
pub fn check(read: Option<(&Registers, u64)>) -> Result<Reading, BadRead> {
    let Some((regs, age_us)) = read else {
        return Err(BadRead::Missing { age_ms: u32::MAX });
    };
    if age_us > limits::TC_MAX_AGE_MS as u64 * 1000 {
        return Err(BadRead::Missing {
            age_ms: (age_us / 1000).min(u32::MAX as u64) as u32,
        });
    }
    if regs.iter().all(|&b| b == 0x00) {
        return Err(BadRead::AllZero);
    }
    if regs.iter().all(|&b| b == 0xFF) {
        return Err(BadRead::AllOnes);
    }
    if !config_ok(regs) {
        return Err(BadRead::Config);
    }
    let status = regs[reg::SR as usize];
    if status & sr::OPEN != 0 {
        return Err(BadRead::Open);
    }
    if status & sr::OVUV != 0 {
        return Err(BadRead::OverUnderVoltage);
    }
    if status & (sr::TC_RANGE | sr::TC_HIGH | sr::TC_LOW) != 0 {
        return Err(BadRead::ThermocoupleRange);
    }
    if status & (sr::CJ_RANGE | sr::CJ_HIGH | sr::CJ_LOW) != 0 {
        return Err(BadRead::ColdJunctionRange);
    }
    let (tc_raw, plate_c) = plate_word(regs);
    let (cj_raw, cold_junction_c) = cold_junction_word(regs);
    if tc_raw == 0 || tc_raw == 0x7_FFFF || cj_raw == 0 || cj_raw == 0x3FFF {
        return Err(BadRead::StuckWord);
    }
    if !limits::COLD_JUNCTION_C.contains(&cold_junction_c) {
        return Err(BadRead::ColdJunctionImplausible(cold_junction_c));
    }
    if plate_c < limits::PLATE_MIN_C {
        return Err(BadRead::PlateImplausible(plate_c));
    }
    Ok(Reading {
        plate_c,
        cold_junction_c,
    })
}

/// The register file a configured converter holds for these temperatures and this fault status
/// (temperatures rounded to the converter's resolution and clamped to its words). The simulated rig
/// builds its converter from this; tests build their bad reads from it.
pub fn encode(plate_c: f32, cold_junction_c: f32, status: u8) -> Registers {
    let mut r = [0u8; REGISTERS];
    r[..CONFIG_READBACK.len()].copy_from_slice(&CONFIG_READBACK);
    let tc = round_to_i32(plate_c * 128.0).clamp(-(1 << 18), (1 << 18) - 1);
    let tc = ((tc as u32) << 5) & 0x00FF_FFE0;
    r[reg::LTCBH as usize] = (tc >> 16) as u8;
    r[reg::LTCBM as usize] = (tc >> 8) as u8;
    r[reg::LTCBL as usize] = tc as u8;
    let cj = round_to_i32(cold_junction_c * 64.0).clamp(-(1 << 13), (1 << 13) - 1);
    let cj = ((cj as u32) << 2) as u16;
    r[reg::CJTH as usize] = (cj >> 8) as u8;
    r[reg::CJTL as usize] = cj as u8;
    r[reg::SR as usize] = status;
    r
}

fn round_to_i32(x: f32) -> i32 {
    if x.is_nan() {
        0
    } else if x >= 0.0 {
        (x + 0.5) as i32
    } else {
        (x - 0.5) as i32
    }
}

#[cfg(test)]
mod tests {

    #[test]
    fn chip_select_delays_at_the_board_clock() {
        // 400 MHz: 2.5 ns a cycle; twice 100, 100 and 400 ns.
        assert_eq!(
            cs_delays(400_000_000),
            CsDelays {
                setup: 80,
                hold: 80,
                inactive: 320
            }
        );
        // The H743's fastest core (480 MHz, revision V at VOS0) and the reset clock (HSI 64 MHz).
        assert_eq!(cs_delays(480_000_000).inactive, 384);
        assert_eq!(cs_delays(64_000_000).inactive, 52, "51.2 rounded up");
        assert_eq!(cs_delays(64_000_000).setup, 13, "12.8 rounded up");
    }

    #[test]
    fn chip_select_delays_never_fall_short_of_the_datasheet() {
        for core_hz in [
            1_000_000u32,
            4_000_000,
            8_000_000,
            64_000_000,
            199_999_999,
            333_333_333,
            400_000_000,
            480_000_000,
            u32::MAX,
        ] {
            let d = cs_delays(core_hz);
            for (cycles, min_ns) in [
                (d.setup, T_CC_NS),
                (d.hold, T_CCH_NS),
                (d.inactive, T_CWH_NS),
            ] {
                // cycles / core_hz >= CS_MARGIN × min_ns, in integers.
                let lasts = cycles as u128 * 1_000_000_000;
                let needs = (CS_MARGIN * min_ns) as u128 * core_hz as u128;
                assert!(
                    lasts >= needs,
                    "{core_hz} Hz: {cycles} cycles < {min_ns} ns × margin"
                );
                // And not more than one cycle over (rounded up, not padded).
                assert!(
                    lasts < needs + 1_000_000_000,
                    "{core_hz} Hz: {cycles} cycles"
                );
            }
        }
        assert_eq!(cycles_at_least(0, 400_000_000), 0);
        assert_eq!(cycles_at_least(u32::MAX, u32::MAX), u32::MAX, "saturates");
    }

    use super::*;
    use proptest::prelude::*;

    fn fresh(r: &Registers) -> Option<(&Registers, u64)> {
        Some((r, 100_000))
    }

    #[test]
    fn datasheet_examples_decode() {
        // Datasheet table 5/6: +1600 °C is 0x640000 (LTCB), −250 °C is 0xF06000; CJ +125 °C is 0x7D00,
        // −55 °C is 0xC900. Checked on the words alone (those temperatures are not plausible here).
        let mut r = encode(0.0, 25.0, 0);
        r[12..15].copy_from_slice(&[0x64, 0x00, 0x00]);
        assert_eq!(plate_word(&r).1, 1600.0);
        r[12..15].copy_from_slice(&[0xF0, 0x60, 0x00]);
        assert_eq!(plate_word(&r).1, -250.0);
        r[10..12].copy_from_slice(&[0x7D, 0x00]);
        assert_eq!(cold_junction_word(&r).1, 125.0);
        r[10..12].copy_from_slice(&[0xC9, 0x00]);
        assert_eq!(cold_junction_word(&r).1, -55.0);
        // And a good one: 0.0078125 °C steps.
        let r = encode(40.0 + 65.0 / 128.0, 23.0 + 1.0 / 64.0, 0);
        assert_eq!(
            check(fresh(&r)),
            Ok(Reading {
                plate_c: 40.0 + 65.0 / 128.0,
                cold_junction_c: 23.0 + 1.0 / 64.0
            })
        );
    }

    #[test]
    fn every_bad_read_is_named() {
        let good = encode(60.0, 25.0, 0);
        assert!(check(fresh(&good)).is_ok());
        let cases: [(Registers, BadRead); 10] = [
            ([0; REGISTERS], BadRead::AllZero),
            ([0xFF; REGISTERS], BadRead::AllOnes),
            (encode(60.0, 25.0, sr::OPEN), BadRead::Open),
            (encode(60.0, 25.0, sr::OVUV), BadRead::OverUnderVoltage),
            (encode(60.0, 25.0, sr::TC_RANGE), BadRead::ThermocoupleRange),
            (encode(60.0, 25.0, sr::CJ_RANGE), BadRead::ColdJunctionRange),
            (encode(60.0, 2.0, 0), BadRead::ColdJunctionImplausible(2.0)),
            (
                encode(60.0, 55.0, 0),
                BadRead::ColdJunctionImplausible(55.0),
            ),
            (encode(-40.0, 25.0, 0), BadRead::PlateImplausible(-40.0)),
            (encode(0.0, 25.0, 0), BadRead::StuckWord),
        ];
        for (r, want) in cases {
            assert_eq!(check(fresh(&r)), Err(want), "{r:02x?}");
        }
        // A converter reset to its power-on state: conversions off, the configuration gone.
        let mut reset = good;
        reset[0] = 0x00;
        assert_eq!(check(fresh(&reset)), Err(BadRead::Config));
        // All-ones temperature words in an otherwise sane burst.
        let mut ones = good;
        ones[12..15].copy_from_slice(&[0xFF, 0xFF, 0xE0]);
        assert_eq!(check(fresh(&ones)), Err(BadRead::StuckWord));
        let mut ones = good;
        ones[10..12].copy_from_slice(&[0xFF, 0xFC]);
        assert_eq!(check(fresh(&ones)), Err(BadRead::StuckWord));
        // Missing, and too old.
        assert_eq!(check(None), Err(BadRead::Missing { age_ms: u32::MAX }));
        assert_eq!(
            check(Some((&good, 251_000))),
            Err(BadRead::Missing { age_ms: 251 })
        );
        assert!(check(Some((&good, 250_000))).is_ok());
    }

    #[test]
    fn the_config_writes_leave_what_the_readback_expects() {
        // A register file at its power-on defaults, then the writes.
        let mut regs: Registers = [0; REGISTERS];
        regs[..10].copy_from_slice(&[0x00, 0x03, 0xFF, 0x7F, 0xC0, 0x7F, 0xFF, 0x80, 0x00, 0x00]);
        assert!(!config_ok(&regs));
        let mut filter_changed_while_converting = false;
        for (reg, val) in CONFIG_WRITES {
            if reg == reg::CR0 && regs[0] & 0x80 != 0 && (regs[0] ^ val) & 0x01 != 0 {
                filter_changed_while_converting = true;
            }
            regs[reg as usize] = val;
        }
        assert!(config_ok(&regs));
        assert!(!filter_changed_while_converting);
        assert_eq!(regs[0] & 0x80, 0x80, "automatic conversions");
        assert_eq!(regs[0] & 0x30, 0x10, "open-circuit detection on");
        assert_eq!(regs[1] & 0x0F, 0x03, "type K");
    }

    #[test]
    fn each_bad_read_maps_to_its_fault() {
        assert_eq!(BadRead::AllZero.fault(), HeaterFault::BadConverterData);
        assert_eq!(BadRead::AllOnes.fault(), HeaterFault::BadConverterData);
        assert_eq!(BadRead::Open.fault(), HeaterFault::OpenThermocouple);
        assert_eq!(
            BadRead::OverUnderVoltage.fault(),
            HeaterFault::ShortedThermocouple
        );
        assert_eq!(
            BadRead::ColdJunctionImplausible(0.0).fault(),
            HeaterFault::ColdJunction
        );
        assert_eq!(
            BadRead::Missing { age_ms: 300 }.fault(),
            HeaterFault::NoReading
        );
    }

    proptest! {
        #[test]
        fn plausible_temperatures_round_trip_to_the_resolution(t in -19.9f32..400.0, cj in 5.0f32..50.0) {
            // 0 and −1/128 °C are the all-zero and all-ones words; nothing else plausible is refused.
            let q = (t * 128.0).round();
            prop_assume!(q != 0.0 && q != -1.0);
            let r = check(fresh(&encode(t, cj, 0))).unwrap();
            prop_assert!((r.plate_c - t).abs() <= 1.0 / 256.0 + 1e-4);
            prop_assert!((r.cold_junction_c - cj).abs() <= 1.0 / 128.0 + 1e-4);
        }

        #[test]
        fn any_bytes_decode_without_panic_and_garbage_is_refused(regs in prop::array::uniform16(any::<u8>()), age in any::<u64>()) {
            if let Ok(r) = check(Some((&regs, age))) {
                prop_assert!(config_ok(&regs));
                prop_assert!(limits::COLD_JUNCTION_C.contains(&r.cold_junction_c));
                prop_assert!(r.plate_c >= limits::PLATE_MIN_C && r.plate_c.is_finite());
            }
        }
    }
}
