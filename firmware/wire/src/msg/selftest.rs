//! The bring-up self-test (`tribo selftest`): what the host asks ([`SelfTestCheck`], in
//! [`HostMsg::SelfTest`](super::HostMsg::SelfTest)) and what the rig measured
//! ([`SelfTestReport`], in [`DeviceMsg::SelfTest`](super::DeviceMsg::SelfTest)).
//!
//! The rig measures; the host judges (`tribo_firmware::selftest` holds the limits, so that a
//! report reads the same wherever it is judged).

use super::*;

/// Analog channels a converter self-test reports (displacement, velocity, force, ECR: the ADC's
/// scan; the temperature comes from the thermocouple converter, not from the ADC).
pub const SELFTEST_CHANNELS: usize = 4;
/// Most payload bytes of one throughput filler frame.
pub const FILLER_MAX: usize = 256;

wire_type! {
    /// One check of the bring-up self-test. Each is answered by `Ack` (or `Error`: `Busy` while
    /// armed, running or still writing a run to flash), then, for the measured ones, by a
    /// [`SelfTestReport`].
    #[derive(Copy)]
    pub enum SelfTestCheck {
        /// Convert at `rate_hz` for `ms` milliseconds: the samples the converter delivered against
        /// the rig's time base, and each analog channel's statistics. Answered by
        /// [`SelfTestReport::Converter`].
        Converter { rate_hz: u32, ms: u32 },
        /// Erase one sector of the run flash that the stored run does not occupy, program
        /// `bytes` of a pattern, read them back, erase it again. Answered by
        /// [`SelfTestReport::Flash`].
        Flash { bytes: u32 },
        /// Send `frames` filler frames of `len` bytes (at most [`FILLER_MAX`]) as fast as the
        /// link takes them, then [`SelfTestReport::FillerDone`].
        Throughput { frames: u32, len: u16 },
        /// Panic on purpose (after the `Ack`): the next boot's report must say `Panic`, with the
        /// message [`DELIBERATE_PANIC`].
        Panic,
        /// Stop the thermocouple task on purpose (after the `Ack`): the watchdog must make the
        /// outputs safe and reset the rig, the boot report naming the task.
        Stall,
        /// The thermocouple converter's register file as the rig last read it (configuration,
        /// cold junction, plate, fault status). Answered by [`SelfTestReport::Thermocouple`].
        Thermocouple,
        /// Drive the outputs the rig may drive at rest through a few patterns (ECR range pins,
        /// lamps, ECR source DAC; heater and magnet held off) and read each back where the board
        /// can sense it. Refused while the heater heats or the magnet's coil is on. Answered by
        /// [`SelfTestReport::Outputs`].
        Outputs,
        /// Measure the low-speed internal RC oscillator (LSI) with a timer clocked from the HSE:
        /// `intervals` capture intervals, one per poll (an independent clock against the crystal
        /// every other rate derives from). Answered by [`SelfTestReport::Clock`].
        Clock { intervals: u16 },
    }
}

/// The message of the self-test's deliberate panic.
pub const DELIBERATE_PANIC: &str = "self-test: deliberate panic";

wire_type! {
    /// What the rig measured for a [`SelfTestCheck`].
    pub enum SelfTestReport {
        Converter(ConverterReport),
        Flash(FlashReport),
        /// Filler frame `index` of a throughput check: `data[i]` is
        /// [`filler_byte`]`(index, i)`.
        Filler {
            index: u32,
            data: heapless::Vec<u8, FILLER_MAX>,
        },
        /// Every filler frame was sent; `refused` times the link had no room and the frame
        /// waited.
        FillerDone { frames: u32, refused: u32 },
        Thermocouple(ThermocoupleReport),
        Outputs(OutputsReport),
        Clock(ClockReport),
    }
}

wire_type! {
    /// A clock check: the LSI (an RC oscillator independent of the crystal) measured in ticks of a
    /// timer clocked from the HSE, as the intervals between two consecutive input captures.
    #[derive(Copy, Default)]
    pub struct ClockReport {
        /// The rig has such a timer input (false: not on this rig, e.g. an emulator or replayed
        /// hardware; the other fields mean nothing).
        pub available: bool,
        /// The LSI was ready (its RDY flag) within the check's timeout.
        pub lsi_ready: bool,
        /// The timer's tick rate as the firmware configured it from the HSE's nominal frequency, Hz.
        pub timer_hz: u32,
        /// LSI periods per capture (the input-capture prescaler).
        pub periods_per_capture: u8,
        /// Intervals measured (two consecutive captures, none overwritten in between).
        pub intervals: u16,
        /// Intervals thrown away because a capture overwrote an unread one (overcapture flag).
        pub overcaptures: u16,
        /// Waits in which no capture came (the LSI does not reach the timer).
        pub timeouts: u16,
        /// Timer ticks per interval over the measured intervals: sum, least, most.
        pub ticks_sum: u64,
        pub ticks_min: u32,
        pub ticks_max: u32,
    }
}

/// Outputs an outputs check reports, in this order: heater gate, magnet bridge inputs, ECR
/// source DAC, ECR range-select pins, lamps.
pub const SELFTEST_OUTPUTS: usize = 5;

wire_type! {
    /// One output over an outputs check.
    #[derive(Copy, Default)]
    pub struct OutputCheck {
        /// The board reads this output back (a pin's input level, a DAC's output register);
        /// false: it cannot, and the other fields mean nothing.
        pub sensed: bool,
        /// Steps at which what was read back differed from what was driven.
        pub mismatches: u8,
        /// What was driven and what was read back at the first mismatch (at the last step when
        /// none): pin levels as bits, or the DAC's 12-bit code.
        pub driven: u16,
        pub read: u16,
    }
}

wire_type! {
    /// An outputs check: `steps` patterns driven and read back.
    #[derive(Copy)]
    pub struct OutputsReport {
        pub steps: u8,
        pub outputs: [OutputCheck; SELFTEST_OUTPUTS],
    }
}

wire_type! {
    /// A thermocouple check: the MAX31856's register file (0x00–0x0F) as the rig's thermocouple
    /// task last read it, and how old that read is; `None` if the converter never answered.
    #[derive(Copy)]
    pub struct ThermocoupleReport {
        pub registers: Option<[u8; 16]>,
        /// µs between that read and the check (`u64::MAX` without one).
        pub age_us: u64,
    }
}

/// Byte `i` of filler frame `index` (a pattern a lost, repeated or shifted byte breaks).
pub const fn filler_byte(index: u32, i: usize) -> u8 {
    let x = index.wrapping_mul(0x9E37_79B1) ^ (i as u32).wrapping_mul(0x85EB_CA77);
    (x ^ (x >> 13) ^ (x >> 24)) as u8
}

wire_type! {
    /// One analog channel over a converter check: raw 16-bit counts.
    #[derive(Copy, Default)]
    pub struct ChannelStats {
        pub min: u16,
        pub max: u16,
        pub mean: f32,
        /// Standard deviation, counts.
        pub sd: f32,
        /// Samples at a rail of the converter (0 or 65535).
        pub at_rail: u32,
    }
}

wire_type! {
    /// A converter check: samples delivered by the converter's DMA (by their index in its stream)
    /// between two instants of the rig's time base, and the channels' statistics.
    #[derive(Copy)]
    pub struct ConverterReport {
        /// The rate the sample timer really runs at (the clock the converter started with).
        pub clock: SampleClock,
        /// Converter stream indices at the first and last read.
        pub first_index: u64,
        pub last_index: u64,
        /// Rig time base (µs) at the first and last read.
        pub first_us: u64,
        pub last_us: u64,
        /// Samples lost (the reader fell behind, the ADC overran) in between.
        pub lost: u32,
        /// Samples read (and in the statistics).
        pub samples: u32,
        pub channels: [ChannelStats; SELFTEST_CHANNELS],
    }
}

wire_type! {
    /// A flash check on one sector of the run flash.
    #[derive(Copy)]
    pub struct FlashReport {
        pub sector: u32,
        pub bytes: u32,
        /// Each operation was accepted and finished without an error.
        pub erase_ok: bool,
        pub program_ok: bool,
        /// Bytes that read back different from what was programmed (or not erased to 0xFF).
        pub mismatches: u32,
        /// Times of the first erase, of programming `bytes` (all of it), of the read-back and of
        /// the final erase, µs of the rig's time base.
        pub erase_us: u32,
        pub program_us: u32,
        pub read_us: u32,
        pub erase2_us: u32,
        /// The flash controller's status and error flags the operations raised (FLASH_SR2 on the
        /// STM32H743); `None` on a rig without them (the virtual rig's simulated flash).
        pub flags: Option<u32>,
    }
}
