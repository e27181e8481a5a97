//! Replay hardware: the [`tribo_firmware::hal`] traits fed from a simulated [`Record`].
//!
//! Time is virtual: before each call into the application the test brings the hardware to the call's
//! time with [`Replay::advance`] (outside the measured call, as the board's DMA and flash work in
//! the background). The converter is the firmware's own model of the board's
//! ([`ConverterModel`]: sample timer, DMA ring, and the board's ring reader, whose reading code is
//! what `adc_read` runs inside the measured call). Each trigger is converted with the record's counts:
//! while the magnet holds the pin, the record's hold (cycled if the hold lasts longer); from the
//! first conversion after the magnet lets go, the record's motion from its first sample after the
//! hold; past the record's end the last sample repeats (the pin at rest). The run store's flash is
//! the firmware's flash model ([`MemFlash`], with the STM32H743's erase and program times).
//!
//! The link models the board's USB pipe: [`PIPE`] bytes of room; a frame that does not fit is
//! refused (nothing queued), as the board's `send_frame` does; the test takes the bytes out (the
//! host reading) whenever it likes. Every hardware method is cheap (a copy at most), because its
//! instructions are counted as the application's, as the board's would be.

use crate::bundle::Record;
use tribo_firmware::acquisition::clock::BOARD_TIMER_HZ;
use tribo_firmware::acquisition::{Batch, ConverterModel};
use tribo_firmware::hal::{
    AnalogSample, Button, ClockCheck, ConverterRead, EcrFrontEnd, FlashGeometry, HeaterOutput,
    Lamps, Led, Link, Magnet, MagnetDrive, OutputSense, RunFlash, SampleSource, SensedOutputs,
    Thermocouple, ANALOG_CHANNELS,
};
use tribo_firmware::runstore::memflash::MemFlash;
use tribo_firmware::wire::SampleClock;

/// Bytes the link's pipe holds (the board's USB pipe is 4 KiB).
pub const PIPE: usize = 4096;

/// Reads an instruction clock (`None` on the host): a plain function, so that hardware methods can
/// time themselves while the probe is busy measuring the call around them.
pub type Clock = fn() -> Option<u64>;

fn no_clock() -> Option<u64> {
    None
}

/// Timing of the converter's ring reads, in application instructions.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReadTiming {
    /// Application instructions executed before the current call.
    pub base: u64,
    /// Clock at the start of the current call.
    pub call_start: Option<u64>,
    /// Application time of the last ring read of this acquisition.
    pub last: Option<u64>,
    /// Largest application time between two ring reads of one acquisition.
    pub worst_gap: u64,
    /// Ring reads.
    pub reads: u64,
}

/// What the replayed MAX31856 answers (the board hands the application its register file and the
/// reading's age).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Converter {
    /// A configured converter reading [`Replay::temp`] with the cold junction at 25 °C, fresh.
    Reads,
    /// This register file, fresh (a faulty converter, wire or bus).
    Answers(tribo_firmware::thermocouple::Registers),
    /// The last good reading, taken at this time (µs): the converter task stopped publishing.
    StaleSince(u64),
}

/// The replay hardware (see the module docs).
pub struct Replay<'r> {
    rec: Record<'r>,
    /// Virtual time, µs (set by [`Replay::advance`]).
    pub now_us: u64,
    /// The instruction clock for [`ReadTiming`].
    pub clock: Clock,
    pub timing: ReadTiming,
    // magnet
    drive: MagnetDrive,
    released_at_us: Option<u64>,
    /// Index of the first conversion after the magnet let go (the run's first motion sample).
    released_k: Option<u64>,
    adc: ConverterModel,
    flash: MemFlash<&'r mut [u8]>,
    /// A sector erase the application started, handed to the flash model by [`Replay::advance`]:
    /// the model clears the sector's 128 KiB at once, which the board's flash does by itself
    /// (starting an erase is a register write), so that work must not count as the application's.
    erase: Option<u32>,
    // heater, ECR, button, lamps
    /// Plate temperature the converter reads, °C (a configured MAX31856, cold junction at 25 °C).
    pub temp: f32,
    /// What the converter answers instead (fault injection, see [`Converter`]).
    pub converter: Converter,
    pub heater_duty: f32,
    /// Transimpedance output the ECR front end reads, V.
    pub ecr_output_v: f32,
    pub ecr_source_v: f32,
    pub ecr_range: u8,
    pub button: bool,
    pub lamps: Lamps,
    // link
    outbox: [u8; PIPE],
    outbox_len: usize,
    /// Frames the link refused (pipe full).
    pub refused: u32,
    /// Frames the link took.
    pub sent: u32,
}

impl<'r> Replay<'r> {
    /// Replay of `rec`, with `flash` (at least [`FlashGeometry::H743_BANK2`]'s size) as bank 2.
    pub fn new(rec: Record<'r>, flash: &'r mut [u8]) -> Self {
        Replay {
            rec,
            now_us: 0,
            clock: no_clock,
            timing: ReadTiming::default(),
            drive: MagnetDrive::Off,
            released_at_us: None,
            released_k: None,
            adc: ConverterModel::new(BOARD_TIMER_HZ),
            flash: MemFlash::new(flash, FlashGeometry::H743_BANK2).with_h743_timing(),
            erase: None,
            temp: 25.0,
            converter: Converter::Reads,
            heater_duty: 0.0,
            ecr_output_v: 1.0,
            ecr_source_v: 0.0,
            ecr_range: 0,
            button: false,
            lamps: Lamps::default(),
            outbox: [0; PIPE],
            outbox_len: 0,
            refused: 0,
            sent: 0,
        }
    }

    pub fn record(&self) -> &Record<'r> {
        &self.rec
    }

    /// When the magnet let the pin go, µs.
    pub fn released_at_us(&self) -> Option<u64> {
        self.released_at_us
    }

    pub fn magnet(&self) -> MagnetDrive {
        self.drive
    }

    /// Brings the converter and the flash to `now_us`: every trigger due by then is converted.
    pub fn advance(&mut self, now_us: u64) {
        self.now_us = self.now_us.max(now_us);
        self.flash.advance(self.now_us);
        if let Some(sector) = self.erase.take() {
            self.flash.flash_erase(sector);
        }
        while self.adc.due(self.now_us).is_some() {
            let k = self.adc.next_index();
            let s = self.rec.sample(self.index(k));
            let mut a = [0u16; ANALOG_CHANNELS];
            a.copy_from_slice(&s[..ANALOG_CHANNELS]);
            self.adc.convert(&a);
        }
    }

    /// The bytes the link took since the last call (the host reads them all; the pipe empties).
    pub fn take_output(&mut self, mut f: impl FnMut(&[u8])) {
        f(&self.outbox[..self.outbox_len]);
        self.outbox_len = 0;
    }

    /// Index in the record of conversion `k` of the stream (see the module docs).
    fn index(&self, k: u64) -> usize {
        match self.released_k {
            Some(r) if k >= r => {
                let i = self.rec.hold as u64 + (k - r);
                i.min(self.rec.len().max(1) as u64 - 1) as usize
            }
            _ => (k % self.rec.hold.max(1) as u64) as usize,
        }
    }

    fn note_read(&mut self) {
        let t = &mut self.timing;
        t.reads += 1;
        let (Some(start), Some(now)) = (t.call_start, (self.clock)()) else {
            return;
        };
        let at = t.base + now.saturating_sub(start);
        if let Some(last) = t.last {
            t.worst_gap = t.worst_gap.max(at.saturating_sub(last));
        }
        t.last = Some(at);
    }
}

impl Magnet for Replay<'_> {
    fn magnet_drive(&mut self, drive: MagnetDrive) {
        if self.released_at_us.is_none()
            && matches!(self.drive, MagnetDrive::Hold { .. })
            && !matches!(drive, MagnetDrive::Hold { .. })
        {
            self.released_at_us = Some(self.now_us);
            self.released_k = Some(self.adc.next_index());
        }
        self.drive = drive;
    }
}

impl Thermocouple for Replay<'_> {
    fn read_thermocouple(&mut self) -> Option<ConverterRead> {
        let good = || tribo_firmware::thermocouple::encode(self.temp, 25.0, 0);
        Some(match self.converter {
            Converter::Reads => ConverterRead {
                regs: good(),
                age_us: 0,
            },
            Converter::Answers(regs) => ConverterRead { regs, age_us: 0 },
            Converter::StaleSince(at_us) => ConverterRead {
                regs: good(),
                age_us: self.now_us.saturating_sub(at_us),
            },
        })
    }
}

impl HeaterOutput for Replay<'_> {
    fn set_heater_duty(&mut self, duty: f32) {
        self.heater_duty = duty;
    }
}

impl EcrFrontEnd for Replay<'_> {
    fn set_ecr_source(&mut self, volts: f32) {
        self.ecr_source_v = volts;
    }
    fn set_ecr_range(&mut self, range: u8) {
        self.ecr_range = range;
    }
    fn read_ecr_output(&mut self) -> f32 {
        self.ecr_output_v
    }
}

impl SampleSource for Replay<'_> {
    fn adc_clock(&self, rate_hz: u32) -> Option<SampleClock> {
        self.adc.clock_for(rate_hz)
    }

    fn adc_start(&mut self, rate_hz: u32) -> Option<SampleClock> {
        self.timing.last = None;
        self.adc.start(rate_hz, self.now_us)
    }

    fn adc_stop(&mut self) {
        self.timing.last = None;
        self.adc.stop();
    }

    fn adc_running(&self) -> bool {
        self.adc.is_running()
    }

    fn adc_next_index(&mut self) -> u64 {
        self.adc.next_index()
    }

    fn adc_read(&mut self, out: &mut [AnalogSample]) -> Batch {
        self.note_read();
        self.adc.read(out)
    }
    fn force_lowpass(&self) -> tribo_firmware::wire::LowPass {
        tribo_firmware::wire::LowPass::butterworth(2, 300.0)
    }
}

impl RunFlash for Replay<'_> {
    fn flash_geometry(&self) -> FlashGeometry {
        self.flash.flash_geometry()
    }
    fn flash_busy(&mut self) -> bool {
        self.erase.is_some() || self.flash.flash_busy()
    }
    fn flash_erase(&mut self, sector: u32) -> bool {
        if self.flash_busy() || sector >= self.flash.flash_geometry().sectors {
            return false;
        }
        self.erase = Some(sector);
        true
    }
    fn flash_program(&mut self, offset: u32, data: &[u8]) -> bool {
        self.erase.is_none() && self.flash.flash_program(offset, data)
    }
    fn flash_read(&mut self, offset: u32, out: &mut [u8]) -> bool {
        self.erase.is_none() && self.flash.flash_read(offset, out)
    }
    fn flash_take_error(&mut self) -> bool {
        self.flash.flash_take_error()
    }
}

impl Button for Replay<'_> {
    fn button_pressed(&mut self) -> bool {
        self.button
    }
}

impl Led for Replay<'_> {
    fn set_lamps(&mut self, lamps: Lamps) {
        self.lamps = lamps;
    }
}

impl OutputSense for Replay<'_> {
    /// The replayed hardware has no pins: nothing reads back.
    fn sense_outputs(&mut self) -> SensedOutputs {
        SensedOutputs::default()
    }
}

/// The emulated Cortex-M7 has no RCC, LSI or TIM16 (QEMU's mps2-an500): the defaults, which
/// say the clock check is not available here.
impl ClockCheck for Replay<'_> {}

impl Link for Replay<'_> {
    fn send_frame(&mut self, frame: &[u8]) -> bool {
        // One block copy, like the board's pipe write.
        let at = self.outbox_len;
        match self.outbox.get_mut(at..at + frame.len()) {
            Some(room) => {
                room.copy_from_slice(frame);
                self.outbox_len += frame.len();
                self.sent += 1;
                true
            }
            None => {
                self.refused += 1;
                false
            }
        }
    }
}
