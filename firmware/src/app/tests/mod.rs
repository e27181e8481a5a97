//! Host tests of the application through the hardware traits, with a small kinematic rig.

use super::*;
use crate::hal::*;
use crate::runstore::memflash::MemFlash;
use crate::runstore::{FlashState, MAX_RUN_BLOCKS};
use crate::wire::frame::decode_one;

fn encode_vec(seq: u32, msg: &HostMsg) -> Result<Vec<u8>, crate::wire::EncodeError> {
    let mut out = vec![0u8; MAX_FRAME];
    let n = Encoder::new().encode(seq, msg, &mut out)?.len();
    out.truncate(n);
    Ok(out)
}
use crate::wire::{ChannelSet, Field, HeaterFault, HeaterSetpoint};
use proptest::prelude::*;

/// The run's end frame among the messages, if it came.
fn run_end<M: core::borrow::Borrow<DeviceMsg>>(msgs: &[M]) -> Option<RunEnd> {
    msgs.iter().find_map(|m| match m.borrow() {
        DeviceMsg::RunEnded(e) => Some(*e),
        _ => None,
    })
}

/// Block indices of the sample frames among the messages, in order.
fn block_indices<'a>(msgs: impl IntoIterator<Item = &'a DeviceMsg>) -> Vec<u32> {
    msgs.into_iter()
        .filter_map(|m| match m {
            DeviceMsg::Samples(s) => Some(s.block),
            DeviceMsg::Packed(p) => Some(p.block),
            _ => None,
        })
        .collect()
}

/// The sample blocks among the messages (packed ones unpacked), in order.
fn sample_blocks<'a>(msgs: impl IntoIterator<Item = &'a DeviceMsg>) -> Vec<SampleBlock> {
    msgs.into_iter()
        .filter_map(|m| match m {
            DeviceMsg::Samples(s) => Some(s.clone()),
            DeviceMsg::Packed(p) => Some(p.unpack().expect("the rig packs blocks that unpack")),
            _ => None,
        })
        .collect()
}

fn is_block(m: &DeviceMsg) -> bool {
    matches!(m, DeviceMsg::Samples(_) | DeviceMsg::Packed(_))
}

/// The run's on-board result among the messages, if it came.
fn onboard_result<M: core::borrow::Borrow<DeviceMsg>>(msgs: &[M]) -> Option<OnboardResult> {
    msgs.iter().find_map(|m| match m.borrow() {
        DeviceMsg::Result(r) => Some(*r),
        _ => None,
    })
}

/// What the mock's ECR output reads while its amplifier settles (no contact reads exactly this).
const SETTLING_V: f32 = 1.2345;

/// A rig whose pin, once released, oscillates at 26 Hz with an amplitude decaying linearly to rest
/// (Coulomb-like) in `stop_s`. The ADC converts on demand up to the time set by the test.
struct Mock {
    now_us: u64,
    cal: [crate::wire::ChannelCal; CHANNELS],
    drives: Vec<(u64, MagnetDrive)>,
    released_at: Option<u64>,
    tc: Option<crate::thermocouple::Registers>,
    heater_duty: f32,
    ecr_r: f32,
    ecr_range: u8,
    ecr_source: f32,
    /// Model the transimpedance amplifier's settling: for `SETTLE_US` of the range after a change
    /// of range or source, the output reads [`SETTLING_V`].
    ecr_settles: bool,
    ecr_changed_us: u64,
    adc_ok: bool,
    adc: crate::acquisition::ConverterModel,
    button: bool,
    connected: bool,
    out: Vec<u8>,
    lamps: Lamps,
    stop_s: f64,
    flash: MemFlash<Vec<u8>>,
    /// The range-select pin PG1 reads low whatever is driven (a stuck output).
    range_bit1_stuck_low: bool,
    /// The LSI path: `None` no timer input on the LSI; `Some(f)` an LSI at 32 kHz read by a
    /// 25 MHz timer whose HSE runs at `f` times its nominal.
    lsi_hse_ratio: Option<f64>,
    /// The LSI timer is running (between `lsi_start` and `lsi_stop`).
    lsi_running: bool,
}

impl Mock {
    fn new() -> Self {
        Mock {
            now_us: 0,
            cal: Configure::real_rig(0.3).calibration,
            drives: Vec::new(),
            released_at: None,
            tc: Some(reg(25.0)),
            heater_duty: 0.0,
            ecr_r: 1e7,
            ecr_range: 0,
            ecr_source: 0.0,
            ecr_settles: false,
            ecr_changed_us: 0,
            adc_ok: true,
            adc: crate::acquisition::ConverterModel::new(200_000_000),
            button: false,
            connected: true,
            out: Vec::new(),
            lamps: Lamps::default(),
            stop_s: 0.5,
            flash: MemFlash::new(vec![0; 1 << 20], FlashGeometry::H743_BANK2).with_h743_timing(),
            range_bit1_stuck_low: false,
            lsi_hse_ratio: Some(1.0),
            lsi_running: false,
        }
    }

    fn x_v(&self, t_us: f64) -> (f64, f64) {
        let x0 = 667e-6;
        let Some(r) = self.released_at else {
            return (x0, 0.0);
        };
        let t = ((t_us - r as f64) * 1e-6).max(0.0);
        let w = 2.0 * core::f64::consts::PI * 26.0;
        let a = (x0 * (1.0 - t / self.stop_s)).max(0.0);
        (a * (w * t).cos(), -a * w * (w * t).sin())
    }

    /// Converts every sample due up to `now_us` into the ring (and lets the flash work that long).
    fn convert(&mut self) {
        self.flash.advance(self.now_us);
        while let Some(t) = self.adc.due(self.now_us) {
            let (x, v) = self.x_v(t as f64);
            let s = [
                self.cal[0].to_count(x as f32),
                self.cal[1].to_count(v as f32),
                self.cal[2].to_count(0.01),
                self.cal[3].to_count(self.ecr_at(t)),
            ];
            self.adc.convert(&s);
        }
    }

    /// Asserts that every sample of `blk` holds the displacement and velocity of its own instant:
    /// run sample `i` is stream sample `base + i`, converted at that trigger's time.
    fn check_block(&self, blk: &SampleBlock, base: u64) {
        let (px, pv) = (
            blk.channels.position(Channel::Displacement).unwrap(),
            blk.channels.position(Channel::Velocity).unwrap(),
        );
        for i in 0..blk.samples() {
            let k = base + blk.first_sample as u64 + i as u64;
            let (x, v) = self.x_v(self.adc.trigger_time_us(k) as f64);
            let s = blk.sample(i).unwrap();
            assert_eq!(
                (s[px], s[pv]),
                (
                    self.cal[0].to_count(x as f32),
                    self.cal[1].to_count(v as f32)
                ),
                "block {} sample {i} (stream {k})",
                blk.block
            );
        }
    }

    /// The ECR output converted at device time `t_us`.
    fn ecr_at(&self, t_us: u64) -> f32 {
        let settle = crate::ecr::SETTLE_US[self.ecr_range as usize] as u64;
        if self.ecr_settles && t_us < self.ecr_changed_us + settle {
            SETTLING_V
        } else {
            self.ecr_out()
        }
    }

    fn ecr_out(&self) -> f32 {
        (self.ecr_source / self.ecr_r * crate::ecr::GAIN_V_PER_A[self.ecr_range as usize])
            .min(crate::ecr::FULL_SCALE_V)
    }

    fn magnet(&self) -> MagnetDrive {
        self.drives.last().map_or(MagnetDrive::Off, |d| d.1)
    }
}

impl Magnet for Mock {
    fn magnet_drive(&mut self, d: MagnetDrive) {
        if self.released_at.is_none()
            && !matches!(d, MagnetDrive::Hold { .. })
            && matches!(self.magnet(), MagnetDrive::Hold { .. })
        {
            self.released_at = Some(self.now_us);
        }
        self.drives.push((self.now_us, d));
    }
}
impl Thermocouple for Mock {
    fn read_thermocouple(&mut self) -> Option<ConverterRead> {
        self.tc.map(|regs| ConverterRead {
            regs,
            age_us: 1_000,
        })
    }
}

/// The converter's registers for a good reading at `t` °C.
fn reg(t: f32) -> crate::thermocouple::Registers {
    crate::thermocouple::encode(t, 25.0, 0)
}

/// The converter's registers with fault status bits `status` set.
fn bad(status: u8) -> crate::thermocouple::Registers {
    crate::thermocouple::encode(25.0, 25.0, status)
}
impl HeaterOutput for Mock {
    fn set_heater_duty(&mut self, d: f32) {
        self.heater_duty = d;
    }
}
impl EcrFrontEnd for Mock {
    fn set_ecr_source(&mut self, v: f32) {
        if v != self.ecr_source {
            self.ecr_changed_us = self.now_us;
        }
        self.ecr_source = v;
    }
    fn set_ecr_range(&mut self, r: u8) {
        if r != self.ecr_range {
            self.ecr_changed_us = self.now_us;
        }
        self.ecr_range = r;
    }
    fn read_ecr_output(&mut self) -> f32 {
        self.ecr_out()
    }
}
impl SampleSource for Mock {
    fn adc_clock(&self, rate_hz: u32) -> Option<SampleClock> {
        self.adc.clock_for(rate_hz)
    }
    fn adc_start(&mut self, rate_hz: u32) -> Option<SampleClock> {
        if !self.adc_ok {
            return None;
        }
        self.adc.start(rate_hz, self.now_us)
    }
    fn adc_stop(&mut self) {
        self.adc.stop();
    }
    fn adc_running(&self) -> bool {
        self.adc.is_running()
    }
    fn adc_next_index(&mut self) -> u64 {
        self.convert();
        self.adc.next_index()
    }
    fn adc_read(&mut self, out: &mut [AnalogSample]) -> Batch {
        self.convert();
        self.adc.read(out)
    }
    fn force_lowpass(&self) -> crate::wire::LowPass {
        crate::wire::LowPass::butterworth(2, 300.0)
    }
}
impl Button for Mock {
    fn button_pressed(&mut self) -> bool {
        self.button
    }
}
impl Led for Mock {
    fn set_lamps(&mut self, l: Lamps) {
        self.lamps = l;
    }
}
impl OutputSense for Mock {
    fn sense_outputs(&mut self) -> SensedOutputs {
        let magnet = match self.magnet() {
            MagnetDrive::Off => 0,
            MagnetDrive::Hold { .. } => 1,
            MagnetDrive::Reverse { .. } => 2,
        };
        let range = if self.range_bit1_stuck_low {
            self.ecr_range & !2
        } else {
            self.ecr_range
        };
        SensedOutputs {
            heater_pin: Some(self.heater_duty > 0.0),
            magnet_pins: Some(magnet),
            ecr_dac_code: Some(crate::ecr::source_dac_code(self.ecr_source)),
            ecr_range_pins: Some(range),
            lamp_pins: Some(
                self.lamps.green as u8
                    | (self.lamps.amber as u8) << 1
                    | (self.lamps.red as u8) << 2,
            ),
        }
    }
}
impl ClockCheck for Mock {
    fn lsi_start(&mut self) -> Option<LsiTimer> {
        self.lsi_hse_ratio?;
        self.lsi_running = true;
        Some(LsiTimer {
            timer_hz: 25_000_000,
            periods_per_capture: 8,
        })
    }
    fn lsi_ready(&mut self) -> bool {
        self.lsi_running
    }
    fn lsi_interval(&mut self) -> LsiInterval {
        match self.lsi_hse_ratio {
            Some(f) if self.lsi_running => {
                LsiInterval::Ticks((25e6 * f * 8.0 / 32_000.0).round() as u32)
            }
            _ => LsiInterval::Timeout,
        }
    }
    fn lsi_stop(&mut self) {
        self.lsi_running = false;
    }
}
impl Link for Mock {
    fn send_frame(&mut self, f: &[u8]) -> bool {
        if self.connected {
            self.out.extend_from_slice(f);
        }
        self.connected
    }
}

impl RunFlash for Mock {
    fn flash_geometry(&self) -> FlashGeometry {
        self.flash.flash_geometry()
    }
    fn flash_busy(&mut self) -> bool {
        self.flash.flash_busy()
    }
    fn flash_erase(&mut self, sector: u32) -> bool {
        self.flash.flash_erase(sector)
    }
    fn flash_program(&mut self, offset: u32, data: &[u8]) -> bool {
        self.flash.flash_program(offset, data)
    }
    fn flash_read(&mut self, offset: u32, out: &mut [u8]) -> bool {
        self.flash.flash_read(offset, out)
    }
    fn flash_take_error(&mut self) -> bool {
        self.flash.flash_take_error()
    }
}

struct Bench {
    app: App<'static>,
    hw: Mock,
    seq: u32,
}

/// A run store with `ram` bytes of RAM (in two buffers, as on the board).
fn store(ram: usize) -> RunStore<'static> {
    let a: &'static mut [u8] = Box::leak(vec![0u8; ram / 2].into_boxed_slice());
    let b: &'static mut [u8] = Box::leak(vec![0u8; ram - ram / 2].into_boxed_slice());
    let index = Box::leak(vec![0u32; MAX_RUN_BLOCKS].into_boxed_slice());
    RunStore::new([a, b], index)
}

impl Bench {
    fn new() -> Self {
        Self::with_store(256 * 1024)
    }

    fn with_store(ram: usize) -> Self {
        let mut b = Bench {
            app: App::new(AppConfig::new(42), store(ram)),
            hw: Mock::new(),
            seq: 100,
        };
        b.poll();
        // Past the thermocouple's start-up grace: a rig that has been on for a second.
        b.run_for(crate::wire::limits::TC_STARTUP_GRACE_MS as u64);
        b.take();
        b
    }

    fn poll(&mut self) {
        self.hw.convert();
        let now = self.hw.now_us;
        self.app.poll(&mut self.hw, now);
    }

    /// Advances time in polls of the application's period (500 µs).
    fn run_for(&mut self, ms: u64) {
        let period = self.app.cfg.poll_period_us as u64;
        for _ in 0..ms * 1000 / period {
            self.hw.now_us += period;
            self.poll();
        }
    }

    fn send(&mut self, msg: HostMsg) -> u32 {
        self.seq += 1;
        let bytes = encode_vec(self.seq, &msg).unwrap();
        let now = self.hw.now_us;
        self.app.on_bytes(&mut self.hw, &bytes, now);
        self.seq
    }

    /// Frames sent so far (raw bytes and decoded), and clears the output.
    fn take(&mut self) -> Vec<(Vec<u8>, Frame<DeviceMsg>)> {
        let out = core::mem::take(&mut self.hw.out);
        out.split_inclusive(|&b| b == 0)
            .map(|f| {
                (
                    f.to_vec(),
                    decode_one::<DeviceMsg>(f).expect("every frame the rig sends decodes"),
                )
            })
            .collect()
    }

    fn msgs(&mut self) -> Vec<DeviceMsg> {
        self.take().into_iter().map(|f| f.1.msg).collect()
    }

    /// Sends a command and returns the answer to it (Ack or Error) and everything else sent.
    fn command(&mut self, msg: HostMsg) -> (Result<(), ErrorCode>, Vec<DeviceMsg>) {
        let seq = self.send(msg);
        let msgs = self.msgs();
        let mut answer = None;
        for m in &msgs {
            match m {
                DeviceMsg::Ack { seq: s } if *s == seq => answer = Some(Ok(())),
                DeviceMsg::Error(DeviceError {
                    code,
                    about_seq: Some(s),
                }) if *s == seq => answer = Some(Err(*code)),
                _ => {}
            }
        }
        (answer.expect("every command is answered"), msgs)
    }

    fn ready(&mut self) {
        let mut c = Configure::real_rig(0.3);
        c.max_duration_s = 2.0;
        assert_eq!(self.command(HostMsg::Configure(c)).0, Ok(()));
        assert_eq!(self.command(HostMsg::Arm).0, Ok(()));
        self.run_for(50);
    }
}

/// Time for a thermocouple fault to latch: that many bad reads, one per 100 ms, plus a poll.
const TC_FAULT_MS: u64 = 100 * crate::wire::limits::TC_BAD_READS as u64 + 50;

fn faults(msgs: &[DeviceMsg]) -> Vec<FaultReason> {
    msgs.iter()
        .filter_map(|m| match m {
            DeviceMsg::Fault(f) => Some(f.reason),
            _ => None,
        })
        .collect()
}

fn errors(msgs: &[DeviceMsg]) -> Vec<ErrorCode> {
    msgs.iter()
        .filter_map(|m| match m {
            DeviceMsg::Error(e) => Some(e.code),
            _ => None,
        })
        .collect()
}

/// Runs to the end (the run's end frame sent: frames follow the state by a few polls) and
/// returns all frames sent.
fn full_run(b: &mut Bench) -> Vec<(Vec<u8>, Frame<DeviceMsg>)> {
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    let mut frames = b.take();
    for _ in 0..3000 {
        b.run_for(1);
        frames.extend(b.take());
        if frames
            .iter()
            .any(|f| matches!(f.1.msg, DeviceMsg::RunEnded(_)))
        {
            break;
        }
    }
    frames
}

/// Runs `b` until the flash holds everything of the finished run.
fn settle_flash(b: &mut Bench) {
    for _ in 0..20_000 {
        if b.app.store().flash_state() == FlashState::Done {
            return;
        }
        b.run_for(1);
    }
    panic!("flash copy not done: {:?}", b.app.store().flash_state());
}

mod commands;
mod failsafe;
mod run;
mod selftest;
mod store;
