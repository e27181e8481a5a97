//! The bring-up self-test: the measurements the application makes for `tribo selftest`
//! (`HostMsg::SelfTest`), through the same hardware traits as everything else, so that the board,
//! the virtual rig and the host's tests run the very same code; and the limits a report is judged
//! by, so that the host judges a report the way this crate documents it.
//!
//! * [`ConverterProbe`]: the converter started at a rate, every sample it delivers read for a
//!   while: how many it delivered (their index in the DMA's stream) against the rig's time base,
//!   and each analog channel's statistics on whatever its input holds.
//! * [`FlashProbe`]: one sector of the run flash that the stored run does not occupy, erased,
//!   checked erased, programmed with a pattern, read back, erased again; with the times and the
//!   flash controller's flags.
//! * [`Throughput`]: filler frames as fast as the link takes them (the host times them).
//! * [`ClockProbe`]: the LSI (an RC oscillator inside the chip, independent of the crystal)
//!   measured by a timer clocked from the HSE, one capture interval per poll.
//! * [`Deliberate`]: a panic or a stalled task on purpose, carried out by the board's task (or
//!   the virtual rig's emulation of it), never by the application, which cannot panic on any input.
//!
//! Judging ([`judge_rate`], [`judge_channel`], [`judge_flash`], [`judge_clock`], [`judge_reset`]) is pure: a
//! report in, a verdict and its reason out.

use crate::hal::{
    ClockCheck, FlashGeometry, LsiInterval, LsiTimer, RunFlash, SampleSource, ANALOG_CHANNELS,
};
use crate::wire::{
    filler_byte, BootReport, ChannelStats, ClockReport, ConverterReport, FlashReport, OutputCheck,
    OutputsReport, ResetCause, SampleClock, SELFTEST_CHANNELS, SELFTEST_OUTPUTS,
};

const _: () = assert!(SELFTEST_CHANNELS == ANALOG_CHANNELS);

/// The STM32H743's pins of the analog inputs, in [`crate::wire::Channel::ALL`]'s order
/// (displacement, velocity, force, ECR): the board scans them in this order (`tribo-board`'s
/// `board::init`), `tribo selftest` names them.
pub const ANALOG_PINS: [&str; ANALOG_CHANNELS] = ["PA3", "PC0", "PB1", "PF11"];
/// FLASH_SR2's flags in bits 17..=28 on the STM32H743 (errors, ECC events, CRC end): the board
/// logs them, `tribo selftest` judges them.
pub const FLASH_SR2_FLAGS: u32 = 0x1FFE_0000;

/// Shortest and longest converter check, ms.
pub const CONVERTER_MS: core::ops::RangeInclusive<u32> = 100..=60_000;
/// Largest slice of the flash one check programs (one sector at most).
pub const FLASH_MAX_BYTES: u32 = 128 * 1024;
/// Bytes a flash check reads back and compares per poll (bounds a poll's work: ~5k instructions
/// on the M7, `cargo xtask target-test app::selftest_checks`).
const READ_PER_POLL: usize = 512;

/// Samples per chunk read from the converter.
const CHUNK: usize = 32;

/// The converter check in progress (see the module docs).
#[derive(Debug, Clone)]
pub struct ConverterProbe {
    clock: SampleClock,
    until_us: u64,
    /// (index, time) of the first read, and of the latest.
    first: Option<(u64, u64)>,
    last: (u64, u64),
    /// Index of the sample expected next.
    next: u64,
    lost: u64,
    n: u64,
    sum: [u64; ANALOG_CHANNELS],
    sum_sq: [u64; ANALOG_CHANNELS],
    min: [u16; ANALOG_CHANNELS],
    max: [u16; ANALOG_CHANNELS],
    rail: [u32; ANALOG_CHANNELS],
}

impl ConverterProbe {
    /// A check of the converter just started with `clock` at `now_us`, for `ms`.
    pub fn new(clock: SampleClock, now_us: u64, ms: u32) -> Self {
        let ms = ms.clamp(*CONVERTER_MS.start(), *CONVERTER_MS.end());
        ConverterProbe {
            clock,
            until_us: now_us + ms as u64 * 1000,
            first: None,
            last: (0, now_us),
            next: 0,
            lost: 0,
            n: 0,
            sum: [0; ANALOG_CHANNELS],
            sum_sq: [0; ANALOG_CHANNELS],
            min: [u16::MAX; ANALOG_CHANNELS],
            max: [0; ANALOG_CHANNELS],
            rail: [0; ANALOG_CHANNELS],
        }
    }

    /// Reads every sample the converter has delivered by `now_us`; the report once the check's
    /// time is over. The first read is the time base's origin: its samples are in the statistics,
    /// not in the count.
    pub fn step<S: SampleSource + ?Sized>(
        &mut self,
        adc: &mut S,
        now_us: u64,
    ) -> Option<ConverterReport> {
        let mut buf = [[0u16; ANALOG_CHANNELS]; CHUNK];
        loop {
            let b = adc.adc_read(&mut buf);
            if b.first > self.next {
                self.lost += b.first - self.next;
            }
            self.next = b.end();
            for s in &buf[..b.len] {
                self.n += 1;
                for (c, &v) in s.iter().enumerate() {
                    self.sum[c] += v as u64;
                    self.sum_sq[c] += v as u64 * v as u64;
                    self.min[c] = self.min[c].min(v);
                    self.max[c] = self.max[c].max(v);
                    if v == 0 || v == u16::MAX {
                        self.rail[c] += 1;
                    }
                }
            }
            if b.len < CHUNK {
                break;
            }
        }
        if self.first.is_none() {
            self.first = Some((self.next, now_us));
            // Samples lost before the first read are not the converter's fault.
            self.lost = 0;
        }
        self.last = (self.next, now_us);
        (now_us >= self.until_us).then(|| self.report())
    }

    /// The report of what was read so far.
    pub fn report(&self) -> ConverterReport {
        let (first_index, first_us) = self.first.unwrap_or(self.last);
        let mut channels = [ChannelStats::default(); SELFTEST_CHANNELS];
        for (c, ch) in channels.iter_mut().enumerate() {
            if self.n == 0 {
                continue;
            }
            let n = self.n as f64;
            let mean = self.sum[c] as f64 / n;
            let var = (self.sum_sq[c] as f64 / n - mean * mean).max(0.0);
            *ch = ChannelStats {
                min: self.min[c],
                max: self.max[c],
                mean: mean as f32,
                sd: crate::wire::sqrt_f32(var as f32),
                at_rail: self.rail[c],
            };
        }
        ConverterReport {
            clock: self.clock,
            first_index,
            last_index: self.last.0,
            first_us,
            last_us: self.last.1,
            lost: self.lost.min(u32::MAX as u64) as u32,
            samples: self.n.min(u32::MAX as u64) as u32,
            channels,
        }
    }
}

/// Byte `i` of the pattern a flash check programs into `sector`.
pub const fn flash_pattern(sector: u32, i: usize) -> u8 {
    filler_byte(sector ^ 0x5E1F_7E57, i)
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Waiting for the flash to be free, then the first erase.
    Start,
    Erasing {
        second: bool,
    },
    /// Checking `bytes` read back erased (after either erase) or as programmed.
    Verify {
        what: Expect,
        at: u32,
    },
    Programming {
        at: u32,
    },
    Done,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Expect {
    Erased { second: bool },
    Pattern,
}

/// The flash check in progress (see the module docs): one operation or one slice of reading per
/// poll, so the application's polls keep their budget. Times are the rig's time base at the polls
/// that started and saw the end of each step (resolution: one poll).
#[derive(Debug, Clone)]
pub struct FlashProbe {
    phase: Phase,
    base: u32,
    since_us: u64,
    report: FlashReport,
}

impl FlashProbe {
    /// A check of `sector`, `bytes` of it (whole flash words, at least one, at most the sector).
    pub fn new(sector: u32, bytes: u32, g: FlashGeometry) -> Self {
        let word = crate::hal::FLASH_WORD as u32;
        let bytes = bytes.clamp(word, g.sector_bytes.min(FLASH_MAX_BYTES)) / word * word;
        FlashProbe {
            phase: Phase::Start,
            base: sector * g.sector_bytes,
            since_us: 0,
            report: FlashReport {
                sector,
                bytes,
                erase_ok: true,
                program_ok: true,
                mismatches: 0,
                erase_us: 0,
                program_us: 0,
                read_us: 0,
                erase2_us: 0,
                flags: None,
            },
        }
    }

    fn elapsed(&self, now_us: u64) -> u32 {
        now_us.saturating_sub(self.since_us).min(u32::MAX as u64) as u32
    }

    /// One step at `now_us`; the report once the check is over.
    pub fn step<F: RunFlash + ?Sized>(
        &mut self,
        flash: &mut F,
        now_us: u64,
    ) -> Option<FlashReport> {
        if flash.flash_busy() {
            return None;
        }
        let t = self.elapsed(now_us);
        let r = &mut self.report;
        match self.phase {
            Phase::Start => {
                // Flags of earlier operations are not this check's.
                let _ = flash.flash_take_error();
                let _ = flash.flash_take_flags();
                if flash.flash_erase(r.sector) {
                    self.since_us = now_us;
                    self.phase = Phase::Erasing { second: false };
                } else {
                    r.erase_ok = false;
                    self.phase = Phase::Done;
                }
            }
            Phase::Erasing { second } => {
                if flash.flash_take_error() {
                    r.erase_ok = false;
                }
                if second {
                    r.erase2_us = t;
                } else {
                    r.erase_us = t;
                }
                self.since_us = now_us;
                self.phase = Phase::Verify {
                    what: Expect::Erased { second },
                    at: 0,
                };
            }
            Phase::Verify { what, at } => {
                let n = (r.bytes - at).min(READ_PER_POLL as u32) as usize;
                let mut buf = [0u8; READ_PER_POLL];
                if flash.flash_read(self.base + at, &mut buf[..n]) {
                    let sector = r.sector;
                    r.mismatches += buf[..n]
                        .iter()
                        .enumerate()
                        .filter(|&(i, &b)| {
                            b != match what {
                                Expect::Pattern => flash_pattern(sector, at as usize + i),
                                Expect::Erased { .. } => 0xFF,
                            }
                        })
                        .count() as u32;
                } else {
                    r.mismatches += n as u32;
                }
                let at = at + n as u32;
                if at < r.bytes {
                    self.phase = Phase::Verify { what, at };
                } else {
                    match what {
                        Expect::Erased { second: false } => {
                            self.since_us = now_us;
                            self.phase = Phase::Programming { at: 0 };
                        }
                        Expect::Pattern => {
                            r.read_us = t;
                            if flash.flash_erase(r.sector) {
                                self.since_us = now_us;
                                self.phase = Phase::Erasing { second: true };
                            } else {
                                r.erase_ok = false;
                                self.phase = Phase::Done;
                            }
                        }
                        Expect::Erased { second: true } => self.phase = Phase::Done,
                    }
                }
            }
            Phase::Programming { at } => {
                if at > 0 && flash.flash_take_error() {
                    r.program_ok = false;
                }
                if at >= r.bytes || !r.program_ok {
                    r.program_us = t;
                    self.since_us = now_us;
                    self.phase = Phase::Verify {
                        what: Expect::Pattern,
                        at: 0,
                    };
                } else {
                    let n = (r.bytes - at).min(crate::hal::FLASH_MAX_PROGRAM as u32) as usize;
                    let mut data = [0u8; crate::hal::FLASH_MAX_PROGRAM];
                    for (i, b) in data[..n].iter_mut().enumerate() {
                        *b = flash_pattern(r.sector, at as usize + i);
                    }
                    if flash.flash_program(self.base + at, &data[..n]) {
                        self.phase = Phase::Programming { at: at + n as u32 };
                    } else {
                        r.program_ok = false;
                    }
                }
            }
            Phase::Done => {}
        }
        if self.phase == Phase::Done {
            self.report.flags = flash.flash_take_flags();
            return Some(self.report);
        }
        None
    }
}

/// The ECR range-select patterns an outputs check drives, one per step: every pin high alone, each
/// pin low while another is high, within the ranges that exist (`0..ecr::RANGES`).
pub const RANGE_PATTERNS: [u8; 5] = [0b000, 0b001, 0b010, 0b100, 0b011];
/// The lamp patterns, one per step (green bit 0, amber 1, red 2).
pub const LAMP_PATTERNS: [u8; 5] = [0b000, 0b001, 0b010, 0b100, 0b111];
/// The ECR source, V, one per step: off and the largest the source may give, alternately.
pub const SOURCE_PATTERNS: [f32; 5] = [
    0.0,
    crate::ecr::MAX_SOURCE_V,
    0.0,
    crate::ecr::MAX_SOURCE_V,
    crate::ecr::START_SOURCE_V,
];
/// The outputs of an outputs check, in the report's order, and the pins the board reads.
pub const OUTPUT_NAMES: [&str; crate::wire::SELFTEST_OUTPUTS] =
    ["heater", "magnet", "ecr-source", "ecr-range", "lamps"];

/// An outputs check in progress: at each step (one per application poll) the outputs read back
/// are compared with what the previous step drove, then the next pattern is driven; the heater and
/// the magnet stay off throughout (the check is refused while either is on), and their pins must
/// read low. A pin's input level settles within a few clock cycles of its output; a poll apart
/// leaves ~0.5 ms.
#[derive(Debug, Clone)]
pub struct OutputsProbe {
    step: usize,
    report: OutputsReport,
}

impl Default for OutputsProbe {
    fn default() -> Self {
        Self::new()
    }
}

impl OutputsProbe {
    pub const fn new() -> Self {
        OutputsProbe {
            step: 0,
            report: OutputsReport {
                steps: 0,
                outputs: [OutputCheck {
                    sensed: false,
                    mismatches: 0,
                    driven: 0,
                    read: 0,
                }; SELFTEST_OUTPUTS],
            },
        }
    }

    fn note(&mut self, i: usize, driven: u16, read: Option<u16>) {
        let o = &mut self.report.outputs[i];
        let Some(read) = read else {
            o.sensed = false;
            return;
        };
        o.sensed = true;
        if read != driven {
            if o.mismatches == 0 {
                (o.driven, o.read) = (driven, read);
            }
            o.mismatches = o.mismatches.saturating_add(1);
        } else if o.mismatches == 0 {
            (o.driven, o.read) = (driven, read);
        }
    }

    /// One step: compares what reads back with what the last step drove, then drives the next
    /// pattern (ECR range and source here, the lamps through [`OutputsProbe::lamps`]); the report
    /// once every pattern was read back. The caller restores the ECR front end afterwards.
    pub fn step<H: crate::hal::EcrFrontEnd + crate::hal::OutputSense + ?Sized>(
        &mut self,
        hw: &mut H,
    ) -> Option<OutputsReport> {
        if self.step > 0 {
            let k = self.step - 1;
            let s = hw.sense_outputs();
            self.note(0, 0, s.heater_pin.map(u16::from));
            self.note(1, 0, s.magnet_pins.map(u16::from));
            self.note(
                2,
                crate::ecr::source_dac_code(SOURCE_PATTERNS[k]),
                s.ecr_dac_code,
            );
            self.note(3, RANGE_PATTERNS[k] as u16, s.ecr_range_pins.map(u16::from));
            self.note(4, LAMP_PATTERNS[k] as u16, s.lamp_pins.map(u16::from));
            self.report.steps = self.step as u8;
        }
        if self.step >= RANGE_PATTERNS.len() {
            return Some(self.report);
        }
        hw.set_ecr_range(RANGE_PATTERNS[self.step]);
        hw.set_ecr_source(SOURCE_PATTERNS[self.step]);
        self.step += 1;
        None
    }

    /// The lamps of the pattern out now (the application sets them after its step).
    pub fn lamps(&self) -> crate::hal::Lamps {
        let b = LAMP_PATTERNS[self.step.saturating_sub(1).min(LAMP_PATTERNS.len() - 1)];
        crate::hal::Lamps {
            green: b & 1 != 0,
            amber: b & 2 != 0,
            red: b & 4 != 0,
        }
    }
}

/// An outputs check: `Err` names the outputs that read back wrong (by [`OUTPUT_NAMES`] index).
pub fn judge_output(r: &OutputsReport, i: usize) -> Option<Result<(), &'static str>> {
    let o = r.outputs.get(i)?;
    if !o.sensed {
        return None;
    }
    Some(if r.steps as usize != RANGE_PATTERNS.len() {
        Err("the check did not drive every pattern")
    } else if o.mismatches > 0 {
        Err(match i {
            0 | 1 => "a pin reads high while the output is off",
            2 => "the DAC does not convert the code written",
            _ => "a pin does not read back what was driven",
        })
    } else {
        Ok(())
    })
}

/// Longest wait for the LSI's ready flag, µs. The LSI starts within about a hundred µs (DS12110's
/// start-up time); on the board it already runs (the IWDG, started at reset, forces it on), so
/// this only bounds a chip that does not start it.
pub const LSI_READY_US: u64 = 5_000;
/// Most intervals one clock check measures (one per poll).
pub const CLOCK_MAX_INTERVALS: u16 = 2_000;
/// Waits without a capture after which a clock check gives up: the LSI does not reach the timer.
pub const CLOCK_MAX_TIMEOUTS: u16 = 3;

/// A clock check in progress: the LSI switched on (if it was not), its ready flag awaited, then
/// one capture interval measured per poll until `want` are, or the LSI is not there; the LSI and
/// the timer are left as they were found.
#[derive(Debug, Clone)]
pub struct ClockProbe {
    want: u16,
    started_us: u64,
    timer: Option<LsiTimer>,
    report: ClockReport,
}

impl ClockProbe {
    /// Starts a check of `intervals` intervals (at least 1, at most [`CLOCK_MAX_INTERVALS`]).
    pub fn start<H: ClockCheck + ?Sized>(hw: &mut H, intervals: u16, now_us: u64) -> Self {
        let timer = hw.lsi_start();
        ClockProbe {
            want: intervals.clamp(1, CLOCK_MAX_INTERVALS),
            started_us: now_us,
            timer,
            report: ClockReport {
                available: timer.is_some(),
                timer_hz: timer.map_or(0, |t| t.timer_hz),
                periods_per_capture: timer.map_or(0, |t| t.periods_per_capture),
                ticks_min: u32::MAX,
                ..ClockReport::default()
            },
        }
    }

    fn finish<H: ClockCheck + ?Sized>(&mut self, hw: &mut H) -> Option<ClockReport> {
        if self.timer.is_some() {
            hw.lsi_stop();
        }
        if self.report.intervals == 0 {
            self.report.ticks_min = 0;
        }
        Some(self.report)
    }

    /// Stops the timer (a check cancelled before its report).
    pub fn cancel<H: ClockCheck + ?Sized>(&mut self, hw: &mut H) {
        if self.timer.take().is_some() {
            hw.lsi_stop();
        }
    }

    /// One step at `now_us`; the report once the check is over.
    pub fn step<H: ClockCheck + ?Sized>(&mut self, hw: &mut H, now_us: u64) -> Option<ClockReport> {
        if self.timer.is_none() {
            return self.finish(hw);
        }
        let r = &mut self.report;
        if !r.lsi_ready {
            if hw.lsi_ready() {
                r.lsi_ready = true;
                return None;
            }
            if now_us.saturating_sub(self.started_us) > LSI_READY_US {
                return self.finish(hw);
            }
            return None;
        }
        match hw.lsi_interval() {
            LsiInterval::Ticks(t) => {
                r.intervals += 1;
                r.ticks_sum += t as u64;
                r.ticks_min = r.ticks_min.min(t);
                r.ticks_max = r.ticks_max.max(t);
            }
            LsiInterval::Overcapture => r.overcaptures = r.overcaptures.saturating_add(1),
            LsiInterval::Timeout => r.timeouts = r.timeouts.saturating_add(1),
        }
        let tries = r.intervals as u32 + r.overcaptures as u32 + r.timeouts as u32;
        if r.intervals >= self.want
            || r.timeouts >= CLOCK_MAX_TIMEOUTS
            || tries >= 2 * self.want as u32 + 8
        {
            return self.finish(hw);
        }
        None
    }
}

/// A throughput check in progress: filler frames `next..frames` still to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Throughput {
    pub next: u32,
    pub frames: u32,
    pub len: u16,
    pub refused: u32,
}

/// What the board (or the virtual rig) must do on purpose after acknowledging the command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Deliberate {
    /// Panic with [`crate::wire::DELIBERATE_PANIC`].
    Panic,
    /// Stop the thermocouple task (it waits forever): the watchdog must catch it.
    Stall,
}

// ---------------------------------------------------------------------------------------------------
// Judging
// ---------------------------------------------------------------------------------------------------

/// A delivered sample count may differ from the time base's by this many samples (the two reads'
/// quantisation: a sample may be converting at each) ...
pub const RATE_SLACK_SAMPLES: f64 = 3.0;
/// ... plus this much of it: the sample timer and the time base both run from the crystal, so any
/// larger difference is the trigger chain dropping or adding conversions.
pub const RATE_TOLERANCE_PPM: f64 = 100.0;
/// A channel whose samples sit at a rail more than this fraction of the time is "at a rail".
pub const RAIL_FRACTION: f64 = 0.5;
/// Largest sector erase time accepted, µs (the STM32H743's datasheet maximum at ×64
/// parallelism; a PSIZE left at ×8 erases several times slower).
pub const ERASE_MAX_US: u32 = 2_200_000;
/// Slowest link accepted, bytes/s: the raw data of the fastest run (20 kS/s, five channels of
/// two bytes), so a live stream never waits on the link.
pub const MIN_THROUGHPUT_BYTES_S: f64 = 200_000.0;

/// The converter's rate against the time base: (measured rate S/s, deviation ppm, within the
/// tolerance).
pub fn judge_rate(r: &ConverterReport) -> (f64, f64, bool) {
    let dt_s = r.last_us.saturating_sub(r.first_us) as f64 * 1e-6;
    let got = r.last_index.saturating_sub(r.first_index) as f64;
    let nominal = r.clock.rate_hz();
    if dt_s <= 0.0 || nominal.is_nan() || nominal <= 0.0 {
        return (0.0, f64::NAN, false);
    }
    let expected = nominal * dt_s;
    let rate = got / dt_s;
    let ppm = (got / expected - 1.0) * 1e6;
    let ok = (got - expected).abs() <= RATE_SLACK_SAMPLES + expected * RATE_TOLERANCE_PPM * 1e-6;
    (rate, ppm, ok)
}

/// What is wrong with a channel on open inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelProblem {
    /// No sample was read.
    NoSamples,
    /// Pinned at a converter rail (0 or 65535) most of the time: shorted, saturated, or a dead
    /// front end.
    AtRail,
    /// Every sample the same code: a converter that does not convert, a DMA that does not write.
    Stuck,
}

/// A channel's statistics on open (or quiet) inputs: in range and moving.
pub fn judge_channel(s: &ChannelStats, samples: u32) -> Result<(), ChannelProblem> {
    if samples == 0 {
        return Err(ChannelProblem::NoSamples);
    }
    if s.at_rail as f64 > RAIL_FRACTION * samples as f64 {
        return Err(ChannelProblem::AtRail);
    }
    if s.min == s.max {
        return Err(ChannelProblem::Stuck);
    }
    Ok(())
}

/// The held position of the pin on the rig as built (`Configure::real_rig`'s initial amplitude), m.
pub const REST_X0_M: f32 = 667e-6;
/// Largest speed of a pin at rest, m/s: 1 % of the velocity channel's ±0.25 m/s.
pub const REST_SPEED_M_S: f32 = 2.5e-3;
/// Largest force on a pin at rest, N: static friction, at most μs·N ≈ 0.1 × 0.7 N on this rig;
/// 10 % of the force channel's ±1 N.
pub const REST_FORCE_N: f32 = 0.1;

/// Each analog input's signature at rest on the rig as built (front ends connected, the pin held
/// by the magnet at x0 or come to rest, the contact loaded, the ECR controller measuring it): the
/// window, in the channel's SI unit, its mean must fall in.
///
/// * displacement: within ±1.1·x0 (held at x0, or at rest inside the stick band around 0);
/// * velocity: within ±[`REST_SPEED_M_S`] (a pin at rest);
/// * force: within ±[`REST_FORCE_N`] (static friction at most);
/// * ECR: from the controller's lower switching threshold (`ecr::UP_FRACTION` of full scale:
///   below it the controller raises the gain, so a conducting contact reads above it) to full
///   scale. An open contact (unloaded) reads below it, like a grounded input.
///
/// Bipolar channels rest at mid-scale and the ECR output above a few tens of mV, so an input
/// grounded (even through an offset of a few hundred counts) fails its window, and every swap of
/// two inputs but velocity ↔ force fails the window of one of the two at least (a bipolar input's
/// mid-scale on the ECR pin reads 1.65 V, a plausible ECR output). Velocity and force both rest at their zero: a swap of those
/// two is not seen at rest.
pub fn rest_window(channel: usize) -> (f32, f32) {
    match channel {
        0 => (-1.1 * REST_X0_M, 1.1 * REST_X0_M),
        1 => (-REST_SPEED_M_S, REST_SPEED_M_S),
        2 => (-REST_FORCE_N, REST_FORCE_N),
        _ => (
            crate::ecr::UP_FRACTION * crate::ecr::FULL_SCALE_V,
            crate::ecr::FULL_SCALE_V,
        ),
    }
}

/// A channel's mean at rest against its [`rest_window`], through its calibration: `Ok(si)` or
/// `Err(si)` outside it.
pub fn judge_identity(
    s: &ChannelStats,
    channel: usize,
    cal: &crate::wire::ChannelCal,
) -> Result<f32, f32> {
    let si = cal.gain * (s.mean.clamp(0.0, 65535.0) - cal.zero);
    let (lo, hi) = rest_window(channel);
    if (lo..=hi).contains(&si) {
        Ok(si)
    } else {
        Err(si)
    }
}

/// The LSI's frequency limits over the part's whole range (junction −40…110 °C, VDD 1.62–3.6 V),
/// Hz: DS12110 (STM32H742xI/G, STM32H743xI/G datasheet), table "LSI oscillator characteristics":
/// 29.76 kHz min, 32 kHz typical, 33.6 kHz max (at 3.3 V and 25 °C it gives 31.4–32.6 kHz).
pub const LSI_MIN_HZ: f64 = 29_760.0;
pub const LSI_TYP_HZ: f64 = 32_000.0;
pub const LSI_MAX_HZ: f64 = 33_600.0;

/// A clock check's figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockFigures {
    /// The LSI's frequency as the HSE-clocked timer measures it (timer ticks read at the rate the
    /// firmware assumes), Hz: the LSI's true frequency divided by the HSE's error factor.
    pub lsi_hz: f64,
    /// Mean timer ticks per capture interval.
    pub ticks_mean: f64,
    /// The HSE's frequency over its nominal that the measurement allows, given the LSI anywhere
    /// in [`LSI_MIN_HZ`]…[`LSI_MAX_HZ`]: (least, most). The check passes when 1 is inside.
    pub hse_ratio: (f64, f64),
    /// The HSE's frequency over its nominal if the LSI ran at its typical [`LSI_TYP_HZ`] (a
    /// figure for the eye, not the judge).
    pub hse_ratio_typ: f64,
}

/// Why a clock check has no verdict, or what is wrong.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClockProblem {
    /// This rig has no timer input on the LSI (an emulator, replayed hardware): not measurable
    /// here, neither pass nor fail.
    NotAvailable,
    /// The LSI's ready flag did not come within [`LSI_READY_US`]: not measurable.
    LsiNotReady,
    /// No interval was measured (every wait timed out or every interval was overwritten): not
    /// measurable.
    NoInterval,
    /// The LSI, measured through the HSE, is outside the LSI's datasheet limits: the HSE (or the
    /// clock tree from it) is not what the firmware assumes.
    OutOfRange(ClockFigures),
}

/// A clock check judged: the LSI measured through the HSE against the LSI's own limits.
pub fn judge_clock(r: &ClockReport) -> Result<ClockFigures, ClockProblem> {
    if !r.available {
        return Err(ClockProblem::NotAvailable);
    }
    if !r.lsi_ready {
        return Err(ClockProblem::LsiNotReady);
    }
    if r.intervals == 0 || r.ticks_sum == 0 || r.timer_hz == 0 || r.periods_per_capture == 0 {
        return Err(ClockProblem::NoInterval);
    }
    let ticks_mean = r.ticks_sum as f64 / r.intervals as f64;
    let lsi_hz = r.timer_hz as f64 * r.periods_per_capture as f64 / ticks_mean;
    let f = ClockFigures {
        lsi_hz,
        ticks_mean,
        hse_ratio: (LSI_MIN_HZ / lsi_hz, LSI_MAX_HZ / lsi_hz),
        hse_ratio_typ: LSI_TYP_HZ / lsi_hz,
    };
    if (LSI_MIN_HZ..=LSI_MAX_HZ).contains(&lsi_hz) {
        Ok(f)
    } else {
        Err(ClockProblem::OutOfRange(f))
    }
}

/// A flash check: `Err` names the first thing wrong.
pub fn judge_flash(r: &FlashReport) -> Result<(), &'static str> {
    if !r.erase_ok {
        return Err("an erase was refused or failed");
    }
    if !r.program_ok {
        return Err("a program was refused or failed");
    }
    if r.mismatches > 0 {
        return Err("bytes read back wrong");
    }
    if r.erase_us > ERASE_MAX_US || r.erase2_us > ERASE_MAX_US {
        return Err("a sector erase took longer than the datasheet's maximum");
    }
    Ok(())
}

/// A thermocouple check: the register file judged exactly as the heater judges every read
/// ([`crate::thermocouple::check`]): the chip answered recently and not with all zeros or all
/// ones, its configuration reads back (type K, 50 Hz filter, automatic conversions, open-circuit
/// detection on: CR0 0x91), no fault flag (open thermocouple, over/under-voltage, ranges), the cold
/// junction within `limits::COLD_JUNCTION_C` and the plate not below `limits::PLATE_MIN_C`.
pub fn judge_thermocouple(
    r: &crate::wire::ThermocoupleReport,
) -> Result<crate::thermocouple::Reading, crate::thermocouple::BadRead> {
    crate::thermocouple::check(r.registers.as_ref().map(|g| (g, r.age_us)))
}

/// The boot report after a deliberate act: `Err` says what it should have said.
pub fn judge_reset(d: Deliberate, boot: &BootReport) -> Result<(), &'static str> {
    match d {
        Deliberate::Panic => {
            if boot.cause != ResetCause::Panic {
                Err("the boot report does not say Panic")
            } else if !boot.message.contains(crate::wire::DELIBERATE_PANIC) {
                Err("the boot report's message is not the deliberate panic's")
            } else {
                Ok(())
            }
        }
        Deliberate::Stall => {
            if boot.cause != ResetCause::Watchdog {
                Err("the boot report does not say Watchdog")
            } else if !boot.message.contains("thermocouple") {
                Err("the boot report does not name the stalled task (thermocouple)")
            } else {
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests;
