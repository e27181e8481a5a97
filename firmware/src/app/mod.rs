//! The rig's application: one state machine that the technician and the host drive.
//!
//! It is a plain value polled with the time ([`App::poll`]) and fed the bytes the host sends
//! ([`App::on_bytes`]); it drives the hardware only through [`crate::hal::Hardware`]. The board runs it
//! in an embassy task; the host's virtual rig runs the very same code against the simulator.
//!
//! ```text
//!   Idle ──Configure──▶ Configured ──Arm──▶ Armed ──Release / button──▶ Running ──▶ Finished
//!                          ▲   ◀──Disarm / hold-time limit──┘                 │ stop, max duration,
//!                          └──────────────────Configure / Arm ◀───────────────┘ abort, fault, gap list full
//! ```
//!
//! * **Arm** energises the magnet (the pin is held at x0) and starts the converter; samples taken while
//!   held calibrate the zeros of the on-board analysis.
//! * **Release** is refused unless armed, the magnet holds, the converter runs and the heater is
//!   healthy; then a short reverse pulse frees the pin and the run starts.
//! * During the run every sample goes to a block and to the analysis; each block is stored in the
//!   [`RunStore`] and sent from there, so the live stream and a later [`HostMsg::Pull`] are the same
//!   frames (same bytes, same sequence numbers).
//! * Samples come from the hardware-timed converter with their index in its stream; a sample's
//!   place in the run (hence its time) is that index, never a count of samples read. Samples the
//!   converter lost (the reader fell a whole ring behind, an ADC overrun) are a jump in index: the
//!   run records exactly which with a [`DeviceMsg::Gap`] frame and goes on; no block spans a gap.
//! * ECR: during a run the range is decided once per block from the mean of the block's settled ECR
//!   samples; each change is a [`DeviceMsg::EcrRange`] frame saying from which sample on the new
//!   range applies and how many samples settle.
//! * The run ends when the analysis sees the pin at rest (or its amplitude in the noise), at the
//!   maximum duration, on Abort or on a heater fault. Then come the result and the end frames.
//!
//! Every command is answered (Ack or Error with its sequence number); a frame that does not decode
//! is answered by `Error { Malformed }`. Nothing a host sends can make it panic.
//!
//! **Fail-safe.** Heating and holding the magnet need someone in charge ([`crate::lease`]): a host
//! renewing its lease with its commands and heartbeats, or the technician in stand-alone mode (a
//! long press of the button). When nobody is, and on every heater or magnet fault, the outputs
//! concerned go safe first
//! and a [`DeviceMsg::Fault`] says why afterwards; the latest fault and the reset cause are in every
//! [`Status`], and the first `Hello` after boot is answered with the [`DeviceMsg::Boot`] report too.

use crate::acquisition::{select, BlockBuilder};
use crate::analysis::{ConfigError, Finish, Phase, Pipeline, StopReason};
use crate::ecr::{count_to_volts, settling_samples, Ecr, RangeTrack};
use crate::hal::{AnalogSample, Hardware, Lamps, MagnetDrive, ANALOG_CHANNELS};
use crate::heater::{Heater, HeaterConfig};
use crate::lease::Lease;
use crate::release::{check_interlocks, Debouncer, MagnetEvent, Release, ReleaseConfig};
use crate::runstore::{Read, RunStore};
use crate::thermocouple;
use crate::wire::codec::Packer;
use crate::wire::frame::MAX_FRAME;
use crate::wire::{
    limits, AnalogChain, BootReport, Channel, Configure, Control, Decoder, DeviceError, DeviceInfo,
    DeviceMsg, EcrRangeChange, Encoder, EndReason, EnvelopeShape, ErrorCode, Estimate, FaultReason,
    FaultReport, Field, Frame, Gap, HeaterSetpoint, HostMsg, Interlock, OnboardResult, PackedBlock,
    ResetCause, RigState, RunEnd, RunHeader, SampleBlock, SampleClock, Status, Verdict, CHANNELS,
    PROTOCOL_VERSION,
};

/// Constants of the application.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AppConfig {
    pub device: DeviceInfo,
    pub release: ReleaseConfig,
    pub heater: HeaterConfig,
    /// Heater controller period, µs.
    pub heater_period_us: u32,
    /// ECR update period outside runs, µs (during a run: once per block).
    pub ecr_period_us: u32,
    /// Most run frames sent per poll (bounds the time a poll takes: each is a copy out of the store
    /// and one into the link, ~2k instructions on the M7 for a block; 4 per poll is 8000 frames/s,
    /// far more than a run makes).
    pub frames_per_poll: u8,
    /// Most samples taken from the converter per poll (bounds the time a poll takes; the
    /// converter's ring holds the rest, see `acquisition::RING_SCANS`). Within that cap a poll takes
    /// twice what arrives between two polls at the run's rate (see `poll_period_us`), at least 16:
    /// a backlog is caught up over several polls rather than in one long one.
    pub samples_per_poll: u16,
    /// How often the application is polled, µs (the board's ticker and the virtual rig's step:
    /// 500 µs). A poll's work must stay within its budget (20,000 instructions on the M7, checked
    /// by `cargo xtask target-test`): at 10 kS/s five channels a block's packing alone is ~45k
    /// instructions, spread over 6 polls, between which the samples, the analysis and the frames
    /// must fit; polls of 1 ms left no room for the live stream.
    pub poll_period_us: u32,
    /// Rows of the end-of-run regressions computed per poll (the fit is spread over polls; a row
    /// is up to ~500 instructions on the M7, so 16 rows stay under 9k). The result of a run of
    /// n half-cycles comes about 35 n / 16 polls after the pin stopped: 0.04 s for 20 half-cycles,
    /// 4.5 s for the longest run the analysis takes (2048).
    pub finish_rows_per_poll: u32,
    /// Host lease, ms ([`limits::HOST_LEASE_MS`]).
    pub host_lease_ms: u32,
    /// Stand-alone mode: long press, ms; longest hold, ms; heating after the last press, ms.
    pub standalone_press_ms: u32,
    pub standalone_hold_ms: u32,
    pub standalone_heat_ms: u32,
}

impl AppConfig {
    /// Defaults for a rig with this serial number.
    pub fn new(serial: u64) -> Self {
        AppConfig {
            device: DeviceInfo {
                protocol: PROTOCOL_VERSION,
                firmware: [0, 1, 0],
                serial,
                max_sample_rate_hz: *crate::wire::limits::SAMPLE_RATE_HZ.end(),
            },
            release: ReleaseConfig::default(),
            heater: HeaterConfig::default(),
            heater_period_us: 100_000,
            ecr_period_us: 100_000,
            frames_per_poll: 4,
            samples_per_poll: 128,
            poll_period_us: 500,
            finish_rows_per_poll: 16,
            host_lease_ms: limits::HOST_LEASE_MS,
            standalone_press_ms: limits::STANDALONE_PRESS_MS,
            standalone_hold_ms: limits::STANDALONE_HOLD_MS,
            standalone_heat_ms: limits::STANDALONE_HEAT_MS,
        }
    }
}

/// What the run-frame sender wants next (the live stream, or a [`HostMsg::Pull`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Want {
    /// The header, then the records from block `from_block` on.
    Header {
        from_block: u32,
    },
    /// The records from just after block `.0 − 1` on (found once the flash allows).
    Blocks(u32),
    /// The records from this position of the run's stream on, then the result and the end.
    From(u32),
    Result,
    End,
}

/// A run whose samples are all in, waiting for its end-of-run analysis (spread over polls): the
/// run is still `Running` until its result and end frames exist.
struct Ending {
    /// The fit in progress (`None`: the run is not analysed).
    job: Option<Finish>,
    reason: EndReason,
    blocks: u32,
    samples: u32,
}

/// A completed block being packed (a channel per poll) and framed before it goes to the store.
struct Packing {
    seq: u32,
    blk: SampleBlock,
    packed: PackedBlock,
    packer: Packer,
    /// Every channel is packed: the next step frames and stores it.
    packed_all: bool,
}

/// The application (see the module docs).
pub struct App<'a> {
    cfg: AppConfig,
    state: RigState,
    config: Option<Configure>,
    release: Release,
    debouncer: Debouncer,
    heater: Heater,
    ecr: Ecr,
    store: RunStore<'a>,
    /// The on-board analysis: allocated once by [`App::new`] and reset in place for each run
    /// (building one by value at run time puts its 43 KiB in the caller's stack frame);
    /// `pipeline_ready` says whether it is configured for the current run (an unloaded run is not
    /// analysed).
    pipeline: Option<Pipeline>,
    pipeline_ready: bool,
    ending: Option<Ending>,
    /// The last completed blocks, on their way to the store, oldest first (see
    /// [`App::pack_step`]): two, so that a block completing while the previous one is still being
    /// packed (the last, partial block of a run; a poll late) waits rather than forcing it.
    packing: heapless::Deque<Packing, 2>,
    /// Blocks handed to `packing` since start-up (tells a poll whether it completed one).
    blocks_completed: u32,
    builder: Option<BlockBuilder>,
    decoder: Decoder<HostMsg>,
    encoder: Encoder,
    out: [u8; MAX_FRAME],
    seq: u32,
    run_id: u32,
    /// The number after `run_id` may have been spent before a reset (see [`App::start`]): the
    /// next run skips it.
    skip_run_number: bool,
    /// The highest run number of this rig a host holds ([`HostMsg::RunFloor`]).
    run_floor: u32,
    run_start_us: u64,
    /// Samples of this run lost by the acquisition.
    run_overruns: u32,
    /// The converter's stream: its clock, the index of the sample expected next, and the index of
    /// the current run's sample 0.
    clock: Option<SampleClock>,
    next_index: u64,
    run_base: u64,
    /// Which range each ECR sample was converted on, and the block's settled ECR mean.
    ecr_track: RangeTrack,
    want: Option<Want>,
    /// Blocks `.0 .. .1` asked for by [`HostMsg::PullBlocks`], sent before the rest.
    range: Option<(u32, u32)>,
    last_heater_us: Option<u64>,
    last_ecr_us: Option<u64>,
    /// Samples lost by the acquisition since start-up (held or running).
    overruns: u32,
    dropped_frames: u32,
    now_us: u64,
    started: bool,
    // ---- fail-safe ----
    lease: Lease,
    last_fault: Option<FaultReport>,
    faults: u32,
    /// The boot report, until a host's `Hello` took it.
    boot: Option<BootReport>,
    reset_cause: ResetCause,
    /// The host's last setpoint (stand-alone mode heats to it).
    last_setpoint: Option<HeaterSetpoint>,
    /// The current press of the button already counted as a long press.
    long_press_done: bool,
    // ---- self-test ----
    /// The self-test check under way, if any.
    selftest: Option<selftest::SelfTestRun>,
    /// A deliberate panic or stall the board must carry out (the application never panics).
    deliberate: Option<crate::selftest::Deliberate>,
    /// A deliberate panic or stall was accepted: the ECR source is at 0 V and its controller no
    /// longer sets it, until the reset that follows.
    ecr_parked: bool,
}

macro_rules! info {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")]
        defmt::info!($($t)*);
    }};
}

mod commands;
mod faults;
mod frames;
mod run_end;
mod sampling;
mod selftest;

impl<'a> App<'a> {
    pub fn new(cfg: AppConfig, store: RunStore<'a>) -> Self {
        App {
            cfg,
            state: RigState::Idle,
            config: None,
            release: Release::new(cfg.release),
            debouncer: Debouncer::new(cfg.release.debounce_us),
            heater: Heater::new(cfg.heater),
            ecr: Ecr::new(),
            store,
            pipeline: Pipeline::new(&Configure::real_rig(0.3)).ok(),
            pipeline_ready: false,
            ending: None,
            packing: heapless::Deque::new(),
            blocks_completed: 0,
            builder: None,
            decoder: Decoder::new(),
            encoder: Encoder::new(),
            out: [0; MAX_FRAME],
            seq: 0,
            run_id: 0,
            skip_run_number: false,
            run_floor: 0,
            run_start_us: 0,
            run_overruns: 0,
            clock: None,
            next_index: 0,
            run_base: 0,
            ecr_track: RangeTrack::new(0),
            want: None,
            range: None,
            last_heater_us: None,
            last_ecr_us: None,
            overruns: 0,
            dropped_frames: 0,
            now_us: 0,
            started: false,
            lease: Lease::new(cfg.host_lease_ms, cfg.standalone_heat_ms),
            last_fault: None,
            faults: 0,
            boot: None,
            reset_cause: ResetCause::Unknown,
            last_setpoint: None,
            long_press_done: false,
            selftest: None,
            deliberate: None,
            ecr_parked: false,
        }
    }

    /// Why the rig last reset: told to the first host that says hello, and in every status.
    pub fn set_boot_report(&mut self, report: BootReport) {
        self.reset_cause = report.cause;
        self.boot = Some(report);
    }

    /// The latest fault handled since boot, if any.
    pub fn last_fault(&self) -> Option<FaultReport> {
        self.last_fault
    }

    /// Faults handled since boot.
    pub fn faults(&self) -> u32 {
        self.faults
    }

    /// Changes the host lease, ms (default [`limits::HOST_LEASE_MS`]).
    pub fn set_host_lease_ms(&mut self, ms: u32) {
        self.cfg.host_lease_ms = ms;
        self.lease.set_host_ms(ms);
    }

    /// Who holds the rig now.
    pub fn control(&self) -> Control {
        self.lease.control(self.now_us)
    }

    /// The state as reported (a latched heater fault shows as `Fault` outside a run).
    pub fn state(&self) -> RigState {
        if self.heater.fault().is_some() && self.state != RigState::Running {
            RigState::Fault
        } else {
            self.state
        }
    }

    /// Id of the current or last run (0 before the first).
    pub fn run_id(&self) -> u32 {
        self.run_id
    }

    /// Index in the converter's stream of the current or last run's sample 0 (run sample `i` is
    /// stream sample `run_first_index() + i`).
    pub fn run_first_index(&self) -> u64 {
        self.run_base
    }

    pub fn store(&self) -> &RunStore<'a> {
        &self.store
    }

    /// Frames the link refused outside runs (Acks, Errors, Status; run frames are never dropped, they
    /// wait in the store).
    pub fn dropped_frames(&self) -> u32 {
        self.dropped_frames
    }

    /// The link was (re)opened: forget any half-received frame.
    pub fn link_reset(&mut self) {
        self.decoder.reset();
    }

    /// Snapshot for [`DeviceMsg::Status`].
    pub fn status(&self) -> Status {
        Status {
            state: self.state(),
            run_id: self.run_id,
            temp_c: self.heater.temp_c(),
            heater_setpoint_c: self.heater.setpoint(),
            heater_duty: self.heater.duty(),
            heater_fault: self.heater.fault(),
            magnet_on: self.release.is_on(),
            log10_ecr_ohm: self.ecr.log10_r(),
            ecr_range: self.ecr.range(),
            samples: self.builder.as_ref().map_or(0, BlockBuilder::samples),
            overruns: self.overruns,
            uptime_ms: self.now_us / 1000,
            last_fault: self.last_fault,
            faults: self.faults,
            reset_cause: self.reset_cause,
            control: self.control(),
        }
    }

    /// The status lamps for the current state at time `now_us`: green blinking slowly when idle,
    /// amber when armed, green blinking fast while running, green steady when a run is finished,
    /// red blinking on a fault.
    pub fn lamps(&self, now_us: u64) -> Lamps {
        let ms = now_us / 1000;
        match self.state() {
            RigState::Fault => Lamps {
                red: ms % 500 < 250,
                ..Lamps::default()
            },
            RigState::Idle | RigState::Configured => Lamps {
                green: ms % 1000 < 500,
                ..Lamps::default()
            },
            RigState::Armed => Lamps {
                amber: true,
                ..Lamps::default()
            },
            RigState::Running => Lamps {
                green: ms % 200 < 100,
                ..Lamps::default()
            },
            RigState::Finished => Lamps {
                green: true,
                ..Lamps::default()
            },
        }
    }

    /// Whether run frames are waiting to be sent (a stream or pull under way).
    pub fn sending(&self) -> bool {
        self.want.is_some() || self.range.is_some()
    }

    /// Feeds bytes received from the host; handles every complete frame.
    pub fn on_bytes<H: Hardware>(&mut self, hw: &mut H, bytes: &[u8], now_us: u64) {
        self.now_us = self.now_us.max(now_us);
        self.start(hw);
        for &b in bytes {
            match self.decoder.push(b) {
                Some(Ok(frame)) => self.handle(hw, frame),
                Some(Err(_)) => self.error(hw, ErrorCode::Malformed, None),
                None => {}
            }
        }
        self.pump(hw, self.cfg.frames_per_poll);
    }

    /// Runs everything that depends on time: magnet, heater, ECR, button, acquisition, sending.
    pub fn poll<H: Hardware>(&mut self, hw: &mut H, now_us: u64) {
        self.now_us = self.now_us.max(now_us);
        let now = self.now_us;
        self.start(hw);
        // Nobody in charge of what heats or holds: safe first, then say why.
        let need = self.heater.heating() || self.release.is_holding();
        if let Some(reason) = self.lease.expired(now, need) {
            info!("nobody holds the rig: heater and magnet off");
            self.make_safe(hw);
            self.fault(hw, reason);
        }
        match self.release.poll(hw, now) {
            Some(MagnetEvent::HoldTimeExceeded) => {
                info!("hold time exceeded: magnet off");
                if self.state == RigState::Armed {
                    hw.adc_stop();
                    self.state = RigState::Configured;
                }
                self.fault(hw, FaultReason::MagnetHoldTime);
            }
            Some(MagnetEvent::Released) | None => {}
        }
        if self
            .last_heater_us
            .is_none_or(|t| now.saturating_sub(t) >= self.cfg.heater_period_us as u64)
        {
            let dt = self
                .last_heater_us
                .map_or(0.0, |t| now.saturating_sub(t) as f32 * 1e-6);
            self.last_heater_us = Some(now);
            let read = hw.read_thermocouple();
            let checked = thermocouple::check(read.as_ref().map(|r| (&r.regs, r.age_us)));
            let step = self.heater.step(checked, dt);
            hw.set_heater_duty(step.duty);
            if let Some(f) = step.new_fault {
                info!("heater fault: heater off");
                self.fault(hw, FaultReason::Heater(f));
                if self.state == RigState::Running {
                    self.end_run(hw, EndReason::Fault(f));
                }
            }
        }
        if self.state != RigState::Running
            && !self.ecr_parked
            && !self.selftest_drives_ecr()
            && self
                .last_ecr_us
                .is_none_or(|t| now.saturating_sub(t) >= self.cfg.ecr_period_us as u64)
        {
            self.last_ecr_us = Some(now);
            let v = hw.read_ecr_output();
            let before = (self.ecr.range(), self.ecr.source_v());
            self.ecr.update(v, hw);
            self.ecr_changed(hw, before);
        }
        let pressed = hw.button_pressed();
        if self.debouncer.update(pressed, now) {
            info!("button");
            if self.lease.control(now) == Control::StandAlone {
                self.lease.press(now);
            }
            let r = if self.state == RigState::Armed {
                self.try_release(hw)
            } else {
                Err(ErrorCode::Interlock(Interlock::NotArmed))
            };
            if let Err(code) = r {
                self.error(hw, code, None);
            }
        }
        let held = self.debouncer.held_us(now);
        if held == 0 {
            self.long_press_done = false;
        } else if !self.long_press_done && held >= self.cfg.standalone_press_ms as u64 * 1000 {
            self.long_press_done = true;
            self.stand_alone(hw);
        }
        // One poll does a bounded amount of work (on the M7 a budget of 20,000 instructions, checked
        // by `cargo xtask target-test`): the samples of one poll period; then, if none of them
        // completed a block, a step of the block being packed (a channel, ~9k on the M7, or its
        // framing) and one frame to the link; if a block was completed (its hand-over is itself
        // work), only the framing of a block already packed. With nothing to pack: more samples if
        // a backlog waits (up to twice a poll's worth in all; never while a block waits to be
        // packed, so that blocks cannot complete faster than they are packed), then frames to the
        // link, then a part of the end-of-run fit.
        let (arrivals, limit) = (self.samples_arriving(), self.samples_per_poll());
        let blocks = self.blocks_completed;
        let mut behind = self.drain(hw, arrivals);
        self.store.service(hw);
        let completed = self.blocks_completed != blocks;
        let stepped = if completed {
            self.packing.front().is_some_and(|p| p.packed_all) && self.pack_step()
        } else {
            self.pack_step()
        };
        if stepped {
            // One frame rides along, so that the live stream keeps up with the blocks however busy
            // the packing is (at 20 kS/s it packs in six polls of every 6.4).
            self.pump(hw, 1);
        } else if self.packing.is_empty() {
            if behind {
                behind = self.drain(hw, limit.saturating_sub(arrivals));
            }
            if !behind && self.pump(hw, self.cfg.frames_per_poll) == 0 {
                self.analyse_step();
            }
        }
        self.selftest_step(hw);
        let lamps = self.selftest_lamps().unwrap_or_else(|| self.lamps(now));
        hw.set_lamps(lamps);
    }

    /// First call after reset: outputs to their safe values, and the last run back from flash.
    fn start<H: Hardware>(&mut self, hw: &mut H) {
        if self.started {
            return;
        }
        self.started = true;
        hw.magnet_drive(MagnetDrive::Off);
        hw.set_heater_duty(0.0);
        self.ecr.init(hw);
        if let Some(r) = self.store.recover(hw) {
            info!(
                "run {} recovered from flash: {} blocks, finished: {}",
                r.run_id, r.blocks, r.finished
            );
            self.run_id = r.run_id;
            // A run released just before the reset may have sent its header to the host before
            // the header reached flash: its number is spent, though flash does not show it. The
            // next run skips it, so that no two runs of this rig share a number.
            self.skip_run_number = true;
        }
    }

    fn next_seq(&mut self) -> u32 {
        let s = self.seq;
        self.seq = self.seq.wrapping_add(1);
        s
    }
}

/// Most events (gaps, ECR range changes) one run records: a run that would need more is ended (an
/// overrun that cannot be described exactly any more) or holds its ECR range.
pub const MAX_RUN_EVENTS: usize = 1024;

/// Event slots of a run kept for gaps: ECR range changes stop (the range is held) when only these
/// are left.
const GAP_RESERVE: usize = 16;

/// The configuration field the on-board analysis objected to.
fn field_of(e: ConfigError) -> Field {
    match e {
        ConfigError::Mass => Field::Mass,
        ConfigError::Stiffness => Field::Stiffness,
        ConfigError::Load => Field::Load,
        ConfigError::SampleRate | ConfigError::Undersampled => Field::SampleRate,
        ConfigError::MaxDuration => Field::MaxDuration,
        ConfigError::InitialAmplitude => Field::InitialAmplitude,
        ConfigError::MissingChannel(_) => Field::Channels,
        ConfigError::Calibration(_) => Field::Calibration,
    }
}

/// The result of a run the on-board analysis could not take (its configuration was refused, e.g. an
/// unloaded run, whose μ are undefined): no estimate.
fn unanalysed(run_id: u32, samples: u32, rate: u32) -> OnboardResult {
    let none = Estimate {
        mu0: f32::NAN,
        mu1: f32::NAN,
        mu0_se: f32::NAN,
        mu1_se: f32::NAN,
    };
    OnboardResult {
        run_id,
        verdict: Verdict::NotAnalysed,
        cycles: 0,
        frequency_hz: f32::NAN,
        initial_amplitude_m: f32::NAN,
        duration_s: samples as f32 / rate.max(1) as f32,
        best: none,
        averaging: none,
        decrement: none,
        shape: EnvelopeShape::Straight,
        curvature: f32::NAN,
    }
}

#[cfg(test)]
mod tests;
