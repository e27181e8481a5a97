//! The message set: what the host may ask ([`HostMsg`]) and what the rig says ([`DeviceMsg`]).
//!
//! All quantities are SI unless the name says otherwise (`_c` for °C, `_us` for microseconds).
//! Range checks live here too ([`Configure::validate`], [`HeaterSetpoint::validate`]), so the host
//! refuses an out-of-range setpoint before sending it and the firmware refuses it again on arrival, by
//! the same code.

use serde::{Deserialize, Serialize};

/// Samples per channel in one [`SampleBlock`].
pub const BLOCK_LEN: usize = 64;
/// Number of acquisition channels ([`Channel`]).
pub const CHANNELS: usize = 5;
/// Largest number of counts a [`SampleBlock`] carries (every channel on).
pub const MAX_BLOCK_COUNTS: usize = BLOCK_LEN * CHANNELS;

macro_rules! wire_type {
    ($(#[$m:meta])* $vis:vis $kind:ident $name:ident $($body:tt)*) => {
        $(#[$m])*
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        $vis $kind $name $($body)*
    };
}

mod faults;
mod result;
mod samples;
mod selftest;
pub use faults::*;
pub use result::*;
pub use samples::*;
pub use selftest::*;

// ---------------------------------------------------------------------------------------------------
// Host → rig
// ---------------------------------------------------------------------------------------------------

wire_type! {
    /// A command from the host. Every command is answered by [`DeviceMsg::Ack`] or [`DeviceMsg::Error`]
    /// carrying the command frame's sequence number (and, for `Hello` and `Status`, by the reply itself).
    pub enum HostMsg {
        /// Variant 0, frozen forever: opens a session. Answered by [`DeviceMsg::Hello`].
        Hello { protocol: u16 },
        /// Rig constants, sample rate, channels, calibration of the next run.
        Configure(Configure),
        /// Heater on, regulated to this setpoint.
        SetHeater(HeaterSetpoint),
        /// Heater off (always accepted).
        HeaterOff,
        /// Hold the pin with the electromagnet and allow a release.
        Arm,
        /// Leave the armed state without releasing (the magnet keeps holding).
        Disarm,
        /// Release the pin now (only when armed, sampling and the heater healthy).
        Release,
        /// Stop the run in progress; the run is kept and can still be pulled.
        Abort,
        /// Ask for a [`DeviceMsg::Status`].
        Status,
        /// Send the stored run again, from sample block `from_block` on, then its result and end.
        Pull { run_id: u32, from_block: u32 },
        // ---- protocol v2 ----
        /// Renews the host lease (so does every command that acts on the rig; the queries `Hello`,
        /// `Status`, `Pull` and `PullBlocks` do not: a program that only looks does not keep the rig
        /// heating): while heating or holding the magnet the rig needs one at least every
        /// [`limits::HOST_LEASE_MS`], or it drives its outputs safe.
        Heartbeat,
        /// Drive everything that heats or holds to its safe value now: heater off, magnet off, armed
        /// state left. A run in progress goes on recording. Always accepted.
        Safe,
        /// Send blocks `first .. first + count` of a stored run again, and nothing else (the host
        /// asks for exactly the blocks it is missing).
        PullBlocks { run_id: u32, first: u32, count: u32 },
        /// One check of the bring-up self-test (`tribo selftest`; see [`SelfTestCheck`]). A
        /// firmware older than the self-test answers `Error { Malformed }`.
        SelfTest(SelfTestCheck),
        /// The highest run number of this rig the host holds (its run folders): the rig's next
        /// run is numbered above it. A rig whose power went after a release, before the run's
        /// header reached its flash, knows nothing of that run; its host does. Answered by an
        /// `Ack`; a firmware older than it answers `Error { Malformed }`.
        RunFloor { run_id: u32 },
    }
}

wire_type! {
    /// The rig's constants as the operator set them.
    #[derive(Copy)]
    pub struct RigConstants {
        pub mass_kg: f32,
        pub stiffness_n_per_m: f32,
        pub load_n: f32,
    }
}

wire_type! {
    /// One acquisition channel. The discriminant is the channel's index everywhere (bit in
    /// [`ChannelSet`], slot in [`Configure::calibration`], order of counts in a [`SampleBlock`]).
    #[derive(Copy, Eq, PartialOrd, Ord, Hash)]
    pub enum Channel {
        /// Vibrometer displacement, m.
        Displacement = 0,
        /// Vibrometer velocity, m/s.
        Velocity = 1,
        /// Tangential force from the charge amplifier, N.
        Force = 2,
        /// ECR transimpedance output, V (the range is in the block).
        Ecr = 3,
        /// Thermocouple amplifier, °C.
        Temperature = 4,
    }
}

impl Channel {
    pub const ALL: [Channel; CHANNELS] = [
        Channel::Displacement,
        Channel::Velocity,
        Channel::Force,
        Channel::Ecr,
        Channel::Temperature,
    ];

    pub const fn index(self) -> usize {
        self as usize
    }

    pub const fn name(self) -> &'static str {
        match self {
            Channel::Displacement => "displacement",
            Channel::Velocity => "velocity",
            Channel::Force => "force",
            Channel::Ecr => "ecr",
            Channel::Temperature => "temperature",
        }
    }

    pub const fn unit(self) -> &'static str {
        match self {
            Channel::Displacement => "m",
            Channel::Velocity => "m/s",
            Channel::Force => "N",
            Channel::Ecr => "V",
            Channel::Temperature => "°C",
        }
    }
}

wire_type! {
    /// A set of channels, one bit per [`Channel`] index.
    #[derive(Copy, Eq, Hash, Default)]
    pub struct ChannelSet(pub u8);
}

impl ChannelSet {
    pub const EMPTY: ChannelSet = ChannelSet(0);
    pub const ALL: ChannelSet = ChannelSet((1 << CHANNELS) - 1);
    /// Displacement and velocity: what a run cannot do without.
    pub const VIBROMETER: ChannelSet = ChannelSet(0b11);

    pub const fn with(self, c: Channel) -> Self {
        ChannelSet(self.0 | 1 << c as u8)
    }

    pub const fn contains(self, c: Channel) -> bool {
        self.0 & (1 << c as u8) != 0
    }

    pub const fn len(self) -> usize {
        (self.0 & Self::ALL.0).count_ones() as usize
    }

    pub const fn is_empty(self) -> bool {
        self.len() == 0
    }

    /// The channels in index order, which is the order of their counts in a sample.
    pub fn iter(self) -> impl Iterator<Item = Channel> {
        Channel::ALL.into_iter().filter(move |c| self.contains(*c))
    }

    /// Position of `c`'s count within one sample of this set: the number of channels of lower
    /// index in the set.
    pub const fn position(self, c: Channel) -> Option<usize> {
        if !self.contains(c) {
            return None;
        }
        Some((self.0 & ((1u8 << c as u8) - 1)).count_ones() as usize)
    }
}

impl FromIterator<Channel> for ChannelSet {
    fn from_iter<I: IntoIterator<Item = Channel>>(iter: I) -> Self {
        iter.into_iter().fold(ChannelSet::EMPTY, ChannelSet::with)
    }
}

wire_type! {
    /// Linear calibration of a 16-bit channel: SI value = `gain * (count - zero)`.
    #[derive(Copy)]
    pub struct ChannelCal {
        /// SI units per count.
        pub gain: f32,
        /// Count that reads zero (32768 for a bipolar input at mid-scale).
        pub zero: f32,
    }
}

impl ChannelCal {
    /// Calibration of a bipolar input spanning ±`full_scale` over the 16-bit range.
    pub fn bipolar(full_scale: f32) -> Self {
        ChannelCal {
            gain: 2.0 * full_scale / 65536.0,
            zero: 32768.0,
        }
    }

    /// Calibration of a unipolar input spanning 0..`full_scale`.
    pub fn unipolar(full_scale: f32) -> Self {
        ChannelCal {
            gain: full_scale / 65536.0,
            zero: 0.0,
        }
    }

    pub fn to_si(&self, count: u16) -> f32 {
        self.gain * (count as f32 - self.zero)
    }

    /// The count an ideal ADC would give for `value`, saturating at the ends of the range
    /// (NaN reads as the zero count).
    pub fn to_count(&self, value: f32) -> u16 {
        let c = value / self.gain + self.zero;
        if c.is_nan() {
            return self.zero.clamp(0.0, 65535.0) as u16;
        }
        // Round half away from zero without `f32::round` (not in core).
        let r = if c >= 0.0 { c + 0.5 } else { c - 0.5 };
        r.clamp(0.0, 65535.0) as u16
    }

    fn is_valid(&self) -> bool {
        self.gain.is_finite()
            && self.gain != 0.0
            && self.zero.is_finite()
            && (0.0..=65535.0).contains(&self.zero)
    }
}

wire_type! {
    /// Everything the rig needs to know before a run.
    #[derive(Copy)]
    pub struct Configure {
        pub rig: RigConstants,
        pub sample_rate_hz: u32,
        pub channels: ChannelSet,
        /// Initial displacement at which the electromagnet holds the pin.
        pub initial_amplitude_m: f32,
        /// The run ends by itself after this long even if the pin still moves.
        pub max_duration_s: f32,
        /// One calibration per [`Channel`], by index.
        pub calibration: [ChannelCal; CHANNELS],
    }
}

/// Limits every configuration must respect (the rig's physical ranges).
pub mod limits;

fn in_range<T: PartialOrd>(v: T, r: core::ops::RangeInclusive<T>, f: Field) -> Result<(), Field> {
    // NaN is in no range.
    if r.contains(&v) {
        Ok(())
    } else {
        Err(f)
    }
}

impl Configure {
    /// The thesis's rig: k ≈ 1150 N/m, m ≈ 0.04 kg, x0 = 667 µm, 10 kS/s, every channel, with the
    /// front-end ranges of the default board (±2 mm, ±0.25 m/s, ±1 N, 0–3.3 V, 0–200 °C).
    pub fn real_rig(load_n: f32) -> Self {
        Configure {
            rig: RigConstants {
                mass_kg: 0.04,
                stiffness_n_per_m: 1150.0,
                load_n,
            },
            sample_rate_hz: 10_000,
            channels: ChannelSet::ALL,
            initial_amplitude_m: 667e-6,
            max_duration_s: 40.0,
            calibration: [
                ChannelCal::bipolar(2e-3),
                ChannelCal::bipolar(0.25),
                ChannelCal::bipolar(1.0),
                ChannelCal::unipolar(3.3),
                ChannelCal::unipolar(200.0),
            ],
        }
    }

    /// Checks every field against [`limits`]; names the first one out of range.
    pub fn validate(&self) -> Result<(), Field> {
        in_range(self.rig.mass_kg, limits::MASS_KG, Field::Mass)?;
        in_range(
            self.rig.stiffness_n_per_m,
            limits::STIFFNESS_N_PER_M,
            Field::Stiffness,
        )?;
        in_range(self.rig.load_n, limits::LOAD_N, Field::Load)?;
        in_range(
            self.sample_rate_hz,
            limits::SAMPLE_RATE_HZ,
            Field::SampleRate,
        )?;
        let ch = self.channels;
        if ch.0 & !ChannelSet::ALL.0 != 0
            || !ch.contains(Channel::Displacement)
            || !ch.contains(Channel::Velocity)
        {
            return Err(Field::Channels);
        }
        in_range(
            self.initial_amplitude_m,
            limits::INITIAL_AMPLITUDE_M,
            Field::InitialAmplitude,
        )?;
        in_range(
            self.max_duration_s,
            limits::MAX_DURATION_S,
            Field::MaxDuration,
        )?;
        if !self.calibration.iter().all(ChannelCal::is_valid) {
            return Err(Field::Calibration);
        }
        Ok(())
    }

    /// Natural angular frequency Ω = sqrt(k/m), rad/s (not validated).
    pub fn omega(&self) -> f32 {
        sqrt_f32(self.rig.stiffness_n_per_m / self.rig.mass_kg)
    }

    /// Samples in a run of `max_duration_s`.
    pub fn max_samples(&self) -> u32 {
        let n = self.max_duration_s * self.sample_rate_hz as f32;
        if n.is_finite() && n > 0.0 {
            n as u32
        } else {
            0
        }
    }
}

/// Square root for `no_std` (Newton iterations from the bit-level estimate; exact to f32 rounding
/// for normal positive inputs). Negative and NaN inputs give NaN.
pub fn sqrt_f32(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 || x.is_infinite() {
        return x;
    }
    let mut y = f32::from_bits((x.to_bits() >> 1) + 0x1FBD_1DF5);
    for _ in 0..4 {
        y = 0.5 * (y + x / y);
    }
    y
}

wire_type! {
    /// Heater regulation target.
    #[derive(Copy)]
    pub struct HeaterSetpoint {
        pub setpoint_c: f32,
        /// Largest rate of change of the internal setpoint ramp.
        pub ramp_c_per_min: f32,
    }
}

impl HeaterSetpoint {
    pub fn validate(&self) -> Result<(), Field> {
        in_range(
            self.setpoint_c,
            limits::HEATER_SETPOINT_C,
            Field::HeaterSetpoint,
        )?;
        in_range(
            self.ramp_c_per_min,
            limits::HEATER_RAMP_C_PER_MIN,
            Field::HeaterRamp,
        )
    }
}

// ---------------------------------------------------------------------------------------------------
// Rig → host
// ---------------------------------------------------------------------------------------------------

wire_type! {
    /// Everything the rig sends.
    // `Samples` is by far the largest variant, and the most frequent one: boxing it would need a heap
    // the firmware does not have.
    #[allow(clippy::large_enum_variant)]
    pub enum DeviceMsg {
        /// Variant 0, frozen forever: who the rig is and which protocol it speaks.
        Hello(DeviceInfo),
        /// The command with this frame sequence number was accepted.
        Ack { seq: u32 },
        /// A command was refused, or something went wrong by itself (then `about_seq` is `None`).
        Error(DeviceError),
        Status(Status),
        /// A run begins (the pin was released); its blocks follow.
        RunStarted(RunHeader),
        Samples(SampleBlock),
        /// The on-board analysis at the end of a run.
        Result(OnboardResult),
        /// The run is over: no block of it follows (unless pulled again).
        RunEnded(RunEnd),
        // ---- protocol v2 ----
        /// The rig drove outputs to their safe state by itself, and why (unsolicited).
        Fault(FaultReport),
        /// Why the rig last reset (power-on, watchdog, panic with its message, ...): sent once after
        /// boot, in answer to the first `Hello`.
        Boot(BootReport),
        /// Run frame: samples of the run that were lost (acquisition overrun), exactly which ones.
        Gap(Gap),
        /// Run frame: a compressed sample block (the v2 form of [`DeviceMsg::Samples`]).
        Packed(PackedBlock),
        /// Run frame: the ECR transimpedance range changed; samples from `first_sample` on were
        /// converted on `range`, the first `settling` of them while the amplifier settled.
        EcrRange(EcrRangeChange),
        /// What a self-test check measured (see [`SelfTestReport`]).
        SelfTest(SelfTestReport),
        // ---- protocol v3 ----
        /// Run frame, right after the header: the analog chain in front of the converter (the
        /// force channel's low-pass), as the board is built, so that a record states it.
        Chain(AnalogChain),
    }
}

impl DeviceMsg {
    /// A frame of a run (header, sample block, result, end): what the rig stores and a
    /// [`HostMsg::Pull`] sends again, byte for byte.
    pub fn is_run_frame(&self) -> bool {
        matches!(
            self,
            DeviceMsg::RunStarted(_)
                | DeviceMsg::Samples(_)
                | DeviceMsg::Result(_)
                | DeviceMsg::RunEnded(_)
                | DeviceMsg::Gap(_)
                | DeviceMsg::Packed(_)
                | DeviceMsg::EcrRange(_)
                | DeviceMsg::Chain(_)
        )
    }
}

wire_type! {
    /// An analog low-pass filter: `poles` = 0 for none; otherwise a Butterworth filter of that
    /// order with its −3 dB point at `cutoff_hz`.
    #[derive(Copy)]
    pub struct LowPass {
        pub poles: u8,
        pub cutoff_hz: f32,
    }
}

impl LowPass {
    /// No filter.
    pub const NONE: LowPass = LowPass {
        poles: 0,
        cutoff_hz: 0.0,
    };

    /// A Butterworth low-pass of `poles` poles at `cutoff_hz`.
    pub const fn butterworth(poles: u8, cutoff_hz: f32) -> Self {
        LowPass { poles, cutoff_hz }
    }
}

wire_type! {
    /// What run `run_id`'s channels went through before the converter, as the board is built
    /// (the firmware knows its front-end; a record from another DAQ may not state it).
    #[derive(Copy)]
    pub struct AnalogChain {
        pub run_id: u32,
        /// The force channel's low-pass (the charge amplifier's output filter).
        pub force_lowpass: LowPass,
    }
}

wire_type! {
    /// The rig's identity. `protocol` must stay the first field (see the crate's compatibility rule).
    #[derive(Copy)]
    pub struct DeviceInfo {
        pub protocol: u16,
        pub firmware: [u16; 3],
        /// The MCU's unique id folded to 64 bits.
        pub serial: u64,
        pub max_sample_rate_hz: u32,
    }
}

wire_type! {
    /// A refusal or a fault.
    #[derive(Copy)]
    pub struct DeviceError {
        pub code: ErrorCode,
        /// Sequence number of the command refused, if the error answers one.
        pub about_seq: Option<u32>,
    }
}

wire_type! {
    /// What went wrong.
    #[derive(Copy, Eq)]
    pub enum ErrorCode {
        /// A frame failed COBS, CRC or decoding; it was dropped.
        Malformed,
        /// The hello carried another protocol version.
        ProtocolMismatch { device: u16 },
        /// A field of a command is out of range.
        OutOfRange(Field),
        /// Arm/Release before any Configure.
        NotConfigured,
        /// Configure/Arm while a run is in progress.
        Busy,
        /// A release was refused by an interlock.
        Interlock(Interlock),
        /// The heater was cut off.
        Heater(HeaterFault),
        /// Pull of a run the rig does not hold.
        NoRun,
        /// Samples were lost because the consumer fell behind (reported, never silent).
        Overrun { lost_samples: u32 },
        /// The electromagnet held longer than its duty limit and was switched off.
        HoldTimeExceeded,
        // ---- protocol v2 ----
        /// Arm refused: the electromagnet is cooling down after its hold budget ran out.
        MagnetCooling { wait_ms: u32 },
    }
}

wire_type! {
    /// A configuration field, named in [`ErrorCode::OutOfRange`].
    #[derive(Copy, Eq)]
    pub enum Field {
        Mass,
        Stiffness,
        Load,
        SampleRate,
        Channels,
        InitialAmplitude,
        MaxDuration,
        Calibration,
        HeaterSetpoint,
        HeaterRamp,
        RunId,
    }
}

wire_type! {
    /// Why a release was refused.
    #[derive(Copy, Eq)]
    pub enum Interlock {
        NotArmed,
        NotSampling,
        HeaterUnhealthy,
        MagnetOff,
        // ---- protocol v3 ----
        /// A deliberate fault of the self-test (a panic, a stalled task) is refused while the
        /// heater heats: a reset is tried with every output already off, never to turn one off.
        HeaterOn,
    }
}

wire_type! {
    /// Heater faults; each one cuts the heater off until cleared by a new setpoint.
    #[derive(Copy, Eq)]
    pub enum HeaterFault {
        /// Above the hard cut-off (110 °C).
        OverTemperature,
        OpenThermocouple,
        ShortedThermocouple,
        /// The thermocouple converter stopped answering (no reading, or readings too old).
        NoReading,
        // ---- protocol v2 ----
        /// The converter answered garbage: all-zero or all-ones words (stuck MISO, converter absent or
        /// reset), or a configuration that does not read back.
        BadConverterData,
        /// The converter flagged the thermocouple out of its type's range, or the reading is
        /// implausibly low.
        ThermocoupleRange,
        /// The cold-junction (board) temperature is out of the converter's range or implausible.
        ColdJunction,
        /// Heating, the plate did not gain the watch's stated amount in the stated time: the heater
        /// does not heat, or the thermocouple is not on the plate.
        HeatingFailed,
        /// The plate warmed while no heat was wanted: the heater's switch is stuck on.
        Runaway,
    }
}

wire_type! {
    /// The rig's state machine.
    #[derive(Copy, Eq)]
    pub enum RigState {
        Idle,
        Configured,
        Armed,
        Running,
        Finished,
        Fault,
    }
}

wire_type! {
    /// Snapshot of the rig.
    #[derive(Copy)]
    pub struct Status {
        pub state: RigState,
        /// Id of the current or last run (0 before the first).
        pub run_id: u32,
        pub temp_c: f32,
        pub heater_setpoint_c: Option<f32>,
        pub heater_duty: f32,
        pub heater_fault: Option<HeaterFault>,
        pub magnet_on: bool,
        pub log10_ecr_ohm: f32,
        pub ecr_range: u8,
        pub samples: u32,
        pub overruns: u32,
        pub uptime_ms: u64,
        // ---- protocol v2 ----
        /// The latest fault the rig handled by itself since boot, if any.
        pub last_fault: Option<FaultReport>,
        /// Faults since boot.
        pub faults: u32,
        /// Why the rig last reset (the message, if any, comes in [`DeviceMsg::Boot`]).
        pub reset_cause: ResetCause,
        /// Whether the lease of a host holds the rig, the rig runs stand-alone (button only), or
        /// neither.
        pub control: Control,
    }
}

wire_type! {
    /// Who may keep the rig heating and the magnet holding.
    #[derive(Copy, Eq)]
    pub enum Control {
        /// Nobody: the outputs are off (or go off).
        None,
        /// A host, while its lease ([`limits::HOST_LEASE_MS`]) is renewed.
        Host,
        /// The technician at the rig (stand-alone mode, its own limits).
        StandAlone,
    }
}

wire_type! {
    /// Opens a run: its id and the configuration it was taken with.
    #[derive(Copy)]
    pub struct RunHeader {
        pub run_id: u32,
        pub config: Configure,
        pub temp_c: f32,
        /// Device time of the release.
        pub t_us: u64,
        /// The sample clock the run was converted with (the rate the timer really produced, which
        /// may differ from `config.sample_rate_hz` when the timer cannot make that one exactly):
        /// sample `i` of the run was converted at `clock.time_s(i)` after the run's first sample.
        pub clock: SampleClock,
    }
}
