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

use crate::acquisition::{select, BlockBuilder};
use crate::analysis::{ConfigError, Finish, Phase, Pipeline, StopReason};
use crate::ecr::{count_to_volts, settling_samples, Ecr, RangeTrack};
use crate::hal::{AnalogSample, Hardware, Lamps, MagnetDrive, ANALOG_CHANNELS};
use crate::heater::{Heater, HeaterConfig};
use crate::release::{check_interlocks, Debouncer, MagnetEvent, Release, ReleaseConfig};
use crate::runstore::{Read, RunStore};
use crate::wire::codec::Packer;
use crate::wire::frame::MAX_FRAME;
use crate::wire::{
    Channel, Configure, Decoder, DeviceError, DeviceInfo, DeviceMsg, EcrRangeChange, Encoder,
    EndReason, EnvelopeShape, ErrorCode, Estimate, Field, Frame, Gap, HostMsg, Interlock,
    OnboardResult, PackedBlock, RigState, RunEnd, RunHeader, SampleBlock, SampleClock, Status,
    Verdict, CHANNELS, PROTOCOL_VERSION,
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
}

macro_rules! info {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")]
        defmt::info!($($t)*);
    }};
}

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
        }
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
        match self.release.poll(hw, now) {
            Some(MagnetEvent::HoldTimeExceeded) => {
                info!("hold time exceeded: magnet off");
                self.error(hw, ErrorCode::HoldTimeExceeded, None);
                if self.state == RigState::Armed {
                    hw.adc_stop();
                    self.state = RigState::Configured;
                }
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
            let reading = hw.read_thermocouple();
            let step = self.heater.step(reading, dt);
            hw.set_heater_duty(step.duty);
            if let Some(f) = step.new_fault {
                info!("heater fault: heater off");
                self.error(hw, ErrorCode::Heater(f), None);
                if self.state == RigState::Running {
                    self.end_run(hw, EndReason::Fault(f));
                }
            }
        }
        if self.state != RigState::Running
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
            let r = if self.state == RigState::Armed {
                self.try_release(hw)
            } else {
                Err(ErrorCode::Interlock(Interlock::NotArmed))
            };
            if let Err(code) = r {
                self.error(hw, code, None);
            }
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
        let lamps = self.lamps(now);
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
        }
    }

    fn next_seq(&mut self) -> u32 {
        let s = self.seq;
        self.seq = self.seq.wrapping_add(1);
        s
    }

    /// Sends a frame made now (not part of a run). Returns whether the link took it.
    fn send<H: Hardware>(&mut self, hw: &mut H, msg: &DeviceMsg) -> bool {
        let seq = self.next_seq();
        let ok = match self.encoder.encode(seq, msg, &mut self.out) {
            Ok(bytes) => hw.send_frame(bytes),
            Err(_) => false,
        };
        if !ok {
            self.dropped_frames = self.dropped_frames.saturating_add(1);
        }
        ok
    }

    fn ack<H: Hardware>(&mut self, hw: &mut H, seq: u32) {
        self.send(hw, &DeviceMsg::Ack { seq });
    }

    fn error<H: Hardware>(&mut self, hw: &mut H, code: ErrorCode, about_seq: Option<u32>) {
        self.send(hw, &DeviceMsg::Error(DeviceError { code, about_seq }));
    }

    fn reply<H: Hardware>(&mut self, hw: &mut H, seq: u32, r: Result<(), ErrorCode>) {
        match r {
            Ok(()) => self.ack(hw, seq),
            Err(code) => self.error(hw, code, Some(seq)),
        }
    }

    fn handle<H: Hardware>(&mut self, hw: &mut H, frame: Frame<HostMsg>) {
        let seq = frame.seq;
        let r = match frame.msg {
            HostMsg::Hello { protocol } => {
                let info = self.cfg.device;
                self.send(hw, &DeviceMsg::Hello(info));
                if protocol == PROTOCOL_VERSION {
                    Ok(())
                } else {
                    Err(ErrorCode::ProtocolMismatch {
                        device: PROTOCOL_VERSION,
                    })
                }
            }
            HostMsg::Configure(c) => self.configure(c),
            HostMsg::SetHeater(sp) => match sp.validate() {
                Ok(()) => {
                    self.heater.set(sp);
                    Ok(())
                }
                Err(f) => Err(ErrorCode::OutOfRange(f)),
            },
            HostMsg::HeaterOff => {
                self.heater.off();
                hw.set_heater_duty(0.0);
                Ok(())
            }
            HostMsg::Arm => self.arm(hw),
            HostMsg::Disarm => {
                if self.state == RigState::Armed {
                    hw.adc_stop();
                    self.state = RigState::Configured;
                }
                Ok(())
            }
            HostMsg::Release => self.try_release(hw),
            HostMsg::Abort => {
                match self.state {
                    RigState::Running => self.end_run(hw, EndReason::Aborted),
                    RigState::Armed => {
                        hw.adc_stop();
                        self.state = RigState::Configured;
                    }
                    _ => {}
                }
                Ok(())
            }
            HostMsg::Status => {
                let s = self.status();
                self.send(hw, &DeviceMsg::Status(s));
                Ok(())
            }
            HostMsg::Pull { run_id, from_block } => {
                if self.store.run_id() == Some(run_id) && run_id != 0 {
                    self.want = Some(Want::Header { from_block });
                    Ok(())
                } else {
                    Err(ErrorCode::NoRun)
                }
            }
            HostMsg::PullBlocks {
                run_id,
                first,
                count,
            } => {
                if self.store.run_id() == Some(run_id) && run_id != 0 {
                    self.range = Some((first, first.saturating_add(count)));
                    Ok(())
                } else {
                    Err(ErrorCode::NoRun)
                }
            }
            HostMsg::Heartbeat => Ok(()),
            HostMsg::Safe => {
                self.heater.off();
                hw.set_heater_duty(0.0);
                self.release.off(hw);
                if self.state == RigState::Armed {
                    hw.adc_stop();
                    self.state = RigState::Configured;
                }
                Ok(())
            }
        };
        self.reply(hw, seq, r);
    }

    fn configure(&mut self, c: Configure) -> Result<(), ErrorCode> {
        c.validate().map_err(ErrorCode::OutOfRange)?;
        if matches!(self.state, RigState::Armed | RigState::Running) {
            return Err(ErrorCode::Busy);
        }
        // What the on-board analysis cannot take is refused now rather than discovered after the run,
        // except an unloaded run (load 0: the apparatus alone), which runs without on-board analysis.
        // (No pipeline is built here, even as a fallback: its 43 KiB would be in this call's stack
        // frame. App::new allocates the one pipeline.)
        let refused = match &mut self.pipeline {
            Some(p) => p.reset(&c).err(),
            None => None,
        };
        match refused {
            None | Some(ConfigError::Load) => {}
            Some(e) => return Err(ErrorCode::OutOfRange(field_of(e))),
        }
        self.config = Some(c);
        self.state = RigState::Configured;
        Ok(())
    }

    fn arm<H: Hardware>(&mut self, hw: &mut H) -> Result<(), ErrorCode> {
        let cfg = match (self.state, self.config) {
            (RigState::Running, _) => return Err(ErrorCode::Busy),
            (RigState::Armed, _) => return Ok(()),
            (_, None) => return Err(ErrorCode::NotConfigured),
            (_, Some(c)) => c,
        };
        self.release.hold(hw, self.now_us);
        self.pipeline_ready = match &mut self.pipeline {
            Some(p) => p.reset(&cfg).is_ok(),
            None => false,
        };
        hw.adc_stop();
        // A converter that does not start is caught by the release interlock (NotSampling).
        self.clock = hw.adc_start(cfg.sample_rate_hz);
        self.next_index = 0;
        self.ecr_track = RangeTrack::new(self.ecr.range());
        self.state = RigState::Armed;
        info!("armed");
        Ok(())
    }

    fn try_release<H: Hardware>(&mut self, hw: &mut H) -> Result<(), ErrorCode> {
        let Some(cfg) = self.config else {
            return Err(ErrorCode::NotConfigured);
        };
        if self.state == RigState::Running {
            return Err(ErrorCode::Busy);
        }
        let clock = self.clock.filter(|_| hw.adc_running());
        check_interlocks(
            self.state == RigState::Armed,
            self.release.is_holding(),
            clock.is_some(),
            self.heater.healthy(),
        )
        .map_err(ErrorCode::Interlock)?;
        let Some(clock) = clock else {
            return Err(ErrorCode::Interlock(Interlock::NotSampling));
        };
        // Samples converted before this instant belong to the hold.
        self.drain(hw, self.cfg.samples_per_poll as usize);
        if self.state != RigState::Armed {
            return Err(ErrorCode::Interlock(Interlock::NotArmed));
        }
        let now = self.now_us;
        // The run's sample 0 is the first conversion to begin after the magnet lets go.
        self.release.release(hw, now);
        self.run_base = hw.adc_next_index();
        if let Some(p) = self.pipeline.as_mut().filter(|_| self.pipeline_ready) {
            p.release();
        }
        self.run_id = self.run_id.wrapping_add(1).max(1);
        self.run_start_us = now;
        self.run_overruns = 0;
        self.ecr.set_hold(false);
        self.builder = Some(BlockBuilder::new(
            self.run_id,
            cfg.channels,
            cfg.calibration[Channel::Temperature.index()],
            clock,
            now,
        ));
        let header = RunHeader {
            run_id: self.run_id,
            config: cfg,
            temp_c: self.heater.temp_c(),
            t_us: now,
            clock,
        };
        let seq = self.next_seq();
        if let Ok(frame) = self
            .encoder
            .encode(seq, &DeviceMsg::RunStarted(header), &mut self.out)
        {
            self.store.begin(hw, self.run_id, frame);
        }
        // The range the run starts on, and what is left of its settling after a change made while
        // holding: from here on every sample's range is known from these frames.
        let settling = self
            .ecr_track
            .settled_from()
            .saturating_sub(self.run_base)
            .min(u16::MAX as u64) as u16;
        self.push_event(DeviceMsg::EcrRange(EcrRangeChange {
            run_id: self.run_id,
            first_sample: 0,
            range: self.ecr.range(),
            settling,
        }));
        self.want = Some(Want::Header { from_block: 0 });
        self.range = None;
        self.state = RigState::Running;
        info!("released: run {}", self.run_id);
        Ok(())
    }

    /// Stores a run event (a [`DeviceMsg::Gap`] or [`DeviceMsg::EcrRange`] frame, sent in its place
    /// among the blocks). False when the run has used its [`MAX_RUN_EVENTS`] or the store refused it.
    fn push_event(&mut self, event: DeviceMsg) -> bool {
        if self.events_free() == 0 {
            return false;
        }
        // The block being packed goes first: records stay in the order they happened.
        self.finish_packing();
        let seq = self.next_seq();
        match self.encoder.encode(seq, &event, &mut self.out) {
            Ok(frame) => self.store.push_event(frame),
            Err(_) => false,
        }
    }

    /// Events the run may still record.
    fn events_free(&self) -> usize {
        MAX_RUN_EVENTS.saturating_sub(self.store.events() as usize)
    }

    /// Samples arriving per poll period at the run's rate (at least 8).
    fn samples_arriving(&self) -> usize {
        let rate = self.config.map_or(0, |c| c.sample_rate_hz) as u64;
        let per_poll = rate * self.cfg.poll_period_us as u64 / 1_000_000;
        (per_poll.max(8) as usize).min(self.cfg.samples_per_poll as usize)
    }

    /// Most samples one poll takes (see [`AppConfig::samples_per_poll`]).
    pub fn samples_per_poll(&self) -> usize {
        (2 * self.samples_arriving())
            .max(16)
            .min(self.cfg.samples_per_poll as usize)
    }

    /// Moves converted samples to the hold capture or to the run, at most `limit` (the converter's
    /// ring holds the rest until the next poll; a reader that falls a whole ring behind loses
    /// samples, which the indices then show). Returns true when it stopped at that limit (samples
    /// may still be waiting).
    fn drain<H: Hardware>(&mut self, hw: &mut H, limit: usize) -> bool {
        const CHUNK: usize = 32;
        let mut buf = [[0u16; ANALOG_CHANNELS]; CHUNK];
        let mut budget = limit;
        while budget > 0 {
            if !matches!(self.state, RigState::Armed | RigState::Running) || self.ending.is_some() {
                return false;
            }
            let want = budget.min(CHUNK);
            let batch = hw.adc_read(&mut buf[..want]);
            if batch.first > self.next_index {
                self.lost(hw, self.next_index, batch.first);
                if !matches!(self.state, RigState::Armed | RigState::Running) {
                    return false;
                }
            }
            self.next_index = self.next_index.max(batch.end());
            let n = batch.len.min(want);
            for (k, s) in buf.iter().take(n).enumerate() {
                if self.take_sample(hw, s, batch.first + k as u64) {
                    return false;
                }
            }
            budget -= n;
            if n < want {
                return false;
            }
        }
        true
    }

    /// Stream samples `from .. to` were lost by the acquisition. In a run: the block in progress is
    /// closed, a [`DeviceMsg::Gap`] frame records exactly which samples of the run are missing, and
    /// the run goes on (the on-board analysis keeps what came before the first gap). Never silent:
    /// also counted in the status and the run's end frame.
    fn lost<H: Hardware>(&mut self, hw: &mut H, from: u64, to: u64) {
        let count = to.saturating_sub(from);
        self.overruns = self
            .overruns
            .saturating_add(count.min(u32::MAX as u64) as u32);
        info!("acquisition: samples {} .. {} lost", from, to);
        if self.state != RigState::Running || to <= self.run_base {
            // Hold samples: the zero capture simply has fewer of them.
            return;
        }
        let first = from.max(self.run_base) - self.run_base;
        let end = to - self.run_base;
        let (Ok(first), Ok(end)) = (u32::try_from(first), u32::try_from(end)) else {
            self.end_run(hw, EndReason::MaxDuration);
            return;
        };
        let count = end - first;
        self.run_overruns = self.run_overruns.saturating_add(count);
        if let Some(blk) = self.builder.as_mut().and_then(|b| b.gap(end)) {
            self.store_block(hw, blk);
        }
        if let Some(p) = self.pipeline.as_mut().filter(|_| self.pipeline_ready) {
            p.gap(count);
        }
        let gap = Gap {
            run_id: self.run_id,
            first_sample: first,
            count,
        };
        if !self.push_event(DeviceMsg::Gap(gap)) {
            // More gaps than a run can list: what is recorded can no longer be described exactly,
            // so the run ends here (its end frame says so).
            self.end_run(hw, EndReason::Overrun);
        }
    }

    /// One sample, with its index in the converter's stream; returns true when it ended the run.
    fn take_sample<H: Hardware>(&mut self, hw: &mut H, s: &AnalogSample, index: u64) -> bool {
        let temp = self.heater.temp_c();
        let Some(cfg) = &self.config else {
            return false;
        };
        match self.state {
            RigState::Armed => {
                if let Some(p) = self.pipeline.as_mut().filter(|_| self.pipeline_ready) {
                    let mut sel = [0u16; CHANNELS];
                    let n = select(
                        cfg.channels,
                        cfg.calibration[Channel::Temperature.index()],
                        s,
                        temp,
                        &mut sel,
                    );
                    p.capture(&sel[..n]);
                }
                false
            }
            RigState::Running => {
                // Converted before the release: part of the hold, not of the run.
                let Some(i) = index.checked_sub(self.run_base) else {
                    return false;
                };
                let Ok(i) = u32::try_from(i) else {
                    self.end_run(hw, EndReason::MaxDuration);
                    return true;
                };
                self.ecr_track.add(index, s[3]);
                let Some(b) = &mut self.builder else {
                    return false;
                };
                let mut sel = [0u16; CHANNELS];
                let n = b.select(s, temp, &mut sel);
                let block = b.push_selected(&sel[..n], temp, i);
                let max_samples = cfg.max_samples();
                let ready = self.pipeline_ready;
                let phase = self
                    .pipeline
                    .as_mut()
                    .filter(|_| ready)
                    .map(|p| p.push(&sel[..n]));
                if let Some(blk) = block {
                    self.store_block(hw, blk);
                }
                let reason = match phase {
                    Some(Phase::Finished(StopReason::MaxDuration)) => Some(EndReason::MaxDuration),
                    Some(Phase::Finished(_)) => Some(EndReason::Stopped),
                    _ if i.saturating_add(1) >= max_samples => Some(EndReason::MaxDuration),
                    _ => None,
                };
                if let Some(r) = reason {
                    self.end_run(hw, r);
                    return true;
                }
                false
            }
            _ => false,
        }
    }

    /// The ECR range or source changed (`before` = range and source before the last update): the
    /// samples from the next conversion on settle for the new range's settling time; during a run,
    /// a range change is recorded as a [`DeviceMsg::EcrRange`] frame.
    fn ecr_changed<H: Hardware>(&mut self, hw: &mut H, before: (u8, f32)) {
        let (range, source) = (self.ecr.range(), self.ecr.source_v());
        if (range, source.to_bits()) == (before.0, before.1.to_bits()) {
            return;
        }
        let at = if hw.adc_running() {
            hw.adc_next_index()
        } else {
            0
        };
        let settling = self.clock.map_or(0, |c| settling_samples(range, c));
        self.ecr_track.switch(at, range, settling);
        if self.state == RigState::Running && range != before.0 {
            let first_sample = at.saturating_sub(self.run_base).min(u32::MAX as u64) as u32;
            let change = EcrRangeChange {
                run_id: self.run_id,
                first_sample,
                range,
                settling,
            };
            // Keep room for gaps: a run whose range changes this often holds its range instead
            // (switched back at once; the samples settle again from the same instant).
            if self.events_free() <= GAP_RESERVE || !self.push_event(DeviceMsg::EcrRange(change)) {
                self.ecr.set_hold(true);
                self.ecr.set_range(before.0, hw);
                let settling =
                    settling.max(self.clock.map_or(0, |c| settling_samples(before.0, c)));
                self.ecr_track.switch(at, before.0, settling);
            }
        }
    }

    /// Completes a block's ECR and temperature fields (the ECR range is the one used during the
    /// block; the reading at its end sets the next one) and stores it.
    ///
    /// The resistance is computed from the mean of the block's ECR samples converted on the current
    /// range and source after they settled (NaN when the block has none, e.g. all settling, or when
    /// they were outside the range's span); that reading then sets the range and source for what
    /// follows.
    fn store_block<H: Hardware>(&mut self, hw: &mut H, mut blk: SampleBlock) {
        blk.ecr_range = self
            .ecr_track
            .range_at(self.run_base + blk.first_sample as u64);
        blk.log10_ecr_ohm = match self.ecr_track.take_mean() {
            Some(count) => {
                let before = (self.ecr.range(), self.ecr.source_v());
                let l = self.ecr.update(count_to_volts(count), hw);
                self.ecr_changed(hw, before);
                // A reading out of the range's span only moves the range: no resistance for it.
                if self.ecr.measured() {
                    l
                } else {
                    f32::NAN
                }
            }
            None => f32::NAN,
        };
        blk.temp_c = self.heater.temp_c();
        // Both places taken: the oldest is packed and stored now, whatever it costs.
        if self.packing.is_full() {
            while self.pack_step() && self.packing.is_full() {}
        }
        let seq = self.next_seq();
        self.blocks_completed = self.blocks_completed.wrapping_add(1);
        // Cannot fail for a block the builder made (consistent, at most BLOCK_LEN samples).
        if let Ok(packed) = PackedBlock::start(&blk) {
            let _ = self.packing.push_back(Packing {
                seq,
                blk,
                packed,
                packer: Packer::new(),
                packed_all: false,
            });
        }
    }

    /// Packs one channel of the block on its way to the store, or, once all are, frames it and
    /// stores it. False when there was nothing to do.
    fn pack_step(&mut self) -> bool {
        let Some(p) = self.packing.front_mut() else {
            return false;
        };
        if !p.packed_all {
            match p.packed.pack_step(&p.blk, &mut p.packer) {
                Ok(done) => p.packed_all = done,
                // Cannot happen for a block the builder made; dropped rather than stalling.
                Err(_) => {
                    self.packing.pop_front();
                }
            }
            return true;
        }
        if let Some(p) = self.packing.pop_front() {
            let k = p.packed.block;
            if let Ok(frame) =
                self.encoder
                    .encode(p.seq, &DeviceMsg::Packed(p.packed), &mut self.out)
            {
                self.store.push_block(k, frame);
            }
        }
        true
    }

    /// Packs and stores the blocks on their way to the store now, whatever it costs (another record
    /// must follow them: an event, the end of the run).
    fn finish_packing(&mut self) {
        while self.pack_step() {}
    }

    /// Ends the run: no sample is taken after this; the result and end frames follow once the
    /// end-of-run analysis is done ([`App::analyse_step`], a bounded part of it per poll).
    fn end_run<H: Hardware>(&mut self, hw: &mut H, reason: EndReason) {
        if self.state != RigState::Running || self.ending.is_some() {
            return;
        }
        if let Some(blk) = self.builder.as_mut().and_then(BlockBuilder::flush) {
            self.store_block(hw, blk);
        }
        hw.adc_stop();
        let (blocks, samples) = self
            .builder
            .as_ref()
            .map_or((0, 0), |b| (b.blocks(), b.samples()));
        // The result and end frames wait for the last blocks to be packed and, in an analysed
        // run, for the fit: both spread over the next polls.
        let job = self
            .pipeline
            .as_ref()
            .filter(|_| self.pipeline_ready)
            .map(|p| p.start_finish(self.run_id));
        self.ending = Some(Ending {
            job,
            reason,
            blocks,
            samples,
        });
        info!("run {} over", self.run_id);
    }

    /// Advances the end-of-run analysis, if one is pending, by a bounded number of rows; once it
    /// is done and the last block is stored, stores the result and end frames.
    fn analyse_step(&mut self) {
        if !self.packing.is_empty() {
            return;
        }
        let rate = self.config.map_or(1, |c| c.sample_rate_hz);
        let Some(e) = &mut self.ending else { return };
        let result = match (self.pipeline.as_ref(), &mut e.job) {
            (Some(p), Some(job)) => p.finish_step(job, self.cfg.finish_rows_per_poll),
            _ => Some(unanalysed(self.run_id, e.samples, rate)),
        };
        let Some(result) = result else { return };
        if let Some(e) = self.ending.take() {
            self.complete_run(result, e.reason, e.blocks, e.samples);
        }
    }

    /// Stores the result and end frames of the run; it is finished.
    fn complete_run(
        &mut self,
        mut result: OnboardResult,
        reason: EndReason,
        blocks: u32,
        samples: u32,
    ) {
        if reason == EndReason::Aborted {
            result.verdict = Verdict::Aborted;
        }
        self.finish_packing();
        let seq = self.next_seq();
        if let Ok(frame) = self
            .encoder
            .encode(seq, &DeviceMsg::Result(result), &mut self.out)
        {
            self.store.set_result(frame);
        }
        let end = RunEnd {
            run_id: self.run_id,
            blocks,
            samples,
            overruns: self.run_overruns,
            reason,
        };
        let seq = self.next_seq();
        if let Ok(frame) = self
            .encoder
            .encode(seq, &DeviceMsg::RunEnded(end), &mut self.out)
        {
            self.store.set_end(frame);
        }
        self.ecr.set_hold(false);
        self.state = RigState::Finished;
        info!("run {} ended", self.run_id);
    }

    /// Sends run frames from the store while the link takes them: first the blocks a
    /// [`HostMsg::PullBlocks`] asked for, then the stream (live, or a [`HostMsg::Pull`]). At most
    /// `frames` records are looked at per call; every frame is sent as stored, so this is copying
    /// only. Returns how many frames the link took.
    fn pump<H: Hardware>(&mut self, hw: &mut H, frames: u8) -> u8 {
        let mut sent = 0;
        for _ in 0..frames {
            if let Some((k, end)) = self.range {
                if k >= end || k >= self.store.blocks() {
                    self.range = None;
                    continue;
                }
                let Some(pos) = self.store.block_pos(k) else {
                    self.range = None;
                    continue;
                };
                match self.store.read(hw, pos, &mut self.out) {
                    Read::Frame { len, .. } => {
                        if !hw.send_frame(&self.out[..len]) {
                            return sent;
                        }
                        sent += 1;
                        self.range = Some((k + 1, end));
                    }
                    Read::Busy => return sent,
                    Read::Lost { .. } | Read::End => self.range = Some((k + 1, end)),
                }
                continue;
            }
            let Some(want) = self.want else { return sent };
            let (len, next) = match want {
                Want::Header { from_block } => {
                    let Some(h) = self.store.header() else {
                        self.want = None;
                        return sent;
                    };
                    self.out[..h.len()].copy_from_slice(h);
                    (h.len(), Some(Want::Blocks(from_block)))
                }
                Want::Blocks(k) => {
                    match self.store.start_of_block(hw, k) {
                        Some(pos) => self.want = Some(Want::From(pos)),
                        None => return sent,
                    }
                    continue;
                }
                Want::From(pos) => match self.store.read(hw, pos, &mut self.out) {
                    Read::Frame { len, next } => (len, Some(Want::From(next))),
                    Read::Busy => return sent,
                    Read::Lost { next } => {
                        self.want = Some(Want::From(next));
                        continue;
                    }
                    Read::End => {
                        if self.store.result().is_none() {
                            // More may come (a run in progress).
                            return sent;
                        }
                        self.want = Some(Want::Result);
                        continue;
                    }
                },
                Want::Result => {
                    let Some(r) = self.store.result() else {
                        return sent;
                    };
                    self.out[..r.len()].copy_from_slice(r);
                    (r.len(), Some(Want::End))
                }
                Want::End => {
                    let Some(e) = self.store.end() else {
                        return sent;
                    };
                    self.out[..e.len()].copy_from_slice(e);
                    (e.len(), None)
                }
            };
            if !hw.send_frame(&self.out[..len]) {
                return sent;
            }
            sent += 1;
            self.want = next;
        }
        sent
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
#[path = "app_tests.rs"]
mod tests;
