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
        /// Renews the host lease (every command does too): while heating or holding the magnet the
        /// rig needs one at least every [`limits::HOST_LEASE_MS`], or it drives its outputs safe.
        Heartbeat,
        /// Drive everything that heats or holds to its safe value now: heater off, magnet off, armed
        /// state left. A run in progress goes on recording. Always accepted.
        Safe,
        /// Send blocks `first .. first + count` of a stored run again, and nothing else (the host
        /// asks for exactly the blocks it is missing).
        PullBlocks { run_id: u32, first: u32, count: u32 },
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
pub mod limits {
    use core::ops::RangeInclusive;
    pub const MASS_KG: RangeInclusive<f32> = 1e-3..=10.0;
    pub const STIFFNESS_N_PER_M: RangeInclusive<f32> = 1.0..=1e5;
    /// Micrometric knob range.
    pub const LOAD_N: RangeInclusive<f32> = 0.0..=0.7;
    pub const SAMPLE_RATE_HZ: RangeInclusive<u32> = 1_000..=20_000;
    /// The electromagnet holds the head up to 1 mm out of equilibrium.
    pub const INITIAL_AMPLITUDE_M: RangeInclusive<f32> = 1e-6..=1e-3;
    pub const MAX_DURATION_S: RangeInclusive<f32> = 0.1..=60.0;
    /// Heater setpoint: ambient to 100 °C.
    pub const HEATER_SETPOINT_C: RangeInclusive<f32> = 15.0..=100.0;
    pub const HEATER_RAMP_C_PER_MIN: RangeInclusive<f32> = 0.1..=30.0;
    /// Hard heater cut-off, whatever the setpoint.
    pub const HEATER_CUTOFF_C: f32 = 110.0;
    /// Longest time without a command or [`super::HostMsg::Heartbeat`] from the host while heating or
    /// holding the magnet; then the outputs go safe ([`super::FaultReason::LeaseExpired`]).
    pub const HOST_LEASE_MS: u32 = 3_000;
}

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
        )
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
        /// The thermocouple converter stopped answering.
        NoReading,
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

wire_type! {
    /// A hardware sample clock: a timer clocked at `timer_hz` triggers one conversion every
    /// `ticks_per_sample` ticks, so the rate `timer_hz / ticks_per_sample` is an exact rational and the
    /// time of sample `i` is `i * ticks_per_sample / timer_hz` seconds, with no rounding that grows
    /// with `i`.
    #[derive(Copy, Eq, Hash)]
    pub struct SampleClock {
        pub timer_hz: u32,
        pub ticks_per_sample: u32,
    }
}

impl SampleClock {
    /// The clock of a rate that is exactly `rate_hz` (what a record without a clock assumed).
    pub const fn exact(rate_hz: u32) -> Self {
        SampleClock {
            timer_hz: rate_hz,
            ticks_per_sample: 1,
        }
    }

    /// A usable clock: both numbers non-zero.
    pub const fn is_valid(&self) -> bool {
        self.timer_hz > 0 && self.ticks_per_sample > 0
    }

    /// Samples per second (NaN for an invalid clock).
    pub fn rate_hz(&self) -> f64 {
        if !self.is_valid() {
            return f64::NAN;
        }
        self.timer_hz as f64 / self.ticks_per_sample as f64
    }

    /// Time of sample `index`, seconds after sample 0.
    pub fn time_s(&self, index: u64) -> f64 {
        if !self.is_valid() {
            return f64::NAN;
        }
        // Integer part and remainder apart, so that the result is exact to f64 rounding for any index.
        let ticks = index as u128 * self.ticks_per_sample as u128;
        let whole = ticks / self.timer_hz as u128;
        let rest = ticks % self.timer_hz as u128;
        whole as f64 + rest as f64 / self.timer_hz as f64
    }

    /// Time of sample `index`, whole microseconds after sample 0 (rounded down).
    pub fn time_us(&self, index: u64) -> u64 {
        if !self.is_valid() {
            return 0;
        }
        let us = index as u128 * self.ticks_per_sample as u128 * 1_000_000 / self.timer_hz as u128;
        us.min(u64::MAX as u128) as u64
    }

    /// Whole sample periods completed in `us` microseconds: how many samples a clock started `us`
    /// ago has converted (the first one a period after the start).
    pub fn samples_in_us(&self, us: u64) -> u64 {
        if !self.is_valid() {
            return 0;
        }
        let n = us as u128 * self.timer_hz as u128 / (self.ticks_per_sample as u128 * 1_000_000);
        n.min(u64::MAX as u128) as u64
    }

    /// Whether this clock produces exactly `rate_hz` samples per second.
    pub fn is_exactly(&self, rate_hz: u32) -> bool {
        self.is_valid() && self.timer_hz as u64 == rate_hz as u64 * self.ticks_per_sample as u64
    }
}

wire_type! {
    /// [`BLOCK_LEN`] (or fewer, for the last block) consecutive samples of the run's channels,
    /// interleaved: sample `i`, channel position `c` is `counts[i * channels.len() + c]`.
    pub struct SampleBlock {
        pub run_id: u32,
        /// Index of this block in the run, from 0.
        pub block: u32,
        /// Index in the run of the block's first sample (time = index / sample rate).
        pub first_sample: u32,
        /// Device time of the block's first sample.
        pub t_us: u64,
        pub channels: ChannelSet,
        /// ECR transimpedance range during the block and the resistance it measured.
        pub ecr_range: u8,
        pub log10_ecr_ohm: f32,
        pub temp_c: f32,
        pub counts: Counts,
    }
}

impl SampleBlock {
    /// Number of whole samples in the block.
    pub fn samples(&self) -> usize {
        match self.channels.len() {
            0 => 0,
            n => self.counts.len() / n,
        }
    }

    /// Counts of sample `i`, one per channel of the set, if the block has that sample.
    pub fn sample(&self, i: usize) -> Option<&[u16]> {
        let n = self.channels.len();
        self.counts.get(i * n..(i + 1) * n).filter(|_| n > 0)
    }

    /// All counts of one channel, in time order.
    pub fn channel(&self, c: Channel) -> impl Iterator<Item = u16> + '_ {
        let n = self.channels.len();
        let pos = self.channels.position(c);
        self.counts
            .iter()
            .skip(pos.unwrap_or(0))
            .step_by(n.max(1))
            .take(if pos.is_some() { self.samples() } else { 0 })
            .copied()
    }

    /// A well-formed block: counts a whole number of samples of a valid, non-empty set, at most
    /// [`BLOCK_LEN`] of them.
    pub fn is_consistent(&self) -> bool {
        let n = self.channels.len();
        self.channels.0 & !ChannelSet::ALL.0 == 0
            && n > 0
            && self.counts.len().is_multiple_of(n)
            && self.counts.len() / n <= BLOCK_LEN
    }
}

/// The counts of a [`SampleBlock`], sent as raw little-endian bytes (two per count, not varints:
/// counts sit around mid-scale, where a varint would take three bytes).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counts(pub heapless::Vec<u16, MAX_BLOCK_COUNTS>);

impl core::ops::Deref for Counts {
    type Target = [u16];
    fn deref(&self) -> &[u16] {
        &self.0
    }
}

impl Counts {
    /// Appends a count; `Err` when the block is full.
    pub fn push(&mut self, c: u16) -> Result<(), u16> {
        self.0.push(c)
    }

    pub fn clear(&mut self) {
        self.0.clear()
    }

    pub fn from_slice(s: &[u16]) -> Option<Self> {
        heapless::Vec::from_slice(s).ok().map(Counts)
    }
}

impl Serialize for Counts {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        CountsBytes(&self.0).serialize(s)
    }
}

/// Counts serialised as [`Counts`] is: little-endian bytes.
struct CountsBytes<'a>(&'a [u16]);

impl Serialize for CountsBytes<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if self.0.len() > MAX_BLOCK_COUNTS {
            return Err(serde::ser::Error::custom("more counts than a block holds"));
        }
        let mut bytes = [0u8; 2 * MAX_BLOCK_COUNTS];
        for (pair, c) in bytes.chunks_exact_mut(2).zip(self.0.iter()) {
            pair.copy_from_slice(&c.to_le_bytes());
        }
        s.serialize_bytes(&bytes[..2 * self.0.len()])
    }
}

impl<'de> Deserialize<'de> for Counts {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Counts;
            fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                write!(
                    f,
                    "an even number of bytes, at most {}",
                    2 * MAX_BLOCK_COUNTS
                )
            }
            fn visit_bytes<E: serde::de::Error>(self, b: &[u8]) -> Result<Counts, E> {
                if !b.len().is_multiple_of(2) || b.len() > 2 * MAX_BLOCK_COUNTS {
                    return Err(E::invalid_length(b.len(), &self));
                }
                let mut v = heapless::Vec::new();
                for pair in b.chunks_exact(2) {
                    // Cannot fail: the length was checked above.
                    let _ = v.push(u16::from_le_bytes([pair[0], pair[1]]));
                }
                Ok(Counts(v))
            }
        }
        d.deserialize_bytes(V)
    }
}

wire_type! {
    /// Shape of the envelope's decay, from the sign of F'(A) over the amplitudes seen (thesis 3.3).
    #[derive(Copy, Eq)]
    pub enum EnvelopeShape {
        Straight,
        Convex,
        Concave,
        Mixed,
    }
}

impl EnvelopeShape {
    pub const fn name(self) -> &'static str {
        match self {
            EnvelopeShape::Straight => "straight",
            EnvelopeShape::Convex => "convex",
            EnvelopeShape::Concave => "concave",
            EnvelopeShape::Mixed => "mixed",
        }
    }
}

wire_type! {
    /// Whether the on-board numbers can be trusted, and if not why.
    #[derive(Copy, Eq)]
    pub enum Verdict {
        Ok,
        /// Fewer than 5 cycles: the thesis advises against any fit.
        TooFewCycles,
        NoOscillation,
        /// The displacement or velocity ADC saturated.
        Saturated,
        /// The two estimators disagree beyond their standard errors.
        EstimatorsDisagree,
        Aborted,
        /// The on-board analysis did not run: an unloaded run (load 0, the apparatus alone), whose
        /// dimensionless μ are undefined. Fit the stored record on the host instead.
        NotAnalysed,
    }
}

impl Verdict {
    pub const fn name(self) -> &'static str {
        match self {
            Verdict::Ok => "ok",
            Verdict::TooFewCycles => "too-few-cycles",
            Verdict::NoOscillation => "no-oscillation",
            Verdict::Saturated => "saturated",
            Verdict::EstimatorsDisagree => "estimators-disagree",
            Verdict::Aborted => "aborted",
            Verdict::NotAnalysed => "not-analysed",
        }
    }
}

wire_type! {
    /// Coulomb–viscous constants (dimensionless μ0, μ1 of the thesis, eq. 10–11) and standard errors.
    #[derive(Copy, Default)]
    pub struct Estimate {
        pub mu0: f32,
        pub mu1: f32,
        pub mu0_se: f32,
        pub mu1_se: f32,
    }
}

wire_type! {
    /// The on-board analysis of a run.
    #[derive(Copy)]
    pub struct OnboardResult {
        pub run_id: u32,
        pub verdict: Verdict,
        pub cycles: u16,
        pub frequency_hz: f32,
        pub initial_amplitude_m: f32,
        pub duration_s: f32,
        /// What the technician is shown.
        pub best: Estimate,
        /// Averaging-law regression dA/dτ = a0 + a1 A.
        pub averaging: Estimate,
        /// Half-cycle peak regression X_{n+1} = D X_n − r(1 + D).
        pub decrement: Estimate,
        pub shape: EnvelopeShape,
        /// a2 of dA/dτ = a0 + a1 A + a2 A² (dimensionless).
        pub curvature: f32,
    }
}

wire_type! {
    /// Why a run ended.
    #[derive(Copy, Eq)]
    pub enum EndReason {
        /// The pin came to rest (or its amplitude sank into the noise).
        Stopped,
        MaxDuration,
        Aborted,
        Fault(HeaterFault),
        /// The acquisition overran and the run cannot be trusted.
        Overrun,
    }
}

wire_type! {
    /// Closes a run.
    #[derive(Copy)]
    pub struct RunEnd {
        pub run_id: u32,
        pub blocks: u32,
        pub samples: u32,
        pub overruns: u32,
        pub reason: EndReason,
    }
}

// ---------------------------------------------------------------------------------------------------
// Protocol v2: faults and boot report (fail-safe rig), gaps and compressed blocks (whole runs)
// ---------------------------------------------------------------------------------------------------

wire_type! {
    /// Why the rig drove outputs to their safe state by itself.
    #[derive(Copy, Eq)]
    pub enum FaultReason {
        /// The heater was cut off (thermocouple, temperature or runaway fault).
        Heater(HeaterFault),
        /// No command or heartbeat from the host for longer than [`limits::HOST_LEASE_MS`] while
        /// heating or holding the magnet.
        LeaseExpired,
        /// The electromagnet held longer than its limit and was switched off.
        MagnetHoldTime,
    }
}

wire_type! {
    /// A fault the rig handled by itself: the outputs concerned are already safe when this is sent.
    #[derive(Copy)]
    pub struct FaultReport {
        pub reason: FaultReason,
        /// Device uptime when the fault was detected.
        pub uptime_ms: u64,
        /// Temperature at the time (NaN when unknown).
        pub temp_c: f32,
    }
}

wire_type! {
    /// Why the MCU last reset.
    #[derive(Copy, Eq)]
    pub enum ResetCause {
        PowerOn,
        /// The reset pin (NRST button, debugger).
        Pin,
        /// A software reset requested by the firmware.
        Software,
        /// The independent watchdog was not fed in time: a task was stuck.
        Watchdog,
        /// A panic (message in [`BootReport::message`]).
        Panic,
        /// A HardFault or other CPU fault (registers in [`BootReport::message`]).
        CpuFault,
        Brownout,
        Unknown,
    }
}

/// Longest message a [`BootReport`] carries.
pub const BOOT_MESSAGE_LEN: usize = 120;

wire_type! {
    /// The reset cause and, after a panic or fault, what was kept of its message.
    pub struct BootReport {
        pub cause: ResetCause,
        pub message: heapless::String<BOOT_MESSAGE_LEN>,
    }
}

wire_type! {
    /// Samples `first_sample .. first_sample + count` of run `run_id` were lost: the acquisition
    /// overran. Stored and sent with the run's other frames, so the gap is part of the record.
    #[derive(Copy)]
    pub struct Gap {
        pub run_id: u32,
        pub first_sample: u32,
        pub count: u32,
    }
}

wire_type! {
    /// From sample `first_sample` of run `run_id` on, the ECR channel was converted on `range`; the
    /// first `settling` samples of it were taken while the transimpedance amplifier settled.
    #[derive(Copy)]
    pub struct EcrRangeChange {
        pub run_id: u32,
        pub first_sample: u32,
        pub range: u8,
        pub settling: u16,
    }
}

wire_type! {
    /// A compressed sample block: the v2 form of [`SampleBlock`], every field the same, the counts
    /// packed by [`crate::codec`] ([`PackedBlock::pack`], [`PackedBlock::unpack`]).
    pub struct PackedBlock {
        pub run_id: u32,
        /// Index of this block in the run, from 0.
        pub block: u32,
        /// Index in the run of the block's first sample.
        pub first_sample: u32,
        /// Device time of the block's first sample.
        pub t_us: u64,
        pub channels: ChannelSet,
        /// Number of samples in the block.
        pub samples: u16,
        /// ECR transimpedance range during the block.
        pub ecr_range: u8,
        pub temp_c: f32,
        pub log10_ecr_ohm: f32,
        /// The compressed counts ([`crate::codec`] describes the format). Serialised as bytes:
        /// the same bytes as a sequence of `u8` in postcard (a length, then the bytes), in one
        /// copy rather than one call per byte.
        #[serde(serialize_with = "packed_bytes")]
        pub data: heapless::Vec<u8, MAX_PACKED_BYTES>,
    }
}

fn packed_bytes<S: serde::Serializer>(
    data: &heapless::Vec<u8, MAX_PACKED_BYTES>,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_bytes(data)
}

/// Largest compressed payload of a [`PackedBlock`]: the raw form (a format byte and two bytes per
/// count), which the codec falls back to when compression would not pay, plus a little room.
pub const MAX_PACKED_BYTES: usize = 2 * MAX_BLOCK_COUNTS + 16;
