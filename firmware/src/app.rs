//! The rig's application: one state machine that the technician and the host drive.
//!
//! It is a plain value polled with the time ([`App::poll`]) and fed the bytes the host sends
//! ([`App::on_bytes`]); it drives the hardware only through [`crate::hal::Hardware`]. The board runs it
//! in an embassy task; the host's virtual rig runs the very same code against the simulator.
//!
//! ```text
//!   Idle ──Configure──▶ Configured ──Arm──▶ Armed ──Release / button──▶ Running ──▶ Finished
//!                          ▲   ◀──Disarm / hold-time limit──┘                 │ stop, max duration,
//!                          └──────────────────Configure / Arm ◀───────────────┘ abort, fault, overrun
//! ```
//!
//! * **Arm** energises the magnet (the pin is held at x0) and starts the converter; samples taken while
//!   held calibrate the zeros of the on-board analysis.
//! * **Release** is refused unless armed, the magnet holds, the converter runs and the heater is
//!   healthy; then a short reverse pulse frees the pin and the run starts.
//! * During the run every sample goes to a block and to the analysis; each block is stored in the
//!   [`RunStore`] and sent from there, so the live stream and a later [`HostMsg::Pull`] are the same
//!   frames (same bytes, same sequence numbers).
//! * The run ends when the analysis sees the pin at rest (or its amplitude in the noise), at the
//!   maximum duration, on Abort, on a heater fault, or on an acquisition overrun (reported, and the
//!   run is cut there: a gap is never stitched over). Then come the result and the end frames.
//!
//! Every command is answered (Ack or Error with its sequence number); a frame that does not decode
//! is answered by `Error { Malformed }`. Nothing a host sends can make it panic.

use crate::acquisition::{select, BlockBuilder};
use crate::analysis::{ConfigError, Finish, Phase, Pipeline, StopReason};
use crate::ecr::Ecr;
use crate::hal::{AnalogSample, Hardware, Lamps, MagnetDrive, ANALOG_CHANNELS};
use crate::heater::{Heater, HeaterConfig};
use crate::release::{check_interlocks, Debouncer, MagnetEvent, Release, ReleaseConfig};
use crate::runstore::{Item, RunStore};
use crate::wire::frame::MAX_FRAME;
use crate::wire::{
    Channel, Configure, Decoder, DeviceError, DeviceInfo, DeviceMsg, Encoder, EndReason,
    EnvelopeShape, ErrorCode, Estimate, Field, Frame, HostMsg, Interlock, OnboardResult, RigState,
    RunEnd, RunHeader, SampleBlock, Status, Verdict, CHANNELS, PROTOCOL_VERSION,
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
    /// Steps of run-frame sending per poll; a frame takes three (taken from the store and
    /// serialised; its CRC; byte-stuffed and offered to the link), because framing a full
    /// five-channel block at once is the largest piece of work a poll could do (13k instructions
    /// on the M7). One step per millisecond poll is 333 frames/s, more than the 312 blocks/s of a
    /// five-channel run at 20 kS/s.
    pub frames_per_poll: u8,
    /// Rows of the end-of-run regressions computed per poll (the fit is spread over polls; a row
    /// is up to ~500 instructions on the M7, so 16 rows stay under 9k). The result of a run of
    /// n half-cycles comes about 35 n / 16 polls after the pin stopped: 0.04 s for 20 half-cycles,
    /// 4.5 s for the longest run the analysis takes (2048).
    pub finish_rows_per_poll: u32,
    /// How often the application is polled, µs (the board's ticker). With the sample rate it sets
    /// how many samples one poll takes at most: twice what arrives between two polls (at least
    /// 16), so that a backlog (the application held up) is caught up over several polls instead
    /// of in one long one.
    pub poll_period_us: u32,
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
            frames_per_poll: 1,
            finish_rows_per_poll: 16,
            poll_period_us: 1_000,
        }
    }
}

/// How far the run frame being sent is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum RunFrame {
    /// Serialised in `run_encoder` (this many bytes).
    Serialised(usize),
    /// Its CRC appended (this many bytes now).
    Prepared(usize),
    /// Byte-stuffed in `run_out` (this many bytes; 0: could not be encoded, skipped).
    Stuffed(usize),
}

/// What the run-frame sender wants next.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Want {
    Header {
        from_block: u32,
    },
    Blocks(u32),
    End,
    /// Blocks `.0 .. .1` only ([`HostMsg::PullBlocks`]).
    Range(u32, u32),
}

/// A run whose samples are all in, waiting for its end-of-run analysis (spread over polls): the
/// run is still `Running` until its result and end frames exist.
struct Ending {
    job: Finish,
    reason: EndReason,
    blocks: u32,
    samples: u32,
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
    /// (building one by value at run time puts its 43 KiB on the stack); `pipeline_ready` says
    /// whether it is configured for the current run (an unloaded run is not analysed).
    pipeline: Option<Pipeline>,
    pipeline_ready: bool,
    ending: Option<Ending>,
    builder: Option<BlockBuilder>,
    decoder: Decoder<HostMsg>,
    encoder: Encoder,
    out: [u8; MAX_FRAME],
    /// The run frame in the making (its own encoder: acknowledgements may be sent between its two
    /// steps) and, once stuffed, in `run_out`: a frame the link refuses waits there and is offered
    /// again as is.
    run_encoder: Encoder,
    run_out: [u8; MAX_FRAME],
    run_frame: Option<(Item, RunFrame)>,
    seq: u32,
    run_id: u32,
    run_start_us: u64,
    run_overruns: u32,
    want: Option<Want>,
    last_heater_us: Option<u64>,
    last_ecr_us: Option<u64>,
    lost_seen: u32,
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
            builder: None,
            decoder: Decoder::new(),
            encoder: Encoder::new(),
            out: [0; MAX_FRAME],
            run_encoder: Encoder::new(),
            run_out: [0; MAX_FRAME],
            run_frame: None,
            seq: 0,
            run_id: 0,
            run_start_us: 0,
            run_overruns: 0,
            want: None,
            last_heater_us: None,
            last_ecr_us: None,
            lost_seen: 0,
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

    /// Feeds bytes received from the host; handles every complete frame.
    pub fn on_bytes<H: Hardware>(&mut self, hw: &mut H, bytes: &[u8], now_us: u64) {
        self.now_us = self.now_us.max(now_us);
        for &b in bytes {
            match self.decoder.push(b) {
                Some(Ok(frame)) => self.handle(hw, frame),
                Some(Err(_)) => self.error(hw, ErrorCode::Malformed, None),
                None => {}
            }
        }
        self.pump(hw);
    }

    /// Runs everything that depends on time: magnet, heater, ECR, button, acquisition, sending.
    pub fn poll<H: Hardware>(&mut self, hw: &mut H, now_us: u64) {
        self.now_us = self.now_us.max(now_us);
        let now = self.now_us;
        if !self.started {
            self.started = true;
            hw.magnet_drive(MagnetDrive::Off);
            hw.set_heater_duty(0.0);
            self.ecr.init(hw);
        }
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
            self.ecr.update(v, hw);
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
        let behind = self.drain(hw, self.samples_per_poll());
        self.analyse_step();
        // While catching up on samples, frames wait (in the store) for a poll with room.
        if !behind {
            self.pump(hw);
        }
        let lamps = self.lamps(now);
        hw.set_lamps(lamps);
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
                    self.want = Some(Want::Range(first, first.saturating_add(count)));
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
        let _ = hw.adc_start(cfg.sample_rate_hz);
        self.lost_seen = hw.adc_lost();
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
        check_interlocks(
            self.state == RigState::Armed,
            self.release.is_holding(),
            hw.adc_running(),
            self.heater.healthy(),
        )
        .map_err(ErrorCode::Interlock)?;
        // Samples converted before this instant belong to the hold: all of them, however many.
        self.drain(hw, usize::MAX);
        if self.state != RigState::Armed {
            // An overrun seen while draining disarmed nothing, but be strict.
            return Err(ErrorCode::Interlock(Interlock::NotArmed));
        }
        let now = self.now_us;
        self.release.release(hw, now);
        if let Some(p) = self.pipeline.as_mut().filter(|_| self.pipeline_ready) {
            p.release();
        }
        self.run_id = self.run_id.wrapping_add(1).max(1);
        self.run_start_us = now;
        self.run_overruns = 0;
        self.builder = Some(BlockBuilder::new(
            self.run_id,
            cfg.channels,
            cfg.calibration[Channel::Temperature.index()],
        ));
        let header = RunHeader {
            run_id: self.run_id,
            config: cfg,
            temp_c: self.heater.temp_c(),
            t_us: now,
        };
        let seq = self.next_seq();
        self.store.begin(seq, header);
        self.run_frame = None;
        self.want = Some(Want::Header { from_block: 0 });
        self.state = RigState::Running;
        info!("released: run {}", self.run_id);
        Ok(())
    }

    /// Most samples one poll takes (see [`AppConfig::poll_period_us`]).
    fn samples_per_poll(&self) -> usize {
        let rate = self.config.map_or(0, |c| c.sample_rate_hz) as u64;
        let per_poll = rate * self.cfg.poll_period_us as u64 / 1_000_000;
        (2 * per_poll).max(16) as usize
    }

    /// Moves converted samples to the hold capture or to the run, at most `limit` of them; true
    /// when it stopped at the limit (samples are still waiting).
    fn drain<H: Hardware>(&mut self, hw: &mut H, limit: usize) -> bool {
        let mut buf = [[0u16; ANALOG_CHANNELS]; 32];
        let mut taken = 0usize;
        loop {
            if !matches!(self.state, RigState::Armed | RigState::Running) || self.ending.is_some() {
                return false;
            }
            if taken >= limit {
                return true;
            }
            // An overrun is checked before each read: the samples still in the ring may straddle the
            // gap, so a run ends at the last sample read before the loss was seen.
            let lost = hw.adc_lost();
            if lost != self.lost_seen {
                let delta = lost.wrapping_sub(self.lost_seen);
                self.lost_seen = lost;
                self.overruns = self.overruns.saturating_add(delta);
                info!("overrun: {} samples lost", delta);
                self.error(
                    hw,
                    ErrorCode::Overrun {
                        lost_samples: delta,
                    },
                    None,
                );
                if self.state == RigState::Running {
                    self.run_overruns = self.run_overruns.saturating_add(delta);
                    self.end_run(hw, EndReason::Overrun);
                    return false;
                }
            }
            let want = buf.len().min(limit - taken);
            let n = hw.adc_read(&mut buf[..want]);
            if n == 0 {
                return false;
            }
            taken += n;
            for s in buf.iter().take(n) {
                if self.take_sample(hw, s) {
                    return false;
                }
            }
        }
    }

    /// One sample; returns true when it ended the run.
    fn take_sample<H: Hardware>(&mut self, hw: &mut H, s: &AnalogSample) -> bool {
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
                let Some(b) = &mut self.builder else {
                    return false;
                };
                let mut sel = [0u16; CHANNELS];
                let n = b.select(s, temp, &mut sel);
                // The time is only read for a block's first sample (a 64-bit division per sample
                // is a software routine on the M7).
                let t_us = if b.starts_block() {
                    let rate = cfg.sample_rate_hz.max(1) as u64;
                    self.run_start_us + b.samples() as u64 * 1_000_000 / rate
                } else {
                    0
                };
                let block = b.push_selected(&sel[..n], temp, t_us);
                let samples = b.samples();
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
                    _ if samples >= max_samples => Some(EndReason::MaxDuration),
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

    /// Completes a block's ECR and temperature fields (the ECR range is the one used during the
    /// block; the reading at its end sets the next one) and stores it.
    fn store_block<H: Hardware>(&mut self, hw: &mut H, mut blk: SampleBlock) {
        blk.ecr_range = self.ecr.range();
        let v = hw.read_ecr_output();
        blk.log10_ecr_ohm = self.ecr.update(v, hw);
        blk.temp_c = self.heater.temp_c();
        let seq = self.next_seq();
        self.store.push_block(seq, &blk);
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
        let job = match self.pipeline.as_ref().filter(|_| self.pipeline_ready) {
            Some(p) => p.start_finish(self.run_id),
            None => {
                let result = unanalysed(
                    self.run_id,
                    samples,
                    self.config.map_or(1, |c| c.sample_rate_hz),
                );
                self.complete_run(result, reason, blocks, samples);
                return;
            }
        };
        self.ending = Some(Ending {
            job,
            reason,
            blocks,
            samples,
        });
        info!("run {} over: analysing", self.run_id);
    }

    /// Advances the end-of-run analysis, if one is pending, by a bounded number of rows.
    fn analyse_step(&mut self) {
        let Some(e) = &mut self.ending else { return };
        let result = match self.pipeline.as_ref().filter(|_| self.pipeline_ready) {
            Some(p) => p.finish_step(&mut e.job, self.cfg.finish_rows_per_poll),
            None => Some(unanalysed(self.run_id, e.samples, 1)),
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
        let seq = self.next_seq();
        self.store.set_result(seq, result);
        let end = RunEnd {
            run_id: self.run_id,
            blocks,
            samples,
            overruns: self.run_overruns,
            reason,
        };
        let seq = self.next_seq();
        self.store.set_end(seq, end);
        self.state = RigState::Finished;
        info!("run {} ended", self.run_id);
    }

    /// Sends run frames from the store while the link takes them.
    fn pump<H: Hardware>(&mut self, hw: &mut H) {
        for _ in 0..self.cfg.frames_per_poll {
            let Some(want) = self.want else { return };
            let item = match want {
                Want::Header { .. } => Some(Item::Header),
                Want::Blocks(k) => self.store.first_from(k),
                Want::End => self.store.is_finished().then_some(Item::End),
                Want::Range(k, end) => {
                    let k = k.max(self.store.oldest_block());
                    (k < end && k < self.store.blocks()).then_some(Item::Block(k))
                }
            };
            let Some(item) = item else { return };
            // Step one: take the frame from the store and serialise it. Step two: its CRC. Step
            // three: byte-stuff it and offer it to the link (again each poll while the link refuses
            // it, without framing it again).
            let len = match self.run_frame {
                Some((it, RunFrame::Stuffed(len))) if it == item => len,
                Some((it, RunFrame::Serialised(n))) if it == item => {
                    let step = match self.run_encoder.seal(n) {
                        Ok(raw) => RunFrame::Prepared(raw),
                        Err(_) => RunFrame::Stuffed(0),
                    };
                    self.run_frame = Some((item, step));
                    continue;
                }
                Some((it, RunFrame::Prepared(raw))) if it == item => {
                    let len = self
                        .run_encoder
                        .stuff(raw, &mut self.run_out)
                        .map_or(0, |b| b.len());
                    self.run_frame = Some((item, RunFrame::Stuffed(len)));
                    len
                }
                _ => {
                    // Blocks are serialised from the store's counts, not rebuilt first.
                    let enc = &mut self.run_encoder;
                    let serialised = match item {
                        Item::Block(k) => self
                            .store
                            .samples_ref(k)
                            .map(|(seq, view)| enc.serialise(seq, &view)),
                        other => self
                            .store
                            .frame(other)
                            .map(|(seq, msg)| enc.serialise(seq, &msg)),
                    };
                    let Some(serialised) = serialised else {
                        self.want = None;
                        return;
                    };
                    // An encoding error cannot happen for stored frames; skip rather than stall.
                    let step = match serialised {
                        Ok(n) => RunFrame::Serialised(n),
                        Err(_) => RunFrame::Stuffed(0),
                    };
                    self.run_frame = Some((item, step));
                    continue;
                }
            };
            if len > 0 && !hw.send_frame(&self.run_out[..len]) {
                return;
            }
            self.run_frame = None;
            self.want = match (want, item) {
                (Want::Range(_, end), Item::Block(k)) => Some(Want::Range(k + 1, end)),
                (Want::Header { from_block }, Item::Header) => Some(Want::Blocks(from_block)),
                (_, Item::Block(k)) => Some(Want::Blocks(k + 1)),
                (_, Item::Result) => Some(Want::End),
                _ => None,
            };
        }
    }
}

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
