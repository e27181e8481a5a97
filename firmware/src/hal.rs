//! The small hardware traits the rig logic talks to.
//!
//! Each trait is one concern of the rig and is implemented twice: by the board binary
//! (`firmware/board`, embassy-stm32 peripherals) and by the host's virtual rig (`host/rig`, the
//! physics simulator). The application ([`crate::app::App`]) needs all of them at once, so it takes
//! one value implementing [`Hardware`], the union of the traits (blanket-implemented).
//!
//! Every method is non-blocking: the application is a state machine polled with the time, and a
//! slow peripheral (SPI thermocouple, USB) is served by its own task that these methods only talk to.

pub use crate::acquisition::Batch;
pub use crate::wire::SampleClock;

/// Drive of the release electromagnet (an H-bridge on the board: PWM duty and polarity).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MagnetDrive {
    /// Coil off.
    Off,
    /// Holding polarity at this PWM duty (0..=1).
    Hold { duty: f32 },
    /// Reverse polarity at this duty: the short pulse that kills the remanent field at release.
    Reverse { duty: f32 },
}

/// The release electromagnet.
pub trait Magnet {
    fn magnet_drive(&mut self, drive: MagnetDrive);
}

/// One read of the thermocouple converter (a MAX31856): its whole register file and how long ago it
/// was read. The board only moves these bytes; [`crate::thermocouple::check`] decides whether to trust
/// them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConverterRead {
    pub regs: crate::thermocouple::Registers,
    /// Time since the converter task read these bytes, µs.
    pub age_us: u64,
}

/// The heater's thermocouple, cold-junction compensated by its converter.
pub trait Thermocouple {
    /// The converter's latest register file, or `None` if it never answered (SPI error).
    fn read_thermocouple(&mut self) -> Option<ConverterRead>;
}

/// The heater's power stage (PWM on a MOSFET).
pub trait HeaterOutput {
    /// Duty 0..=1 (the caller clamps).
    fn set_heater_duty(&mut self, duty: f32);
}

/// The electrical-contact-resistance front end: a DAC-driven voltage source across the contact and a
/// transimpedance amplifier with switchable gain reading the current.
pub trait EcrFrontEnd {
    /// Source voltage across the contact, V (the caller clamps to 2 mV / 5 mA).
    fn set_ecr_source(&mut self, volts: f32);
    /// Transimpedance range `0..crate::ecr::RANGES` (gain [`crate::ecr::GAIN_V_PER_A`]).
    fn set_ecr_range(&mut self, range: u8);
    /// Latest transimpedance output, V (0..=[`crate::ecr::FULL_SCALE_V`]).
    fn read_ecr_output(&mut self) -> f32;
}

/// Analog channels converted by the ADC, in this order: displacement, velocity, force, ECR.
/// (The temperature channel of a block comes from the thermocouple, not from the ADC.)
pub const ANALOG_CHANNELS: usize = 4;

/// One conversion of every analog channel, 16-bit counts.
pub type AnalogSample = [u16; ANALOG_CHANNELS];

/// Timer-triggered scans of the analog channels, written by DMA round a ring the application reads.
///
/// Every sample has an index in the converter's stream (0 = the first conversion after
/// [`SampleSource::adc_start`]) that comes from where the DMA wrote it, never from counting reads;
/// samples that could not be read (the reader fell a whole ring behind, or the ADC overran and was
/// restarted) show as a jump in index between two reads, so the caller knows exactly which are
/// missing.
pub trait SampleSource {
    /// The sample clock the converter would run at for `rate_hz`: the timer's nearest rate to it
    /// (`None`: no setting comes near).
    fn adc_clock(&self, rate_hz: u32) -> Option<SampleClock>;
    /// Starts a new stream at the rate of [`SampleSource::adc_clock`]; returns that clock, or
    /// `None` if the converter could not start.
    fn adc_start(&mut self, rate_hz: u32) -> Option<SampleClock>;
    fn adc_stop(&mut self);
    fn adc_running(&self) -> bool;
    /// Index of the first sample whose conversion has not begun: whatever the rig changes now (an
    /// ECR range, the magnet) acts on samples from this index on.
    fn adc_next_index(&mut self) -> u64;
    /// Copies the oldest samples not yet read into `out` (at most `out.len()`); the batch says the
    /// index of the first. A batch starting after the index that followed the previous one means the
    /// samples in between are lost (an empty batch still carries where reading goes on).
    fn adc_read(&mut self, out: &mut [AnalogSample]) -> Batch;
    /// The force channel's analog low-pass in front of the converter, as the board is built: what
    /// each run's [`crate::wire::DeviceMsg::Chain`] frame states, so that an analysis of the
    /// record need not fit it.
    fn force_lowpass(&self) -> crate::wire::LowPass;
}

/// The user button (raw level; the application debounces).
pub trait Button {
    fn button_pressed(&mut self) -> bool;
}

/// The three status lamps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Lamps {
    pub green: bool,
    pub amber: bool,
    pub red: bool,
}

pub trait Led {
    fn set_lamps(&mut self, lamps: Lamps);
}

/// The byte link to the host (USB CDC-ACM on the board, any byte stream on the host).
pub trait Link {
    /// Queues one whole frame. Returns false, having queued nothing, when the link cannot take it now
    /// (no host, or the host is not reading): the caller keeps what it must resend.
    fn send_frame(&mut self, frame: &[u8]) -> bool;
}

/// Shape of the flash that keeps runs across power loss: bank 2 of the STM32H743 is 8 sectors of
/// 128 KiB, programmed in 32-byte flash words (each written once after an erase: the ECC covers the
/// whole word).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FlashGeometry {
    pub sector_bytes: u32,
    pub sectors: u32,
}

impl FlashGeometry {
    /// Bank 2 of the STM32H743 (0x0810_0000, 1 MiB).
    pub const H743_BANK2: FlashGeometry = FlashGeometry {
        sector_bytes: 128 * 1024,
        sectors: 8,
    };

    pub const fn bytes(&self) -> u32 {
        self.sector_bytes * self.sectors
    }
}

/// Programming unit of [`RunFlash`]: a 256-bit flash word.
pub const FLASH_WORD: usize = 32;
/// Most bytes one [`RunFlash::flash_program`] takes (whole words).
pub const FLASH_MAX_PROGRAM: usize = 256;

/// The flash the run store writes (bank 2 on the board; a model of it on the host).
///
/// Erase and program only *start* an operation, which runs while the application goes on; meanwhile
/// [`RunFlash::flash_busy`] is true and every call but `flash_busy` is refused (on the STM32H7 a read
/// of the bank being written would stall the CPU for the whole erase). Offsets are from the start of
/// the flash.
pub trait RunFlash {
    fn flash_geometry(&self) -> FlashGeometry;
    /// An erase or program is under way.
    fn flash_busy(&mut self) -> bool;
    /// Starts erasing sector `sector` (every byte to 0xFF). False, nothing started, when busy or
    /// out of range.
    fn flash_erase(&mut self, sector: u32) -> bool;
    /// Starts programming `data` at `offset`: both multiples of [`FLASH_WORD`], at most
    /// [`FLASH_MAX_PROGRAM`] bytes, inside one sector, every word erased since it was last
    /// programmed. False, nothing started, when busy or refused.
    fn flash_program(&mut self, offset: u32, data: &[u8]) -> bool;
    /// Reads `out.len()` bytes at `offset`. False when busy or out of range.
    fn flash_read(&mut self, offset: u32, out: &mut [u8]) -> bool;
    /// Whether the last finished erase or program failed (reading it clears it).
    fn flash_take_error(&mut self) -> bool;
    /// The flash controller's status and error flags raised since the last call (reading them
    /// clears them), for the self-test; `None` where there is no such controller (a model).
    fn flash_take_flags(&mut self) -> Option<u32> {
        None
    }
}

/// What the board reads back of its outputs (the self-test's output rows), each `None` where the
/// board cannot sense it. Pin levels are the pins' input data (IDR on the STM32H7: the pad's level,
/// not the output register), so a pin held by something else than its driver reads what it is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SensedOutputs {
    /// The heater MOSFET gate pin (PD12).
    pub heater_pin: Option<bool>,
    /// The H-bridge inputs: bit 0 the hold leg (PE9), bit 1 the reverse leg (PE11).
    pub magnet_pins: Option<u8>,
    /// The ECR source DAC's output data register (the 12-bit code it converts).
    pub ecr_dac_code: Option<u16>,
    /// The ECR range-select pins, PG0..PG2 as bits 0..2.
    pub ecr_range_pins: Option<u8>,
    /// The lamp pins: bit 0 green (PB0), 1 amber (PE1), 2 red (PB14).
    pub lamp_pins: Option<u8>,
}

/// Reading the outputs back.
pub trait OutputSense {
    /// The outputs as they read back now (see [`SensedOutputs`]).
    fn sense_outputs(&mut self) -> SensedOutputs;
}

/// The timer that measures the LSI against the HSE, as the board configured it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LsiTimer {
    /// The timer's tick rate as configured from the HSE's nominal frequency, Hz: what it would
    /// tick at if the HSE were what the firmware assumes.
    pub timer_hz: u32,
    /// LSI periods between two captures (the input-capture prescaler).
    pub periods_per_capture: u8,
}

/// One measurement of [`ClockCheck::lsi_interval`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LsiInterval {
    /// Timer ticks between two consecutive captures, no capture lost in between.
    Ticks(u32),
    /// A capture overwrote one not yet read (the overcapture flag): the interval would span an
    /// unknown number of captures, so it is not a measurement.
    Overcapture,
    /// No capture came within the wait (a few capture periods): the LSI does not reach the timer.
    Timeout,
}

/// An independent clock against the crystal: the LSI (an RC oscillator inside the chip, not
/// derived from the HSE) measured by a timer clocked from the HSE. The board implements it; hardware
/// without such a path (an emulator, replayed hardware) keeps the defaults, which say so.
pub trait ClockCheck {
    /// Switches the LSI on (if it is not already) and starts the capture; `None`: this hardware
    /// has no timer input on the LSI.
    fn lsi_start(&mut self) -> Option<LsiTimer> {
        None
    }
    /// The LSI is ready (its RDY flag).
    fn lsi_ready(&mut self) -> bool {
        false
    }
    /// One interval between two consecutive captures (the board may wait for them: at most a
    /// few capture periods, bounded).
    fn lsi_interval(&mut self) -> LsiInterval {
        LsiInterval::Timeout
    }
    /// Stops the capture and leaves the LSI as [`ClockCheck::lsi_start`] found it.
    fn lsi_stop(&mut self) {}
}

/// A monotonic clock, microseconds.
pub trait Clock {
    fn now_us(&self) -> u64;
}

/// Everything the application drives.
pub trait Hardware:
    Magnet
    + Thermocouple
    + HeaterOutput
    + EcrFrontEnd
    + SampleSource
    + Button
    + Led
    + Link
    + RunFlash
    + OutputSense
    + ClockCheck
{
}

impl<
        T: Magnet
            + Thermocouple
            + HeaterOutput
            + EcrFrontEnd
            + SampleSource
            + Button
            + Led
            + Link
            + RunFlash
            + OutputSense
            + ClockCheck,
    > Hardware for T
{
}
