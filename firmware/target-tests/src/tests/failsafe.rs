//! The fail-safe logic on the M7: the thermocouple converter's words, the heater's
//! interlocks (bad reads in a row, heating watch, runaway, over-temperature), the magnet's hold
//! limit and cool-down, the reset record, the safe-state table, and the application going safe by
//! itself (host lease, thermocouple faults) within its poll budget with the right `Fault` frame.
//!
//! The same library code as on the host (`cargo test -p tribo-firmware`, `tests/failsafe.rs`), here
//! compiled for and run on the Cortex-M7, where float rounding, word sizes and the instruction
//! budgets are the board's. Times are the application's (virtual µs); instruction counts are
//! exact (`-icount shift=0`).
// `check!(x > 0.0)` negates its float comparison inside the macro (NaN fails the check, as wanted).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::replay::Converter;
use crate::tests::app::{record, Bench, CALL_BUDGET, POLL_US, STACK_BUDGET};
use crate::{check, check_eq, Cx, Outcome};
use tribo_firmware::hal::{FlashGeometry, Magnet, MagnetDrive};
use tribo_firmware::heater::{Heater, HeaterConfig};
use tribo_firmware::release::{MagnetEvent, Release, ReleaseConfig};
use tribo_firmware::reset::{self, ResetFlags, RECORD_WORDS};
use tribo_firmware::runstore::{RunStore, MAX_RUN_BLOCKS};
use tribo_firmware::safety::{self, h743};
use tribo_firmware::thermocouple::{self as tc, sr, BadRead, Reading, Registers};
use tribo_firmware::wire::{
    limits, FaultReason, HeaterFault, HeaterSetpoint, HostMsg, ResetCause, PROTOCOL_VERSION,
};

/// A read of `regs`, 100 ms old (fresh).
fn fresh(regs: &Registers) -> Option<(&Registers, u64)> {
    Some((regs, 100_000))
}

/// Datasheet words decode, and every kind of bad read is refused with its name.
pub fn thermocouple_words(cx: &mut Cx) -> Outcome {
    // MAX31856 datasheet tables 5 and 6: LTCB +1600 °C = 0x640000, −250 °C = 0xF06000; CJ +125 °C
    // = 0x7D00, −55 °C = 0xC900 (the last three are then refused as implausible here, by value).
    let mut r = tc::encode(0.0, 25.0, 0);
    r[12..15].copy_from_slice(&[0x64, 0x00, 0x00]);
    check_eq!(
        tc::check(fresh(&r)),
        Ok(Reading {
            plate_c: 1600.0,
            cold_junction_c: 25.0
        })
    );
    r[12..15].copy_from_slice(&[0xF0, 0x60, 0x00]);
    check_eq!(tc::check(fresh(&r)), Err(BadRead::PlateImplausible(-250.0)));
    let mut r = tc::encode(60.0, 25.0, 0);
    r[10..12].copy_from_slice(&[0x7D, 0x00]);
    check_eq!(
        tc::check(fresh(&r)),
        Err(BadRead::ColdJunctionImplausible(125.0))
    );
    r[10..12].copy_from_slice(&[0xC9, 0x00]);
    check_eq!(
        tc::check(fresh(&r)),
        Err(BadRead::ColdJunctionImplausible(-55.0))
    );
    // A good read to the converter's resolution (1/128 °C, 1/64 °C).
    let good = tc::encode(40.0 + 65.0 / 128.0, 23.0 + 1.0 / 64.0, 0);
    check_eq!(
        tc::check(fresh(&good)),
        Ok(Reading {
            plate_c: 40.0 + 65.0 / 128.0,
            cold_junction_c: 23.0 + 1.0 / 64.0
        })
    );
    let mut config_lost = good;
    config_lost[0] = 0x00; // CR0 back to its power-on value: the converter was reset
    let mut plate_ones = good;
    plate_ones[12..15].copy_from_slice(&[0xFF, 0xFF, 0xE0]);
    let mut cj_ones = good;
    cj_ones[10..12].copy_from_slice(&[0xFF, 0xFC]);
    let cases: [(Registers, BadRead); 16] = [
        ([0; tc::REGISTERS], BadRead::AllZero),
        ([0xFF; tc::REGISTERS], BadRead::AllOnes),
        (config_lost, BadRead::Config),
        (tc::encode(60.0, 25.0, sr::OPEN), BadRead::Open),
        (tc::encode(60.0, 25.0, sr::OVUV), BadRead::OverUnderVoltage),
        (
            tc::encode(60.0, 25.0, sr::TC_RANGE),
            BadRead::ThermocoupleRange,
        ),
        (
            tc::encode(60.0, 25.0, sr::TC_HIGH),
            BadRead::ThermocoupleRange,
        ),
        (
            tc::encode(60.0, 25.0, sr::CJ_RANGE),
            BadRead::ColdJunctionRange,
        ),
        (
            tc::encode(60.0, 25.0, sr::CJ_LOW),
            BadRead::ColdJunctionRange,
        ),
        (
            tc::encode(60.0, 4.5, 0),
            BadRead::ColdJunctionImplausible(4.5),
        ),
        (
            tc::encode(60.0, 50.5, 0),
            BadRead::ColdJunctionImplausible(50.5),
        ),
        (tc::encode(-20.5, 25.0, 0), BadRead::PlateImplausible(-20.5)),
        (tc::encode(0.0, 25.0, 0), BadRead::StuckWord),
        (plate_ones, BadRead::StuckWord),
        (cj_ones, BadRead::StuckWord),
        // Open wins over the others (the first the status register names).
        (
            tc::encode(60.0, 25.0, sr::OPEN | sr::OVUV | sr::TC_RANGE),
            BadRead::Open,
        ),
    ];
    for (regs, want) in cases {
        check_eq!(tc::check(fresh(&regs)), Err(want), "registers {regs:02x?}");
    }
    // The edges of the plausible cold junction are accepted.
    for cj in [5.0, 50.0] {
        check!(
            tc::check(fresh(&tc::encode(60.0, cj, 0))).is_ok(),
            "cold junction {cj} °C refused"
        );
    }
    // Missing, and too old (the converter task stopped).
    check_eq!(tc::check(None), Err(BadRead::Missing { age_ms: u32::MAX }));
    let limit_us = limits::TC_MAX_AGE_MS as u64 * 1000;
    check!(tc::check(Some((&good, limit_us))).is_ok());
    check_eq!(
        tc::check(Some((&good, limit_us + 1000))),
        Err(BadRead::Missing {
            age_ms: limits::TC_MAX_AGE_MS + 1
        })
    );
    // What one check costs (the application runs it every 100 ms).
    let mut out = Err(BadRead::AllZero);
    let n = cx.count(|| out = tc::check(fresh(core::hint::black_box(&good))));
    check!(out.is_ok());
    cx.figure(
        "failsafe.thermocouple_check",
        n,
        "instructions",
        Some(2_000),
    )
}

/// A heater regulating to `setpoint_c`, stepped every 100 ms with good reads at `plate_c` until
/// `secs` (past the start-up grace).
fn heater_running(setpoint_c: f32, plate_c: f32, secs: f32) -> Heater {
    let mut h = Heater::new(HeaterConfig::default());
    h.set(HeaterSetpoint {
        setpoint_c,
        ramp_c_per_min: 30.0,
    });
    let mut t = 0.0;
    while t < secs {
        h.step(tc::check(fresh(&tc::encode(plate_c, 25.0, 0))), 0.1);
        t += 0.1;
    }
    h
}

/// One bad read switches the heater off for that step only; [`limits::TC_BAD_READS`] in a row latch
/// the fault the bad read names, and it stays latched through good reads.
pub fn bad_reads_in_a_row_fault_the_heater(cx: &mut Cx) -> Outcome {
    let stale = tc::encode(30.0, 25.0, 0);
    let cases: [(Option<(Registers, u64)>, HeaterFault); 8] = [
        (
            Some((tc::encode(30.0, 25.0, sr::OPEN), 0)),
            HeaterFault::OpenThermocouple,
        ),
        (
            Some((tc::encode(30.0, 25.0, sr::OVUV), 0)),
            HeaterFault::ShortedThermocouple,
        ),
        (Some(([0; tc::REGISTERS], 0)), HeaterFault::BadConverterData),
        (
            Some(([0xFF; tc::REGISTERS], 0)),
            HeaterFault::BadConverterData,
        ),
        (
            Some((tc::encode(30.0, 71.0, 0), 0)),
            HeaterFault::ColdJunction,
        ),
        (
            Some((tc::encode(30.0, 25.0, sr::TC_RANGE), 0)),
            HeaterFault::ThermocoupleRange,
        ),
        (Some((stale, 300_000)), HeaterFault::NoReading),
        (None, HeaterFault::NoReading),
    ];
    let good = tc::encode(30.0, 25.0, 0);
    let mut worst = 0u64;
    for (bad, want) in cases {
        let bad_read = || tc::check(bad.as_ref().map(|(r, age)| (r, *age)));
        let mut h = heater_running(60.0, 30.0, 2.0);
        check!(h.duty() > 0.0, "not heating before the fault ({want:?})");
        // One bad read: off for this step, no fault; a good read: heating again.
        let s = h.step(bad_read(), 0.1);
        check_eq!(s.duty, 0.0, "{want:?}: heater on through a bad read");
        check_eq!(s.new_fault, None, "{want:?}: one bad read is not a fault");
        let s = h.step(tc::check(fresh(&good)), 0.1);
        check!(
            s.duty > 0.0,
            "{want:?}: not heating again after a good read"
        );
        // N in a row: the fault latches at the N-th, not before.
        for k in 1..=limits::TC_BAD_READS {
            let mut s = None;
            let n = cx.count(|| s = Some(h.step(bad_read(), 0.1)));
            worst = worst.max(n.unwrap_or(0));
            let Some(s) = s else { continue };
            check_eq!(s.duty, 0.0, "{want:?}: heater on at bad read {k}");
            if k < limits::TC_BAD_READS {
                check_eq!(s.new_fault, None, "{want:?}: fault at bad read {k}");
            } else {
                check_eq!(s.new_fault, Some(want), "at bad read {k}");
            }
        }
        // Latched: good reads do not bring the heat back; only a new setpoint clears it.
        for _ in 0..10 {
            let s = h.step(tc::check(fresh(&good)), 0.1);
            check_eq!(
                s.duty,
                0.0,
                "{want:?}: heating again without a new setpoint"
            );
        }
        check_eq!(h.fault(), Some(want));
    }
    // Bad reads in the start-up grace (the converter's first conversion) are no fault yet.
    let mut h = Heater::new(HeaterConfig::default());
    h.set(HeaterSetpoint {
        setpoint_c: 60.0,
        ramp_c_per_min: 30.0,
    });
    for _ in 0..5 {
        let s = h.step(tc::check(None), 0.1);
        check_eq!(s.new_fault, None, "fault inside the start-up grace");
        check_eq!(s.duty, 0.0);
    }
    let counting = cx.counting();
    cx.figure(
        "failsafe.heater_step_bad_read",
        counting.then_some(worst),
        "instructions",
        None,
    )
}

/// Steps `h` every 100 ms with the plate at `plate(t)` until a fault or `until_s`; returns the
/// time of the fault (s since the first of these steps) and the plate then.
fn until_fault(h: &mut Heater, until_s: f32, plate: impl Fn(f32) -> f32) -> Option<(f32, f32)> {
    let mut t = 0.0f32;
    let mut k = 0u32;
    while t <= until_s {
        k += 1;
        t = k as f32 * 0.1;
        let p = plate(t);
        let s = h.step(tc::check(fresh(&tc::encode(p, 25.0, 0))), 0.1);
        if s.new_fault.is_some() {
            return Some((t, p));
        }
    }
    None
}

/// The heating watch (a heater that does not heat), the runaway watch (a switch stuck on), the
/// over-temperature cut-off, and no false alarm for a plate at its setpoint.
pub fn runaway_and_watch(cx: &mut Cx) -> Outcome {
    // A dead heater from 25 °C towards 60 °C at 30 °C/min: the ramp leaves the plate behind by the
    // band after band / ramp = 10 s, then it has the watch period to gain.
    let mut h = heater_running(60.0, 25.0, 0.0);
    let at = until_fault(&mut h, 200.0, |_| 25.0);
    let expect = limits::HEATER_BAND_C / 0.5 + limits::HEATER_WATCH_PERIOD_S;
    check!(at.is_some(), "a dead heater never faulted in 200 s");
    let (t, _) = at.unwrap_or((0.0, 0.0));
    check!(
        (t - expect).abs() <= 0.25,
        "HeatingFailed at {t} s, expected {expect} s"
    );
    check_eq!(h.fault(), Some(HeaterFault::HeatingFailed));
    check_eq!(h.duty(), 0.0);
    // A weak heater that gains 2.5 °C a minute while lagging is no fault (it keeps up the watch).
    let mut h = heater_running(60.0, 25.0, 0.0);
    let slow = until_fault(&mut h, 300.0, |t| 25.0 + 2.5 * t / 60.0);
    check_eq!(slow, None, "a slow but working heater faulted");
    // Heater off, switch stuck on: the plate climbs 1.3 °C/s; Runaway once it rose 5 °C.
    let mut h = Heater::new(HeaterConfig::default());
    h.step(tc::check(fresh(&tc::encode(25.0, 25.0, 0))), 0.1);
    let at = until_fault(&mut h, 60.0, |t| 25.0 + 1.3 * t);
    check!(at.is_some(), "a switch stuck on never faulted");
    let (t, p) = at.unwrap_or((0.0, 0.0));
    let rise = p - 25.0;
    check!(
        (limits::HEATER_RUNAWAY_RISE_C..=limits::HEATER_RUNAWAY_RISE_C + 0.2).contains(&rise),
        "Runaway after a rise of {rise} °C at {t} s"
    );
    check_eq!(h.fault(), Some(HeaterFault::Runaway));
    // Cooling down with the heater off (and a room warming 2 °C an hour) is no runaway.
    let mut h = Heater::new(HeaterConfig::default());
    let cooling = until_fault(&mut h, 300.0, |t| 25.0 + 40.0 * libm_exp(-t / 120.0));
    check_eq!(cooling, None, "a cooling plate faulted");
    // At setpoint, within the band (±0.4 °C of wobble): no fault for 5 minutes.
    let mut h = heater_running(40.0, 40.0, 2.0);
    let wobble = until_fault(&mut h, 300.0, |t| {
        40.0 + if (t * 10.0) as u32 % 7 < 3 { 0.4 } else { -0.4 }
    });
    check_eq!(wobble, None, "a plate at its setpoint faulted");
    check!(h.duty() >= 0.0 && h.fault().is_none());
    // Over the cut-off: off at the first read, whatever the setpoint.
    let mut h = heater_running(100.0, 100.0, 2.0);
    let s = h.step(
        tc::check(fresh(&tc::encode(limits::HEATER_CUTOFF_C + 0.25, 25.0, 0))),
        0.1,
    );
    check_eq!(s.new_fault, Some(HeaterFault::OverTemperature));
    check_eq!(s.duty, 0.0);
    // What one regulating step with its watches costs (every 100 ms in the application).
    let mut h = heater_running(60.0, 30.0, 2.0);
    let good = tc::encode(30.0, 25.0, 0);
    let n = cx.count(|| {
        h.step(tc::check(fresh(core::hint::black_box(&good))), 0.1);
    });
    check!(h.duty() > 0.0 && h.fault().is_none());
    cx.figure("failsafe.heater_step", n, "instructions", None)
}

/// exp(x) for x ≤ 0 without libm: (1 + x/1024)^1024.
fn libm_exp(x: f32) -> f32 {
    let mut y = 1.0 + x / 1024.0;
    for _ in 0..10 {
        y *= y;
    }
    y
}

/// A magnet model: what the firmware last drove.
struct Coil(MagnetDrive);

impl Magnet for Coil {
    fn magnet_drive(&mut self, drive: MagnetDrive) {
        self.0 = drive;
    }
}

/// One hold lasts at most [`limits::MAGNET_MAX_HOLD_MS`]; the coil is off past it, and holding
/// again waits for the cool-down (half the budget back at the duty's refill rate).
pub fn magnet_hold_limit(cx: &mut Cx) -> Outcome {
    let cfg = ReleaseConfig::default();
    let mut r = Release::new(cfg);
    let mut m = Coil(MagnetDrive::Off);
    let limit = limits::MAGNET_MAX_HOLD_MS as u64 * 1000;
    check!(r.hold(&mut m, 0, u64::MAX).is_ok());
    check!(matches!(m.0, MagnetDrive::Hold { .. }));
    // Polled every 500 µs: holding until the limit, off at the poll that reaches it (the budget,
    // the limit's size, is spent then).
    let mut t = 0;
    let mut off_at = None;
    let mut worst = 0u64;
    while t < limit + 10 * POLL_US {
        t += POLL_US;
        let mut e = None;
        let n = cx.count(|| e = r.poll(&mut m, t));
        worst = worst.max(n.unwrap_or(0));
        if let Some(e) = e {
            check_eq!(e, MagnetEvent::HoldTimeExceeded);
            off_at = Some(t);
            break;
        }
        check!(
            matches!(m.0, MagnetDrive::Hold { .. }),
            "coil off at {t} µs, before the limit"
        );
    }
    check_eq!(off_at, Some(limit), "coil off (µs)");
    check_eq!(m.0, MagnetDrive::Off);
    check!(!r.is_on());
    // The budget is empty: holding again is refused with the wait (60 s at 50 % duty), and
    // accepted once the wait is over.
    let t0 = limit;
    let wait = r.hold(&mut m, t0, u64::MAX);
    let expect_wait = (limit / 2) as f64 * (1.0 - cfg.max_duty as f64) / cfg.max_duty as f64;
    check!(
        matches!(wait, Err(w) if (w as f64 - expect_wait).abs() <= 1.0),
        "hold after an empty budget: {wait:?}, expected a wait of {expect_wait} µs"
    );
    check_eq!(m.0, MagnetDrive::Off, "the coil came on in its cool-down");
    let w = wait.err().unwrap_or(0);
    check!(r.hold(&mut m, t0 + w - 1000, u64::MAX).is_err());
    check!(r.hold(&mut m, t0 + w, u64::MAX).is_ok());
    // A shorter limit (stand-alone mode) is kept.
    let mut r = Release::new(cfg);
    let short = limits::STANDALONE_HOLD_MS as u64 * 1000;
    check!(r.hold(&mut m, 0, short).is_ok());
    check_eq!(r.poll(&mut m, short), None);
    check_eq!(
        r.poll(&mut m, short + 1),
        Some(MagnetEvent::HoldTimeExceeded)
    );
    check_eq!(m.0, MagnetDrive::Off);
    let counting = cx.counting();
    cx.figure(
        "failsafe.magnet_poll",
        counting.then_some(worst),
        "instructions",
        None,
    )
}

/// The reset record round trip for every cause, cut messages, and the CRC refusing garbage: every
/// single-bit flip, erased RAM, a fill pattern, pseudo-random words; the boot report reads the
/// record only when RAM was kept.
pub fn reset_record(cx: &mut Cx) -> Outcome {
    const ALL: [ResetCause; 8] = ResetCause::ALL;
    let msg =
        "panicked at src/heater.rs:212:9: index out of bounds: the len is 4 but the index is 9";
    for c in ALL {
        let r = reset::encode(c, msg.as_bytes());
        let d = reset::decode(&r);
        check!(d.is_some(), "{c:?}: record refused");
        let (cause, text) = d.unwrap_or((ResetCause::Unknown, heapless::String::new()));
        check_eq!(cause, c);
        let n = text.len();
        check!(
            n > 0 && msg.starts_with(text.as_str()),
            "{c:?}: message {text:?}"
        );
    }
    // Longer than the record holds: cut, still a record.
    let long = [b'x'; 300];
    let d = reset::decode(&reset::encode(ResetCause::Panic, &long));
    check!(
        matches!(&d, Some((ResetCause::Panic, s)) if s.len() == tribo_firmware::wire::BOOT_MESSAGE_LEN),
        "long message: {d:?}"
    );
    // Every single-bit flip of a record is refused.
    let good = reset::encode(ResetCause::Watchdog, b"task thermocouple silent for 350 ms");
    let mut flips = 0;
    for w in 0..RECORD_WORDS {
        for b in 0..32 {
            let mut r = good;
            r[w] ^= 1 << b;
            check!(
                reset::decode(&r).is_none(),
                "bit {b} of word {w} flipped and accepted"
            );
            flips += 1;
        }
    }
    // Erased, filled and pseudo-random RAM (what a power-on leaves) is no record.
    check!(reset::decode(&reset::EMPTY).is_none());
    check!(reset::decode(&[0xFFFF_FFFF; RECORD_WORDS]).is_none());
    check!(reset::decode(&[0xDEAD_BEEF; RECORD_WORDS]).is_none());
    let mut x = 0x1234_5678u32;
    for _ in 0..200 {
        let mut r = reset::EMPTY;
        for w in r.iter_mut() {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            *w = x;
        }
        r[0] = good[0]; // even with the right magic
        check!(
            reset::decode(&r).is_none(),
            "random words accepted: {r:08x?}"
        );
    }
    // The boot report: the record wins when RAM was kept; after a power-on it is not even read.
    let rsr_iwdg = (1 << 26) | (1 << 22);
    let b = reset::boot_report(ResetFlags::from_h7_rsr(rsr_iwdg), || good);
    check_eq!(b.cause, ResetCause::Watchdog);
    check!(b.message.starts_with("task thermocouple"));
    let b = reset::boot_report(ResetFlags::from_h7_rsr(rsr_iwdg), || reset::EMPTY);
    check_eq!(b.cause, ResetCause::Watchdog, "the flags alone");
    check!(b.message.is_empty());
    let mut read = false;
    let b = reset::boot_report(ResetFlags::from_h7_rsr((1 << 23) | (1 << 22)), || {
        read = true;
        good
    });
    check_eq!(b.cause, ResetCause::PowerOn);
    check!(
        !read,
        "the record was read after a power-on (its RAM may hold ECC errors)"
    );
    let b = reset::boot_report(ResetFlags::from_h7_rsr(1 << 22), || reset::EMPTY);
    check_eq!(b.cause, ResetCause::Pin);
    cx.note(format_args!(
        "{} causes round-tripped; {flips} single-bit flips and 203 garbage records refused",
        ALL.len()
    ));
    let mut r = reset::EMPTY;
    let n =
        cx.count(|| r = reset::encode(ResetCause::Panic, core::hint::black_box(msg).as_bytes()));
    check!(reset::decode(&r).is_some());
    cx.figure("failsafe.reset_record_encode", n, "instructions", None)
}

/// A register image of the outputs the safe state touches: heater and magnet pins driven by their
/// timers with their latches high, duties set, TIM1's outputs on, the ECR source at full scale.
pub struct RegisterImage {
    regs: [(u32, u32); 12],
}

impl RegisterImage {
    /// The outputs live (what a panic in the middle of a heated, holding run finds).
    pub fn live() -> Self {
        let af = |pin: u32| 0b10 << (2 * pin);
        RegisterImage {
            regs: [
                (h743::GPIOD + h743::MODER, !(0b11 << 24) | af(12)),
                (h743::GPIOE + h743::MODER, af(9) | af(11)),
                (h743::GPIOD + h743::BSRR, 0),
                (h743::GPIOE + h743::BSRR, 0),
                (h743::GPIOD + h743::ODR, 1 << 12),
                (h743::GPIOE + h743::ODR, 1 << 9 | 1 << 11),
                (h743::TIM4 + h743::CCR1, 800),
                (h743::TIM1 + h743::CCR1, 600),
                (h743::TIM1 + h743::CCR2, 300),
                (h743::TIM1 + h743::BDTR, h743::BDTR_MOE | 0x80),
                (h743::DAC1 + h743::DHR12R1, 4095),
                (0, 0),
            ],
        }
    }

    pub fn get(&self, addr: u32) -> Option<u32> {
        self.regs.iter().find(|r| r.0 == addr).map(|r| r.1)
    }

    /// One read-modify-write as the board does it; BSRR as the GPIO does (write-only, moves ODR).
    /// An address outside the image is an error.
    pub fn rmw(&mut self, addr: u32, clear: u32, set: u32) -> bool {
        let bsrr = [h743::GPIOD, h743::GPIOE, h743::GPIOA]
            .into_iter()
            .find(|p| p + h743::BSRR == addr);
        if let Some(port) = bsrr {
            if let Some(odr) = self.regs.iter_mut().find(|r| r.0 == port + h743::ODR) {
                odr.1 = (odr.1 | (set & 0xFFFF)) & !(set >> 16);
            }
            return self.regs.iter().any(|r| r.0 == addr);
        }
        match self.regs.iter_mut().find(|r| r.0 == addr) {
            Some(r) => {
                r.1 = (r.1 & !clear) | set;
                true
            }
            None => false,
        }
    }

    /// Heater and both H-bridge inputs low and general-purpose outputs, duties 0, TIM1's main
    /// outputs off, ECR source 0 V.
    pub fn safe(&self) -> Result<(), &'static str> {
        let mode = |port: u32, pin: u32| {
            self.get(port + h743::MODER)
                .map(|m| (m >> (2 * pin)) & 0b11)
        };
        let high = |port: u32, pin: u32| self.get(port + h743::ODR).map(|o| o & (1 << pin) != 0);
        for (port, pin, name) in [
            (h743::HEATER.0, h743::HEATER.1, "heater"),
            (h743::MAGNET_HOLD.0, h743::MAGNET_HOLD.1, "magnet hold"),
            (
                h743::MAGNET_REVERSE.0,
                h743::MAGNET_REVERSE.1,
                "magnet reverse",
            ),
        ] {
            if mode(port, pin) != Some(0b01) {
                return Err(name);
            }
            if high(port, pin) != Some(false) {
                return Err(name);
            }
        }
        for (addr, name) in [
            (h743::TIM4 + h743::CCR1, "heater duty"),
            (h743::TIM1 + h743::CCR1, "magnet hold duty"),
            (h743::TIM1 + h743::CCR2, "magnet reverse duty"),
            (h743::DAC1 + h743::DHR12R1, "ECR source"),
        ] {
            if self.get(addr) != Some(0) {
                return Err(name);
            }
        }
        if self
            .get(h743::TIM1 + h743::BDTR)
            .map(|b| b & h743::BDTR_MOE)
            != Some(0)
        {
            return Err("TIM1 main outputs");
        }
        Ok(())
    }
}

/// The safe-state table applied to a register image of live outputs: every output safe, no pin
/// high while switched to a plain output on the way, the other bits of each register kept, and a
/// second application changes nothing. Its cost is the handlers' first work.
pub fn safe_state_table(cx: &mut Cx) -> Outcome {
    let mut regs = RegisterImage::live();
    check!(regs.safe().is_err(), "the live image is already safe");
    let mut unknown = 0;
    let mut glitch = false;
    safety::apply(|a, c, s| {
        if !regs.rmw(a, c, s) {
            unknown += 1;
        }
        // After each write: no pin that is a plain output is high.
        for (port, pin) in [h743::HEATER, h743::MAGNET_HOLD, h743::MAGNET_REVERSE] {
            let out = regs
                .get(port + h743::MODER)
                .is_some_and(|m| (m >> (2 * pin)) & 0b11 == 0b01);
            let high = regs
                .get(port + h743::ODR)
                .is_some_and(|o| o & (1 << pin) != 0);
            glitch |= out && high;
        }
    });
    check_eq!(unknown, 0, "writes outside the image");
    check!(
        !glitch,
        "a pin was a high output on the way to the safe state"
    );
    let safe = regs.safe();
    check!(safe.is_ok(), "not safe: {safe:?}");
    check_eq!(
        regs.get(h743::TIM1 + h743::BDTR),
        Some(0x80),
        "TIM1 BDTR's other bits"
    );
    check_eq!(
        regs.get(h743::GPIOD + h743::MODER),
        Some(!(0b11 << 24) | 0b01 << 24),
        "GPIOD's other pins"
    );
    let before = regs.regs;
    safety::apply(|a, c, s| {
        regs.rmw(a, c, s);
    });
    check!(
        before == regs.regs,
        "a second application changed something"
    );
    // The cost of the sequence on the M7, on plain RAM words (the board's are volatile accesses
    // to the same number of registers).
    let mut ram = [0u32; 12];
    let n = cx.count(|| {
        safety::apply(|a, c, s| {
            let w = &mut ram[(a as usize >> 2) % 12];
            *w = core::hint::black_box((*w & !c) | s);
        })
    });
    cx.figure("failsafe.safe_state_writes", n, "instructions", Some(1_000))
}

/// Polls the bench until `until_us`, sending a heartbeat every [`limits::HEARTBEAT_MS`] while
/// `alive`; records when heater and magnet were first both off, and the worst poll.
fn run_with_host(cx: &mut Cx<'_>, b: &mut Bench<'_, '_>, until_us: u64, alive: bool) -> Outcome {
    let beat = limits::HEARTBEAT_MS as u64 * 1000;
    let mut next = b.now_us + beat;
    while b.now_us + POLL_US <= until_us {
        b.now_us += POLL_US;
        b.poll(cx);
        if alive && b.now_us >= next {
            b.command(cx, &HostMsg::Heartbeat)?;
            next = b.now_us + beat;
        }
    }
    Ok(())
}

/// The bench heating towards 40 °C (the plate reads 25 °C) with the magnet holding, from a live
/// host, at 1.2 s (past the thermocouple's start-up grace).
fn heating_and_holding(cx: &mut Cx<'_>, b: &mut Bench<'_, '_>) -> Outcome {
    b.run_until(cx, 10 * POLL_US);
    b.command(
        cx,
        &HostMsg::Hello {
            protocol: PROTOCOL_VERSION,
        },
    )?;
    let c = b.hw.record().configure;
    b.command(cx, &HostMsg::Configure(c))?;
    b.command(
        cx,
        &HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 40.0,
            ramp_c_per_min: 30.0,
        }),
    )?;
    b.command(cx, &HostMsg::Arm)?;
    run_with_host(cx, b, 1_200_000, true)?;
    // The host's last frame before the injection (the lease counts from it).
    b.command(cx, &HostMsg::Heartbeat)?;
    check!(b.hw.heater_duty > 0.0, "not heating");
    check!(
        matches!(b.hw.magnet(), MagnetDrive::Hold { .. }),
        "magnet not holding: {:?}",
        b.hw.magnet()
    );
    check!(b.host.faults.is_empty(), "faults: {:?}", b.host.faults);
    Ok(())
}

/// How one fault through the application went: when heater/magnet were off and the frame came.
struct Went {
    heater_off_us: Option<u64>,
    magnet_off_us: Option<u64>,
    frame: Option<(u64, FaultReason)>,
    fault_poll: u64,
}

/// Polls from the injection at `t0` until `until_us` (heartbeats on if `alive`), noting when each
/// output went off, the first `Fault` frame, and the cost of the poll that sent it.
fn watch(
    cx: &mut Cx<'_>,
    b: &mut Bench<'_, '_>,
    until_us: u64,
    alive: bool,
) -> Result<Went, crate::Failure> {
    let beat = limits::HEARTBEAT_MS as u64 * 1000;
    let mut next = b.now_us + beat;
    let mut w = Went {
        heater_off_us: None,
        magnet_off_us: None,
        frame: None,
        fault_poll: 0,
    };
    while b.now_us + POLL_US <= until_us {
        b.now_us += POLL_US;
        let before = b.worst.total;
        b.poll(cx);
        if w.frame.is_none() {
            if let Some((at, f)) = b.host.faults.first() {
                w.frame = Some((*at, f.reason));
                w.fault_poll = b.worst.total - before;
            }
        }
        if b.hw.heater_duty == 0.0 {
            w.heater_off_us.get_or_insert(b.now_us);
        } else {
            w.heater_off_us = None;
        }
        if b.hw.magnet() == MagnetDrive::Off {
            w.magnet_off_us.get_or_insert(b.now_us);
        } else {
            w.magnet_off_us = None;
        }
        if alive && b.now_us >= next {
            b.command(cx, &HostMsg::Heartbeat)?;
            next = b.now_us + beat;
        }
    }
    Ok(w)
}

/// The application's part: a host that goes silent while the rig heats and holds, and thermocouple
/// faults while a live host heats; each within its stated time, the right `Fault` frame, and every
/// poll (the fault's included) within the application's poll budget.
pub fn app_goes_safe(cx: &mut Cx) -> Outcome {
    let rec = record(cx, "unloaded")?;
    let mut flash = [0xFFu8; FlashGeometry::H743_BANK2.bytes() as usize];
    let lease_us = limits::HOST_LEASE_MS as u64 * 1000;
    let tc_safe_us = 100_000 + POLL_US; // the next heater step (every 100 ms)
    let tc_fault_us = limits::TC_BAD_READS as u64 * 100_000 + POLL_US;
    type Inject = fn(u64) -> Converter;
    // (name, injection at t0 (None: the host goes silent), the reason, safe within, told within)
    let rows: [(&str, Option<Inject>, FaultReason, u64, u64); 6] = [
        (
            "host silent",
            None,
            FaultReason::LeaseExpired,
            lease_us + POLL_US,
            lease_us + POLL_US,
        ),
        (
            "thermocouple open",
            Some(|_| Converter::Answers(tc::encode(25.0, 25.0, sr::OPEN))),
            FaultReason::Heater(HeaterFault::OpenThermocouple),
            tc_safe_us,
            tc_fault_us,
        ),
        (
            "converter all zero",
            Some(|_| Converter::Answers([0; tc::REGISTERS])),
            FaultReason::Heater(HeaterFault::BadConverterData),
            tc_safe_us,
            tc_fault_us,
        ),
        (
            "converter all ones",
            Some(|_| Converter::Answers([0xFF; tc::REGISTERS])),
            FaultReason::Heater(HeaterFault::BadConverterData),
            tc_safe_us,
            tc_fault_us,
        ),
        (
            "cold junction implausible",
            Some(|_| Converter::Answers(tc::encode(25.0, 71.0, 0))),
            FaultReason::Heater(HeaterFault::ColdJunction),
            tc_safe_us,
            tc_fault_us,
        ),
        (
            "converter stale",
            Some(Converter::StaleSince),
            FaultReason::Heater(HeaterFault::NoReading),
            limits::TC_MAX_AGE_MS as u64 * 1000 + tc_safe_us,
            limits::TC_MAX_AGE_MS as u64 * 1000 + tc_fault_us,
        ),
    ];
    let mut worst_fault_poll = 0u64;
    let mut worst_poll = 0u64;
    let mut worst_stack = 0u32;
    for (name, inject, reason, safe_within, told_within) in rows {
        let mut ring = [0u8; 16 * 1024];
        let mut index = [0u32; MAX_RUN_BLOCKS];
        let store = RunStore::new([&mut ring[..]], &mut index);
        let mut b = Bench::new(cx, rec, store, &mut flash);
        heating_and_holding(cx, &mut b)?;
        let t0 = b.now_us;
        let alive = inject.is_some();
        if let Some(f) = inject {
            b.hw.converter = f(t0);
        }
        let w = watch(cx, &mut b, t0 + told_within + 200_000, alive)?;
        let from = t0;
        let heater = w.heater_off_us.map(|t| t - from);
        check!(
            heater.is_some_and(|d| d <= safe_within),
            "{name}: heater off {heater:?} µs after, stated {safe_within} µs"
        );
        if !alive {
            // The lease is not cut short, and both outputs go.
            check!(
                heater.is_some_and(|d| d >= lease_us),
                "{name}: heater off {heater:?} µs after the host's last frame, inside the lease"
            );
            let magnet = w.magnet_off_us.map(|t| t - from);
            check!(
                magnet.is_some_and(|d| d <= safe_within),
                "{name}: magnet off {magnet:?} µs after, stated {safe_within} µs"
            );
        } else {
            check!(
                matches!(b.hw.magnet(), MagnetDrive::Hold { .. }),
                "{name}: the magnet, not at fault, was let go"
            );
        }
        check!(w.frame.is_some(), "{name}: no Fault frame");
        let (at, got) = w.frame.unwrap_or((0, FaultReason::LeaseExpired));
        check_eq!(got, reason, "{name}");
        check!(
            at - from <= told_within,
            "{name}: Fault frame {} µs after, stated {told_within} µs",
            at - from
        );
        if alive {
            // The heater went off at the first bad read; the fault latches exactly
            // TC_BAD_READS − 1 heater steps (100 ms each) later, not one sooner or later.
            let steps = (limits::TC_BAD_READS as u64 - 1) * 100_000;
            let off = w.heater_off_us.unwrap_or(0);
            check!(
                at >= off && (at - off).abs_diff(steps) <= POLL_US,
                "{name}: Fault frame {} µs after the heater went off, expected {steps} µs",
                at.saturating_sub(off)
            );
        }
        check_eq!(b.host.faults.len(), 1, "{name}: one Fault frame");
        cx.note(format_args!(
            "{name}: heater off after {} ms, {:?} told after {} ms",
            heater.unwrap_or(0) / 1000,
            got,
            (at - from) / 1000
        ));
        worst_fault_poll = worst_fault_poll.max(w.fault_poll);
        worst_poll = worst_poll.max(b.worst.poll);
        worst_stack = worst_stack.max(b.worst.stack);
    }
    let counting = cx.counting();
    let on = |v: u64| counting.then_some(v);
    let r0 = cx.figure(
        "failsafe.app.fault_poll",
        on(worst_fault_poll),
        "instructions",
        Some(CALL_BUDGET),
    );
    let r1 = cx.figure(
        "failsafe.app.worst_poll",
        on(worst_poll),
        "instructions",
        Some(CALL_BUDGET),
    );
    let r2 = cx.figure(
        "failsafe.app.stack_bytes",
        on(worst_stack as u64),
        "bytes",
        Some(STACK_BUDGET),
    );
    r0.and(r1).and(r2)
}

/// The watchdog task's decision on the board's timing (app every 1 ms, thermocouple every 100 ms,
/// a look every [`FEED_PERIOD_MS`], the IWDG resetting [`limits::WATCHDOG_TIMEOUT_MS`] after the
/// last feed), across the wrap of the millisecond clock: all alive, never a reset; the thermocouple
/// task stuck: safe state and no more feeding within its allowed silence plus a look, the reset a
/// timeout later, the record naming the task; the core hogged (no task runs, the watchdog task
/// neither): the IWDG resets within its timeout of the last feed.
pub fn watchdog_liveness(cx: &mut Cx) -> Outcome {
    use tribo_firmware::watchdog::{task, Liveness, BOARD_TASKS, FEED_PERIOD_MS};
    /// What happened: (safe state at, reset at, the task named), ms since the stop.
    struct Run {
        safe_at: Option<u32>,
        reset_at: Option<u32>,
        stuck: Option<&'static str>,
        worst_look: u64,
    }
    // `stop`: (which task stops, when, ms after start); `hog`: the whole core stops.
    let simulate = |cx: &mut Cx, stop: Option<(usize, u32)>, hog: bool| -> Run {
        let start = u32::MAX - 5_000; // the clock wraps during the run
        let live = Liveness::new(BOARD_TASKS, start);
        let mut last_feed = start;
        let mut run = Run {
            safe_at: None,
            reset_at: None,
            stuck: None,
            worst_look: 0,
        };
        let mut starved = false;
        for k in 1..=10_000u32 {
            let now = start.wrapping_add(k);
            let stopped = |t: usize| stop.is_some_and(|(s, at)| (s == t || hog) && k >= at);
            if !stopped(task::APP) {
                live.check_in(task::APP, now);
            }
            if k % 100 == 0 && !stopped(task::THERMOCOUPLE) {
                live.check_in(task::THERMOCOUPLE, now);
            }
            let watchdog_runs = !(hog && stop.is_some_and(|(_, at)| k >= at));
            if watchdog_runs && k % FEED_PERIOD_MS == 0 && !starved {
                let mut v = Ok(());
                let n = cx.count(|| v = live.verdict(now));
                run.worst_look = run.worst_look.max(n.unwrap_or(0));
                match v {
                    Ok(()) => last_feed = now,
                    Err(s) => {
                        starved = true;
                        run.stuck = Some(s.name);
                        run.safe_at = stop.map(|(_, at)| k - at);
                    }
                }
            }
            if now.wrapping_sub(last_feed) > limits::WATCHDOG_TIMEOUT_MS {
                run.reset_at = stop.map(|(_, at)| k - at).or(Some(k));
                break;
            }
        }
        run
    };
    let alive = simulate(cx, None, false);
    check!(
        alive.reset_at.is_none() && alive.stuck.is_none(),
        "all tasks alive, yet reset at {:?} ms ({:?} silent)",
        alive.reset_at,
        alive.stuck
    );
    // The thermocouple task stops right after a check-in (at 2 s).
    let tc_silence = BOARD_TASKS[task::THERMOCOUPLE].max_silence_ms;
    let r = simulate(cx, Some((task::THERMOCOUPLE, 2_001)), false);
    check_eq!(r.stuck, Some("thermocouple"));
    cx.note(format_args!(
        "thermocouple task stopped: safe state after {:?} ms, reset after {:?} ms",
        r.safe_at, r.reset_at
    ));
    check!(
        r.safe_at
            .is_some_and(|t| t > tc_silence - 100 && t <= tc_silence + FEED_PERIOD_MS),
        "safe state {:?} ms after the thermocouple task stopped",
        r.safe_at
    );
    let timeout = limits::WATCHDOG_TIMEOUT_MS;
    check!(
        r.reset_at
            .is_some_and(|t| t <= tc_silence + FEED_PERIOD_MS + timeout + 1),
        "reset {:?} ms after the thermocouple task stopped",
        r.reset_at
    );
    // The record the board keeps names the task, and round-trips.
    let l = Liveness::new(BOARD_TASKS, 0);
    l.check_in(task::APP, tc_silence + 1);
    let s = l.verdict(tc_silence + 1);
    check!(s.is_err());
    if let Err(s) = s {
        let rec = reset::encode(ResetCause::Watchdog, s.message().as_bytes());
        let d = reset::decode(&rec);
        check!(
            matches!(&d, Some((ResetCause::Watchdog, m)) if m.contains("task thermocouple silent")),
            "record {d:?}"
        );
    }
    // The app task stuck (its loop stops; the watchdog task still runs).
    let r = simulate(cx, Some((task::APP, 3_000)), false);
    check_eq!(r.stuck, Some("app"));
    let app_silence = BOARD_TASKS[task::APP].max_silence_ms;
    check!(
        r.safe_at.is_some_and(|t| t <= app_silence + FEED_PERIOD_MS),
        "safe state {:?} ms after the app task stopped",
        r.safe_at
    );
    // The core hogged: nothing runs, the IWDG resets within its timeout of the last feed.
    let r = simulate(cx, Some((task::APP, 3_000)), true);
    check!(
        r.reset_at
            .is_some_and(|t| t <= FEED_PERIOD_MS + timeout + 1),
        "reset {:?} ms after the core stopped",
        r.reset_at
    );
    let w = alive.worst_look;
    let counting = cx.counting();
    cx.figure(
        "failsafe.watchdog_verdict",
        counting.then_some(w),
        "instructions",
        None,
    )
}
