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

#[test]
fn hello_is_answered_and_a_wrong_protocol_named() {
    let mut b = Bench::new();
    let (r, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    assert_eq!(r, Ok(()));
    assert!(matches!(
        msgs[0],
        DeviceMsg::Hello(DeviceInfo {
            protocol: PROTOCOL_VERSION,
            serial: 42,
            ..
        })
    ));
    let (r, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION + 1,
    });
    assert_eq!(
        r,
        Err(ErrorCode::ProtocolMismatch {
            device: PROTOCOL_VERSION
        })
    );
    assert!(matches!(msgs[0], DeviceMsg::Hello(_)));
}

#[test]
fn release_interlocks_in_order() {
    let mut b = Bench::new();
    assert_eq!(b.command(HostMsg::Release).0, Err(ErrorCode::NotConfigured));
    assert_eq!(b.command(HostMsg::Arm).0, Err(ErrorCode::NotConfigured));
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Ok(())
    );
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::NotArmed))
    );
    // A converter that does not start: armed, but no release.
    b.hw.adc_ok = false;
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::NotSampling))
    );
    assert_eq!(b.command(HostMsg::Disarm).0, Ok(()));
    b.hw.adc_ok = true;
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    // Heater unhealthy: thermocouple open.
    b.hw.tc = Some(bad(crate::thermocouple::sr::OPEN));
    b.run_for(TC_FAULT_MS);
    assert!(faults(&b.msgs()).contains(&FaultReason::Heater(HeaterFault::OpenThermocouple)));
    assert_eq!(b.app.state(), RigState::Fault);
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::HeaterUnhealthy))
    );
    assert!(b.hw.released_at.is_none(), "an interlock let the pin go");
    // Healthy again, cleared by HeaterOff: the release goes through.
    b.hw.tc = Some(reg(25.0));
    assert_eq!(b.command(HostMsg::HeaterOff).0, Ok(()));
    b.run_for(200);
    assert_eq!(b.app.state(), RigState::Armed);
    let (r, msgs) = b.command(HostMsg::Release);
    assert_eq!(r, Ok(()));
    assert_eq!(b.app.state(), RigState::Running);
    b.run_for(10);
    let msgs: Vec<_> = msgs.into_iter().chain(b.msgs()).collect();
    assert!(
        matches!(&msgs[..], [DeviceMsg::Ack { .. }, DeviceMsg::RunStarted(h), ..] if h.run_id == 1)
    );
    assert_eq!(b.command(HostMsg::Release).0, Err(ErrorCode::Busy));
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Err(ErrorCode::Busy)
    );
}

#[test]
fn release_is_hold_then_reverse_pulse_then_off() {
    let mut b = Bench::new();
    b.ready();
    let t_rel = b.hw.now_us;
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(20);
    let d: Vec<_> = b.hw.drives.iter().filter(|(t, _)| *t >= t_rel).collect();
    assert!(
        matches!(d[0], (t, MagnetDrive::Reverse { duty }) if *t == t_rel && *duty > 0.0),
        "{d:?}"
    );
    let off = d
        .iter()
        .find(|(_, m)| *m == MagnetDrive::Off)
        .expect("coil switched off after the pulse");
    let pulse = off.0 - t_rel;
    let cfg = ReleaseConfig::default();
    assert!(
        pulse >= cfg.reverse_us as u64 && pulse <= cfg.reverse_us as u64 + 1000,
        "pulse {pulse} µs"
    );
    assert!(!b.app.status().magnet_on);
}

#[test]
fn hold_time_limit_disarms_and_is_reported() {
    let mut b = Bench::new();
    b.app.cfg.release.hold_limit_us = 2_000_000;
    b.app.release = Release::new(b.app.cfg.release);
    b.ready();
    b.take();
    b.run_for(2_100);
    assert!(faults(&b.msgs()).contains(&FaultReason::MagnetHoldTime));
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(
        !b.hw.adc.is_running(),
        "sampling left running after the magnet was cut"
    );
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::NotArmed))
    );
    assert_eq!(b.app.state(), RigState::Configured);
    assert_eq!(
        b.app.run_id(),
        0,
        "no run may start from a coil cut by the hold-time limit"
    );
}

#[test]
fn button_releases_only_when_armed_and_is_debounced() {
    let mut b = Bench::new();
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Ok(())
    );
    b.hw.button = true;
    b.run_for(40);
    b.hw.button = false;
    b.run_for(40);
    let e = b.take();
    assert!(e.iter().any(|f| f.1.msg
        == DeviceMsg::Error(DeviceError {
            code: ErrorCode::Interlock(Interlock::NotArmed),
            about_seq: None
        })));
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    b.run_for(50);
    // A 5 ms glitch is not a press.
    b.hw.button = true;
    b.run_for(5);
    b.hw.button = false;
    b.run_for(30);
    assert_eq!(b.app.state(), RigState::Armed);
    b.hw.button = true;
    b.run_for(30);
    assert_eq!(b.app.state(), RigState::Running);
    assert!(b.hw.released_at.is_some());
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

#[test]
fn a_run_streams_contiguous_blocks_then_result_and_end() {
    let mut b = Bench::new();
    let frames = full_run(&mut b);
    assert_eq!(b.app.state(), RigState::Finished);
    let msgs: Vec<_> = frames.iter().map(|f| &f.1.msg).collect();
    let header = msgs
        .iter()
        .find_map(|m| {
            if let DeviceMsg::RunStarted(h) = m {
                Some(*h)
            } else {
                None
            }
        })
        .unwrap();
    let blocks = sample_blocks(msgs.iter().copied());
    let end = run_end(&msgs).unwrap();
    let result = onboard_result(&msgs).unwrap();
    assert_eq!(
        end.reason,
        EndReason::Stopped,
        "the pin stops after 0.5 s; the analysis must see it"
    );
    assert!(result.cycles >= 5, "{result:?}");
    assert!((result.frequency_hz - 26.0).abs() < 0.5, "{result:?}");
    let mut next_sample = 0;
    for (k, blk) in blocks.iter().enumerate() {
        assert!(blk.is_consistent());
        assert_eq!(
            (blk.run_id, blk.block, blk.first_sample),
            (header.run_id, k as u32, next_sample)
        );
        assert_eq!(blk.t_us, header.t_us + blk.first_sample as u64 * 100);
        // The autoranger starts cold at arming (least gain, low source): it climbs a range per block
        // and waits out each change's settling (20 ms on the highest range, three blocks), so
        // a dozen blocks go by before it reads.
        if k >= 14 {
            assert!(
                (blk.log10_ecr_ohm - 7.0).abs() < 0.01,
                "ECR of a 1e7 Ω contact read as {}",
                blk.log10_ecr_ohm
            );
            assert_eq!(
                blk.ecr_range, 3,
                "1e7 Ω at 2 mV: 0.2 nA, 3 % of full scale on the 5e8 V/A range"
            );
        }
        next_sample += blk.samples() as u32;
    }
    assert_eq!(
        (end.blocks as usize, end.samples),
        (blocks.len(), next_sample)
    );
    assert_eq!(end.overruns, 0);
    // Result and end close the run, in that order, after every block.
    let pos = |f: &dyn Fn(&DeviceMsg) -> bool| msgs.iter().position(|m| f(m)).unwrap();
    let last_block = msgs.iter().rposition(|m| is_block(m)).unwrap();
    assert!(last_block < pos(&|m| matches!(m, DeviceMsg::Result(_))));
    assert!(
        pos(&|m| matches!(m, DeviceMsg::Result(_))) < pos(&|m| matches!(m, DeviceMsg::RunEnded(_)))
    );
    // The released pin read x0 = 667 µm at release.
    let x = header.config.calibration[0].to_si(blocks[0].sample(0).unwrap()[0]);
    assert!((x - 667e-6).abs() < 5e-6, "{x}");
}

#[test]
fn heater_fault_during_a_run_cuts_the_heater_and_ends_the_run() {
    let mut b = Bench::new();
    b.hw.tc = Some(reg(60.0));
    b.run_for(200);
    assert_eq!(
        b.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 80.0,
            ramp_c_per_min: 10.0
        }))
        .0,
        Ok(())
    );
    b.run_for(300);
    assert!(b.hw.heater_duty > 0.0);
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(100);
    b.hw.tc = Some(reg(111.0));
    b.run_for(150);
    let msgs = b.msgs();
    assert!(faults(&msgs).contains(&FaultReason::Heater(HeaterFault::OverTemperature)));
    assert_eq!(b.hw.heater_duty, 0.0);
    let end = run_end(&msgs).unwrap();
    assert_eq!(end.reason, EndReason::Fault(HeaterFault::OverTemperature));
    assert_eq!(
        b.app.status().heater_fault,
        Some(HeaterFault::OverTemperature)
    );
    assert!(
        b.hw.lamps.red || {
            b.run_for(250);
            b.hw.lamps.red
        }
    );
    // Shorted thermocouple while idle: reported, heater stays off, until a new setpoint once fixed.
    b.hw.tc = Some(bad(crate::thermocouple::sr::OVUV));
    assert_eq!(
        b.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 50.0,
            ramp_c_per_min: 10.0
        }))
        .0,
        Ok(())
    );
    b.run_for(TC_FAULT_MS);
    assert!(faults(&b.msgs()).contains(&FaultReason::Heater(HeaterFault::ShortedThermocouple)));
    assert_eq!(b.hw.heater_duty, 0.0);
}

#[test]
fn a_reader_stall_is_a_gap_frame_with_the_exact_missing_samples_and_the_run_goes_on() {
    let mut b = Bench::new();
    b.hw.stop_s = 1.0;
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(100);
    // Every sample due so far was read; the reader then stops for 300 ms (3000 samples, for a
    // ring of 2048), while the converter goes on.
    let stall_from = b.hw.adc.next_index();
    b.hw.adc.stall_reader(b.hw.now_us + 300_000);
    b.run_for(299);
    let before_resume = b.hw.adc.next_index();
    b.run_for(1);
    // At the poll that resumed reading, the ring held the last RING_SCANS samples.
    let resumed_at = b.hw.adc.next_index() - crate::acquisition::RING_SCANS as u64;
    assert!(before_resume < b.hw.adc.next_index());
    b.run_for(1500);
    let msgs = b.msgs();
    let base = b.app.run_base;
    let gaps: Vec<Gap> = msgs
        .iter()
        .filter_map(|m| match m {
            DeviceMsg::Gap(g) => Some(*g),
            _ => None,
        })
        .collect();
    assert_eq!(
        gaps,
        [Gap {
            run_id: 1,
            first_sample: (stall_from - base) as u32,
            count: (resumed_at - stall_from) as u32,
        }]
    );
    let end = run_end(&msgs).unwrap();
    assert_eq!(end.reason, EndReason::Stopped, "the run went on to its end");
    assert_eq!(end.overruns, gaps[0].count);
    assert_eq!(b.app.status().overruns, gaps[0].count);
    // Blocks: numbered on, each of consecutive samples, the one after the gap starting at its end,
    // and every sample holding the displacement of its own instant.
    let blocks = sample_blocks(&msgs);
    assert_eq!(
        blocks.iter().map(|k| k.block).collect::<Vec<_>>(),
        (0..blocks.len() as u32).collect::<Vec<_>>()
    );
    let mut next = 0;
    for k in &blocks {
        if k.first_sample != next {
            assert_eq!(
                (next, k.first_sample),
                (gaps[0].first_sample, gaps[0].first_sample + gaps[0].count)
            );
        }
        next = k.first_sample + k.samples() as u32;
        b.hw.check_block(k, base);
    }
    assert_eq!(next, end.samples + end.overruns);
}

#[test]
fn a_poll_takes_a_bounded_number_of_samples_and_a_backlog_drains_over_the_next_polls() {
    let mut b = Bench::new();
    b.hw.stop_s = 3.0;
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(50);
    // 100 ms without reading: 1000 samples wait in the 2048-scan ring (none lost).
    b.hw.adc.stall_reader(b.hw.now_us + 100_000);
    b.run_for(100);
    let taken = |b: &Bench| b.app.builder.as_ref().unwrap().samples();
    let per_poll = b.app.samples_per_poll() as u32;
    assert_eq!(
        per_poll, 16,
        "twice the 5 samples (at least 8) that arrive per 500 µs poll"
    );
    // Each poll takes what arrived and, when no block waits to be packed, up to that many again:
    // the backlog drains over the next polls (packing a block takes 6 of the 12.8 polls its samples
    // span), and nothing is lost.
    let mut polls = 0;
    while b.app.next_index < b.hw.adc.next_index() && polls < 2000 {
        let before = taken(&b);
        b.hw.now_us += 500;
        b.poll();
        let t = taken(&b) - before;
        assert!((5..=per_poll).contains(&t), "a poll took {t} samples");
        polls += 1;
    }
    assert_eq!(b.app.next_index, b.hw.adc.next_index(), "caught up");
    assert!(
        polls > 100,
        "{polls} polls: faster than the packing allows?"
    );
    let msgs = b.msgs();
    assert!(!msgs.iter().any(|m| matches!(m, DeviceMsg::Gap(_))));
    assert_eq!(b.app.status().overruns, 0);
}

#[test]
fn an_adc_overrun_restarts_the_converter_and_is_a_gap_not_a_shift() {
    let mut b = Bench::new();
    b.hw.stop_s = 0.6;
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(200);
    let at = b.hw.adc.next_index();
    b.hw.adc.inject_overrun();
    b.run_for(1000);
    let msgs = b.msgs();
    let base = b.app.run_base;
    let gaps: Vec<Gap> = msgs
        .iter()
        .filter_map(|m| match m {
            DeviceMsg::Gap(g) => Some(*g),
            _ => None,
        })
        .collect();
    // The scan the overrun struck and those converted until the next read (one 1 ms poll: ten).
    assert_eq!(gaps.len(), 1);
    assert_eq!(gaps[0].first_sample as u64, at - base);
    assert!((1..=11).contains(&gaps[0].count), "{:?}", gaps);
    // After it, the samples are those of their own instants: nothing shifted by the lost ones.
    for k in &sample_blocks(&msgs) {
        b.hw.check_block(k, base);
    }
    assert_eq!(run_end(&msgs).unwrap().overruns, gaps[0].count);
}

#[test]
fn a_rate_the_timer_cannot_make_is_run_at_the_nearest_and_recorded() {
    let mut b = Bench::new();
    let mut cfg = Configure::real_rig(0.3);
    cfg.sample_rate_hz = 9_999;
    assert_eq!(b.command(HostMsg::Configure(cfg)).0, Ok(()));
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    b.run_for(300);
    let (r, mut msgs) = b.command(HostMsg::Release);
    assert_eq!(r, Ok(()));
    b.run_for(700);
    msgs.extend(b.msgs());
    let header = msgs
        .iter()
        .find_map(|m| match m {
            DeviceMsg::RunStarted(h) => Some(*h),
            _ => None,
        })
        .unwrap();
    // 200 MHz / 20 002 = 9 999.0001 S/s: the rate used, not the one asked for.
    assert_eq!(
        header.clock,
        SampleClock {
            timer_hz: 200_000_000,
            ticks_per_sample: 20_002
        }
    );
    assert_eq!(header.config.sample_rate_hz, 9_999);
    let base = b.app.run_base;
    for k in &sample_blocks(&msgs) {
        assert_eq!(
            k.t_us,
            header.t_us + header.clock.time_us(k.first_sample as u64)
        );
        b.hw.check_block(k, base);
    }
}

#[test]
fn ecr_range_changes_flag_exactly_the_settling_samples_and_no_reading_uses_them() {
    let mut b = Bench::new();
    b.hw.stop_s = 1.0;
    b.hw.ecr_settles = true;
    b.ready();
    // Armed long enough for the autoranger to find 1e7 Ω (range 3) and settle.
    b.run_for(1500);
    assert_eq!(b.app.ecr.range(), 3);
    let (r, mut msgs) = b.command(HostMsg::Release);
    assert_eq!(r, Ok(()));
    b.run_for(100);
    // The contact drops to 10 Ω: the autoranger steps down to range 0, one change per block.
    b.hw.ecr_r = 10.0;
    b.run_for(1400);
    msgs.extend(b.msgs());
    let clock = msgs
        .iter()
        .find_map(|m| match m {
            DeviceMsg::RunStarted(h) => Some(h.clock),
            _ => None,
        })
        .unwrap();
    let changes: Vec<EcrRangeChange> = msgs
        .iter()
        .filter_map(|m| match m {
            DeviceMsg::EcrRange(e) => Some(*e),
            _ => None,
        })
        .collect();
    let ranges: Vec<u8> = changes.iter().map(|c| c.range).collect();
    assert_eq!(ranges, [3, 2, 1, 0], "{changes:?}");
    // The run starts settled on range 3; each change settles for its range's stated time.
    assert_eq!((changes[0].first_sample, changes[0].settling), (0, 0));
    for c in &changes[1..] {
        assert_eq!(c.settling, crate::ecr::settling_samples(c.range, clock));
    }
    assert!(changes
        .windows(2)
        .all(|w| w[0].first_sample < w[1].first_sample));
    // What the frames say about sample i: its range and whether it settles.
    let range_of = |i: u32| changes.iter().rev().find(|c| c.first_sample <= i).unwrap();
    let settling = |i: u32| {
        let c = range_of(i);
        i < c.first_sample + c.settling as u32
    };
    let blocks = sample_blocks(&msgs);
    let pos = Channel::Ecr.index() - 1; // after displacement and velocity; force is counted too
    let pos = blocks[0].channels.position(Channel::Ecr).unwrap_or(pos);
    let garbage = b.hw.cal[3].to_count(SETTLING_V);
    let mut flagged_garbage = 0;
    for k in &blocks {
        // The range a block declares is the one its first sample was converted on.
        assert_eq!(
            k.ecr_range,
            range_of(k.first_sample).range,
            "block {}",
            k.block
        );
        for i in 0..k.samples() {
            let idx = k.first_sample + i as u32;
            if k.sample(i).unwrap()[pos] == garbage {
                // Every sample taken while the amplifier settled is flagged as settling.
                assert!(settling(idx), "sample {idx} unsettled but not flagged");
                flagged_garbage += 1;
            }
        }
        // No reading is made of settling samples or of samples from two ranges: each one is the
        // contact's resistance before or after the step.
        let l = k.log10_ecr_ohm;
        assert!(
            l.is_nan() || (l - 7.0).abs() < 0.01 || (l - 1.0).abs() < 0.01,
            "block {}: log10 R = {l}",
            k.block
        );
    }
    assert!(flagged_garbage > 0, "the settling was exercised");
    let last = blocks.last().unwrap();
    assert!((last.log10_ecr_ohm - 1.0).abs() < 0.01);
}

#[test]
fn out_of_range_commands_are_refused_by_field() {
    let mut b = Bench::new();
    let good = Configure::real_rig(0.3);
    let cases: Vec<(Configure, Field)> = vec![
        (
            Configure {
                rig: crate::wire::RigConstants {
                    mass_kg: 0.0,
                    ..good.rig
                },
                ..good
            },
            Field::Mass,
        ),
        (
            Configure {
                rig: crate::wire::RigConstants {
                    stiffness_n_per_m: f32::NAN,
                    ..good.rig
                },
                ..good
            },
            Field::Stiffness,
        ),
        (
            Configure {
                rig: crate::wire::RigConstants {
                    load_n: 0.9,
                    ..good.rig
                },
                ..good
            },
            Field::Load,
        ),
        (
            Configure {
                sample_rate_hz: 100,
                ..good
            },
            Field::SampleRate,
        ),
        (
            Configure {
                channels: ChannelSet::EMPTY.with(Channel::Force),
                ..good
            },
            Field::Channels,
        ),
        (
            Configure {
                initial_amplitude_m: 2e-3,
                ..good
            },
            Field::InitialAmplitude,
        ),
        (
            Configure {
                max_duration_s: f32::INFINITY,
                ..good
            },
            Field::MaxDuration,
        ),
    ];
    for (c, f) in cases {
        assert_eq!(
            b.command(HostMsg::Configure(c)).0,
            Err(ErrorCode::OutOfRange(f))
        );
    }
    // In range for the wire, but too few samples per cycle for the on-board analysis (1.6 kHz rig
    // sampled at 1 kS/s): refused now, not discovered after the run.
    let fast = Configure {
        rig: crate::wire::RigConstants {
            mass_kg: 1e-3,
            stiffness_n_per_m: 1e5,
            ..good.rig
        },
        sample_rate_hz: 1000,
        ..good
    };
    assert_eq!(
        b.command(HostMsg::Configure(fast)).0,
        Err(ErrorCode::OutOfRange(Field::SampleRate))
    );
    assert_eq!(
        b.app.state(),
        RigState::Idle,
        "a refused Configure changed the state"
    );
    for (sp, f) in [
        (
            HeaterSetpoint {
                setpoint_c: 150.0,
                ramp_c_per_min: 5.0,
            },
            Field::HeaterSetpoint,
        ),
        (
            HeaterSetpoint {
                setpoint_c: f32::NAN,
                ramp_c_per_min: 5.0,
            },
            Field::HeaterSetpoint,
        ),
        (
            HeaterSetpoint {
                setpoint_c: 50.0,
                ramp_c_per_min: 0.0,
            },
            Field::HeaterRamp,
        ),
    ] {
        assert_eq!(
            b.command(HostMsg::SetHeater(sp)).0,
            Err(ErrorCode::OutOfRange(f))
        );
    }
    assert_eq!(b.app.status().heater_setpoint_c, None);
    assert_eq!(
        b.command(HostMsg::Pull {
            run_id: 1,
            from_block: 0
        })
        .0,
        Err(ErrorCode::NoRun)
    );
    // Garbage, a corrupted frame, then a good one: one Malformed each, and the good one still works.
    let mut bad = encode_vec(7, &HostMsg::Status).unwrap();
    bad[3] ^= 0x10;
    b.app.on_bytes(&mut b.hw, &[1, 2, 3, 0], 0);
    b.app.on_bytes(&mut b.hw, &bad, 0);
    let (r, msgs) = b.command(HostMsg::Status);
    assert_eq!(r, Ok(()));
    assert_eq!(errors(&msgs), [ErrorCode::Malformed, ErrorCode::Malformed]);
    assert!(msgs
        .iter()
        .any(|m| matches!(m, DeviceMsg::Status(s) if s.state == RigState::Idle)));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn random_bytes_never_panic_and_every_reply_decodes(chunks in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..300), 1..8)) {
        let mut b = Bench::with_store(16 * 1024);
        b.ready();
        for c in &chunks {
            let now = b.hw.now_us;
            b.app.on_bytes(&mut b.hw, c, now);
            b.run_for(3);
            // take() decodes every frame sent, or fails the test.
            b.take();
        }
        // A zero byte ends whatever partial frame the garbage left.
        b.app.on_bytes(&mut b.hw, &[0], 0);
        // Still alive and talking.
        let (r, _) = b.command(HostMsg::Status);
        prop_assert_eq!(r, Ok(()));
    }

    #[test]
    fn random_commands_never_panic(cmds in prop::collection::vec(0u8..10, 1..30), k in any::<u32>()) {
        let mut b = Bench::with_store(16 * 1024);
        for c in cmds {
            let msg = match c {
                0 => HostMsg::Configure(Configure::real_rig(0.3)),
                1 => HostMsg::Arm,
                2 => HostMsg::Release,
                3 => HostMsg::Abort,
                4 => HostMsg::Disarm,
                5 => HostMsg::Pull { run_id: k % 3, from_block: k },
                6 => HostMsg::SetHeater(HeaterSetpoint { setpoint_c: (k % 200) as f32, ramp_c_per_min: 1.0 }),
                7 => HostMsg::HeaterOff,
                8 => HostMsg::Status,
                _ => HostMsg::Hello { protocol: (k % 3) as u16 },
            };
            let _ = b.command(msg);
            b.run_for(20);
        }
    }
}

#[test]
fn a_pull_replays_the_same_bytes_from_any_block() {
    let mut b = Bench::new();
    let frames = full_run(&mut b);
    let run_frames: Vec<_> = frames.iter().filter(|f| f.1.msg.is_run_frame()).collect();
    let n_blocks = run_frames.iter().filter(|f| is_block(&f.1.msg)).count();
    assert!(n_blocks > 20);
    assert!(run_frames
        .iter()
        .any(|f| matches!(f.1.msg, DeviceMsg::EcrRange(_))));
    for from in [0, 1, n_blocks / 2, n_blocks - 1, n_blocks + 5] {
        b.send(HostMsg::Pull {
            run_id: 1,
            from_block: from as u32,
        });
        b.run_for(200);
        let mut again = b.take();
        assert!(matches!(again.remove(0).1.msg, DeviceMsg::Ack { .. }));
        // The header, then the live order from just after block `from − 1`: the events between
        // blocks `from − 1` and `from` come along, each in its place (those before were received
        // with the blocks before them).
        let after = run_frames
            .iter()
            .rposition(|f| matches!(&f.1.msg, DeviceMsg::Packed(p) if (p.block as usize) < from))
            .map_or(1, |i| i + 1);
        let expect: Vec<&Vec<u8>> = run_frames[..1]
            .iter()
            .chain(&run_frames[after..])
            .map(|f| &f.0)
            .collect();
        let got: Vec<&Vec<u8>> = again.iter().map(|f| &f.0).collect();
        assert_eq!(got, expect, "pull from block {from}");
    }
}

#[test]
fn a_cable_pulled_mid_run_loses_nothing() {
    let mut b = Bench::new();
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(100);
    let mut seen = b.take();
    b.hw.connected = false;
    b.run_for(150);
    b.hw.connected = true;
    b.app.link_reset();
    for _ in 0..3000 {
        b.run_for(1);
        seen.extend(b.take());
        if b.app.state() == RigState::Finished && b.app.want.is_none() {
            break;
        }
    }
    let blocks: Vec<u32> = block_indices(seen.iter().map(|f| &f.1.msg));
    let end = run_end(&seen.iter().map(|f| &f.1.msg).collect::<Vec<_>>()).unwrap();
    assert_eq!(
        blocks,
        (0..end.blocks).collect::<Vec<_>>(),
        "every block exactly once, in order"
    );
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

#[test]
fn a_run_longer_than_ram_is_pulled_whole_from_flash() {
    // RAM for a few packed blocks; the run has over 60. (RAM this small cannot ride out an erase
    // of the real 1.1 s: the flash here is instant.)
    let mut b = Bench::with_store(2 * 1024);
    b.hw.flash = MemFlash::new(vec![0; 1 << 20], FlashGeometry::H743_BANK2);
    let frames = full_run(&mut b);
    let run_frames: Vec<&Vec<u8>> = frames
        .iter()
        .filter(|f| f.1.msg.is_run_frame())
        .map(|f| &f.0)
        .collect();
    let total = frames.iter().filter(|f| is_block(&f.1.msg)).count() as u32;
    assert!(total > 60);
    settle_flash(&mut b);
    assert!(b.app.store().first_block_in_ram() > total / 2);
    b.take();
    b.send(HostMsg::Pull {
        run_id: 1,
        from_block: 0,
    });
    b.run_for(200);
    let mut again = b.take();
    assert!(matches!(again.remove(0).1.msg, DeviceMsg::Ack { .. }));
    let got: Vec<&Vec<u8>> = again.iter().map(|f| &f.0).collect();
    assert_eq!(got, run_frames, "the very frames first sent, all of them");
    assert_eq!(b.hw.flash.violations(), 0);
}

#[test]
fn after_a_power_cut_the_rig_offers_the_last_run_from_flash() {
    let mut b = Bench::new();
    let frames = full_run(&mut b);
    let run_frames: Vec<Vec<u8>> = frames
        .iter()
        .filter(|f| f.1.msg.is_run_frame())
        .map(|f| f.0.clone())
        .collect();
    settle_flash(&mut b);
    // Power cut: the application and its RAM are gone; the flash (in the hardware) stays.
    b.hw.flash.power_cut();
    b.app = App::new(AppConfig::new(42), store(256 * 1024));
    b.poll();
    assert_eq!(
        b.app.status().run_id,
        1,
        "the recovered run is the rig's last run"
    );
    assert_eq!(b.app.state(), RigState::Idle);
    b.take();
    b.send(HostMsg::Pull {
        run_id: 1,
        from_block: 0,
    });
    b.run_for(300);
    let mut again = b.take();
    assert!(matches!(again.remove(0).1.msg, DeviceMsg::Ack { .. }));
    let got: Vec<Vec<u8>> = again.into_iter().map(|f| f.0).collect();
    assert_eq!(got, run_frames, "bit-identical from flash");
    // The next run gets the next number.
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(20);
    let msgs = b.msgs();
    assert!(
        msgs.iter()
            .any(|m| matches!(m, DeviceMsg::RunStarted(h) if h.run_id == 2)),
        "{msgs:?}"
    );
}

#[test]
fn pull_blocks_sends_those_blocks_only_then_the_live_stream_goes_on() {
    let mut b = Bench::new();
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(100);
    let first = b.take();
    let seen = block_indices(first.iter().map(|f| &f.1.msg));
    assert!(seen.len() > 10);
    let (r, msgs) = b.command(HostMsg::PullBlocks {
        run_id: 1,
        first: 2,
        count: 3,
    });
    assert_eq!(r, Ok(()));
    let mut rest = msgs;
    for _ in 0..3000 {
        b.run_for(1);
        rest.extend(b.msgs());
        if b.app.state() == RigState::Finished && !b.app.sending() {
            break;
        }
    }
    let blocks = block_indices(rest.iter());
    assert_eq!(&blocks[..3], &[2, 3, 4], "the asked blocks first");
    let live: Vec<u32> = blocks[3..].to_vec();
    let end = run_end(&rest).unwrap();
    assert_eq!(
        seen.iter().chain(live.iter()).copied().collect::<Vec<_>>(),
        (0..end.blocks).collect::<Vec<_>>(),
        "the live stream resumed where it was"
    );
    // Out of range: nothing but the Ack.
    let (r, msgs) = b.command(HostMsg::PullBlocks {
        run_id: 1,
        first: end.blocks + 10,
        count: u32::MAX,
    });
    assert_eq!(r, Ok(()));
    b.run_for(20);
    assert!(block_indices(msgs.iter().chain(b.msgs().iter())).is_empty());
    assert_eq!(
        b.command(HostMsg::PullBlocks {
            run_id: 2,
            first: 0,
            count: 1
        })
        .0,
        Err(ErrorCode::NoRun)
    );
}

#[test]
fn abort_keeps_the_run_and_marks_it() {
    let mut b = Bench::new();
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(100);
    let (r, mut msgs) = b.command(HostMsg::Abort);
    assert_eq!(r, Ok(()));
    b.run_for(50);
    msgs.extend(b.msgs());
    let end = run_end(&msgs).unwrap();
    let res = onboard_result(&msgs).unwrap();
    assert_eq!(
        (end.reason, res.verdict),
        (EndReason::Aborted, Verdict::Aborted)
    );
    assert!(!b.hw.adc.is_running());
    assert_eq!(
        b.command(HostMsg::Pull {
            run_id: 1,
            from_block: 0
        })
        .0,
        Ok(())
    );
}

#[test]
fn an_unloaded_run_runs_to_its_maximum_duration_without_onboard_analysis() {
    let mut b = Bench::new();
    let mut c = Configure::real_rig(0.0);
    c.max_duration_s = 0.5;
    assert_eq!(b.command(HostMsg::Configure(c)).0, Ok(()));
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    b.run_for(50);
    b.send(HostMsg::Release);
    b.run_for(700);
    let msgs = b.msgs();
    let end = run_end(&msgs).unwrap();
    let res = onboard_result(&msgs).unwrap();
    assert_eq!((end.reason, end.samples), (EndReason::MaxDuration, 5000));
    assert!(
        res.best.mu0.is_nan() && res.best.mu1.is_nan(),
        "an estimate from no analysis: {res:?}"
    );
    assert_eq!(res.verdict, Verdict::NotAnalysed, "{res:?}");
    assert!((res.duration_s - 0.5).abs() < 1e-6);
}

#[test]
fn lamps_show_idle_armed_running_and_fault() {
    let mut b = Bench::new();
    // Idle: green blinking at 1 Hz, nothing else.
    let mut greens = Vec::new();
    for _ in 0..20 {
        b.run_for(100);
        greens.push(b.hw.lamps.green);
        assert!(!b.hw.lamps.amber && !b.hw.lamps.red);
    }
    assert!(greens.iter().filter(|&&g| g).count() == 10, "{greens:?}");
    b.ready();
    assert_eq!(
        b.hw.lamps,
        Lamps {
            amber: true,
            ..Lamps::default()
        }
    );
    b.send(HostMsg::Release);
    let mut on = 0;
    for _ in 0..400 {
        b.run_for(1);
        on += b.hw.lamps.green as u32;
        assert!(!b.hw.lamps.amber && !b.hw.lamps.red);
    }
    assert_eq!(b.app.state(), RigState::Running);
    assert_eq!(on, 200, "running: green at 5 Hz, half the time on");
    b.hw.tc = Some(bad(crate::thermocouple::sr::OPEN));
    b.run_for(2000);
    let reds: Vec<bool> = (0..8)
        .map(|_| {
            b.run_for(125);
            b.hw.lamps.red
        })
        .collect();
    assert!(
        reds.contains(&true) && reds.contains(&false),
        "fault: red blinking {reds:?}"
    );
    assert!(!b.hw.lamps.green);
}

// ---------------------------------------------------------------------------------------------------
// Fail-safe: lease, safe command, boot report, magnet cool-down, stand-alone mode
// ---------------------------------------------------------------------------------------------------

fn fault_reports(msgs: &[DeviceMsg]) -> Vec<FaultReport> {
    msgs.iter()
        .filter_map(|m| match m {
            DeviceMsg::Fault(f) => Some(*f),
            _ => None,
        })
        .collect()
}

impl Bench {
    /// Heating to 60 °C (the plate at 25 °C) and armed (magnet holding), the host's last frame now.
    fn heating_and_armed(&mut self) {
        let sp = HeaterSetpoint {
            setpoint_c: 60.0,
            ramp_c_per_min: 10.0,
        };
        assert_eq!(self.command(HostMsg::SetHeater(sp)).0, Ok(()));
        self.run_for(300);
        self.ready();
        assert!(self.hw.heater_duty > 0.0);
        assert!(matches!(self.hw.magnet(), MagnetDrive::Hold { .. }));
        self.take();
        assert_eq!(self.command(HostMsg::Heartbeat).0, Ok(()));
    }
}

#[test]
fn host_silence_while_heating_and_holding_makes_the_rig_safe_and_says_why() {
    let mut b = Bench::new();
    b.heating_and_armed();
    let last = b.hw.now_us;
    assert_eq!(b.app.control(), Control::Host);
    // Up to the lease, all on.
    b.run_for(limits::HOST_LEASE_MS as u64);
    assert!(b.hw.heater_duty > 0.0);
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    assert!(faults(&b.msgs()).is_empty());
    // The first poll past it: safe, then the fault frame.
    let period = b.app.cfg.poll_period_us as u64;
    b.hw.now_us += period;
    b.poll();
    assert_eq!(
        b.hw.now_us - last,
        limits::HOST_LEASE_MS as u64 * 1000 + period
    );
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(!b.hw.adc.is_running());
    let f = fault_reports(&b.msgs());
    assert_eq!(f.len(), 1);
    assert_eq!(f[0].reason, FaultReason::LeaseExpired);
    assert_eq!(f[0].uptime_ms, b.hw.now_us / 1000);
    assert_eq!(f[0].temp_c, 25.0);
    // Told once; the status keeps it; nothing heats until a host sets a setpoint again.
    b.run_for(5_000);
    assert!(fault_reports(&b.msgs()).is_empty());
    assert_eq!(b.hw.heater_duty, 0.0);
    let st = b.app.status();
    assert_eq!((st.last_fault, st.faults), (Some(f[0]), 1));
    assert_eq!(st.heater_setpoint_c, None);
    assert!(!st.magnet_on);
    assert_eq!(st.state, RigState::Configured);
    assert_eq!(st.control, Control::None);
    // Idle, a silent host is no fault.
    let mut b = Bench::new();
    b.run_for(10_000);
    assert!(faults(&b.msgs()).is_empty());
}

#[test]
fn heartbeats_and_any_command_keep_the_lease() {
    let mut b = Bench::new();
    b.heating_and_armed();
    b.app.cfg.release.hold_limit_us = 60_000_000;
    for i in 0..20 {
        b.run_for(limits::HEARTBEAT_MS as u64);
        let cmd = if i % 2 == 0 {
            HostMsg::Heartbeat
        } else {
            // A command that acts (here refused: the rig is armed) renews it too.
            HostMsg::Configure(Configure::real_rig(0.3))
        };
        b.send(cmd);
    }
    assert!(faults(&b.msgs()).is_empty());
    assert!(b.hw.heater_duty > 0.0);
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    // Garbage on the line is no sign of a live host.
    for _ in 0..4 {
        b.run_for(limits::HEARTBEAT_MS as u64);
        let now = b.hw.now_us;
        b.app.on_bytes(&mut b.hw, &[1, 2, 3, 0], now);
    }
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    // Nor is a program that only looks: status polls (and hellos, pulls) do not hold the rig.
    let mut b = Bench::new();
    b.heating_and_armed();
    for i in 0..4 {
        b.run_for(limits::HEARTBEAT_MS as u64);
        b.send(if i % 2 == 0 {
            HostMsg::Status
        } else {
            HostMsg::Hello {
                protocol: PROTOCOL_VERSION,
            }
        });
    }
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    assert_eq!(b.hw.heater_duty, 0.0);
}

#[test]
fn the_safe_command_turns_everything_off_at_once() {
    let mut b = Bench::new();
    b.heating_and_armed();
    let (r, msgs) = b.command(HostMsg::Safe);
    assert_eq!(r, Ok(()));
    // Within the same call that read the command: no poll needed.
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(!b.hw.adc.is_running());
    assert!(faults(&msgs).is_empty(), "asked for, not a fault");
    b.run_for(10_000);
    assert!(faults(&b.msgs()).is_empty());
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.app.status().heater_setpoint_c, None);
    // During a run: the run goes on recording.
    let mut b = Bench::new();
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(50);
    assert_eq!(b.command(HostMsg::Safe).0, Ok(()));
    assert_eq!(b.app.state(), RigState::Running);
    b.run_for(100);
    assert!(b.msgs().iter().any(is_block));
}

#[test]
fn the_boot_report_goes_to_the_first_hello_and_the_cause_stays_in_the_status() {
    let mut b = Bench::new();
    let mut msg = heapless::String::new();
    msg.push_str("panicked at src/heater.rs:1:1: boom").unwrap();
    b.app.set_boot_report(BootReport {
        cause: ResetCause::Panic,
        message: msg.clone(),
    });
    // The link refuses frames: kept for the next hello.
    b.hw.connected = false;
    b.send(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    b.hw.connected = true;
    let (r, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    assert_eq!(r, Ok(()));
    assert!(matches!(msgs[0], DeviceMsg::Hello(_)));
    assert_eq!(
        msgs[1],
        DeviceMsg::Boot(BootReport {
            cause: ResetCause::Panic,
            message: msg
        })
    );
    let (_, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    assert!(!msgs.iter().any(|m| matches!(m, DeviceMsg::Boot(_))));
    assert_eq!(b.app.status().reset_cause, ResetCause::Panic);
}

#[test]
fn an_empty_hold_budget_cuts_the_coil_and_arming_waits_for_the_cool_down() {
    let mut b = Bench::new();
    b.app.cfg.release.hold_limit_us = 2_000_000;
    b.app.release = Release::new(b.app.cfg.release);
    b.ready();
    b.take();
    b.run_for(2_100);
    let f = fault_reports(&b.msgs());
    assert_eq!(f.len(), 1);
    assert_eq!(f[0].reason, FaultReason::MagnetHoldTime);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    // Half the budget (1 s) back at 50 % duty: 1 s of rest from the cut, 2 s after arming, which
    // was 50 + 2100 ms ago.
    match b.command(HostMsg::Arm).0 {
        Err(ErrorCode::MagnetCooling { wait_ms }) => assert_eq!(wait_ms, 850),
        r => panic!("{r:?}"),
    }
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    b.run_for(1_000);
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
}

#[test]
fn stand_alone_mode_arms_on_a_long_press_with_its_own_limits() {
    let mut b = Bench::new();
    // Stand-alone heating for 45 s after each press (30 min on the rig), longer than the hold limit.
    b.app.cfg.standalone_heat_ms = 45_000;
    b.app.lease = crate::lease::Lease::new(b.app.cfg.host_lease_ms, 45_000);
    b.heating_and_armed();
    assert_eq!(b.command(HostMsg::Disarm).0, Ok(()));
    // The host goes away: safe.
    b.run_for(limits::HOST_LEASE_MS as u64 + 10);
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    assert_eq!(b.hw.heater_duty, 0.0);
    // A short press does not arm.
    b.hw.button = true;
    b.run_for(500);
    b.hw.button = false;
    b.run_for(100);
    assert_eq!(b.app.state(), RigState::Configured);
    // A long press does: magnet on, heating again to the host's last setpoint.
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    b.run_for(200);
    assert_eq!(b.app.state(), RigState::Armed);
    assert_eq!(b.app.control(), Control::StandAlone);
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    assert_eq!(b.app.status().heater_setpoint_c, Some(60.0));
    assert!(b.hw.heater_duty > 0.0);
    // Not released: the magnet holds at most the stand-alone limit (armed 210 ms ago).
    b.take();
    b.run_for(limits::STANDALONE_HOLD_MS as u64 - 220);
    let f = faults(&b.msgs());
    assert!(f.is_empty(), "{f:?}");
    b.run_for(20);
    assert_eq!(faults(&b.msgs()), vec![FaultReason::MagnetHoldTime]);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(
        b.hw.heater_duty > 0.0,
        "the heater runs on, within its own limit"
    );
    // Long press again, then a short one releases: a run, like with a host.
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    b.run_for(100);
    assert_eq!(b.app.state(), RigState::Armed);
    let press_at = b.hw.now_us;
    b.hw.button = true;
    b.run_for(30);
    b.hw.button = false;
    assert_eq!(b.app.state(), RigState::Running);
    b.run_for(1_000);
    // 45 s after the last press, the heater goes off and the fault says why.
    b.take();
    b.run_for(45_000 - (b.hw.now_us - press_at) / 1000 - 10);
    assert!(faults(&b.msgs()).is_empty());
    assert!(b.hw.heater_duty > 0.0);
    b.run_for(40);
    let f = faults(&b.msgs());
    assert_eq!(f, vec![FaultReason::StandAloneExpired]);
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.app.control(), Control::None);
}

#[test]
fn a_host_takes_over_stand_alone_mode_and_a_held_rig_ignores_long_presses() {
    let mut b = Bench::new();
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Ok(())
    );
    // Held by a host: a long press does nothing.
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    assert_eq!(b.app.state(), RigState::Configured);
    b.run_for(limits::HOST_LEASE_MS as u64 + 10);
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    assert_eq!(b.app.state(), RigState::Armed);
    assert_eq!(b.app.control(), Control::StandAlone);
    b.send(HostMsg::Status);
    assert_eq!(
        b.app.control(),
        Control::StandAlone,
        "a look does not take over"
    );
    b.send(HostMsg::Heartbeat);
    assert_eq!(b.app.control(), Control::Host);
    // The host now holds it, under its lease: silent, the magnet goes off.
    b.take();
    b.run_for(limits::HOST_LEASE_MS as u64 + 10);
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
}

/// The end-of-run fit is spread over polls: once the pin has stopped the run stays `Running`
/// (no new run can be configured or armed) until the result and end frames exist, some polls
/// later, and the result is the pipeline's one-call result.
#[test]
fn the_end_of_run_fit_is_spread_over_polls() {
    let mut b = Bench::new();
    b.app.cfg.finish_rows_per_poll = 4;
    b.ready();
    b.send(HostMsg::Release);
    let mut analysing_polls = 0;
    for _ in 0..3000 {
        b.run_for(1);
        if b.app.ending.is_some() {
            analysing_polls += 1;
            assert_eq!(b.app.state(), RigState::Running);
            if analysing_polls == 2 {
                let (r, _) = b.command(HostMsg::Configure(Configure::real_rig(0.3)));
                assert_eq!(r, Err(ErrorCode::Busy));
                assert!(b.app.store().end().is_none());
            }
        }
        if b.app.state() == RigState::Finished {
            break;
        }
    }
    let p = b.app.pipeline.as_ref().unwrap();
    let half_cycles = p.half_cycles().len();
    assert!(half_cycles > 10, "{half_cycles}");
    // 4 rows per poll over ~35 passes of the half-cycles
    assert!(analysing_polls > half_cycles, "{analysing_polls} polls");
    let one_call = p.finish(b.app.run_id());
    let stored = b
        .app
        .store()
        .result()
        .map(|f| decode_one::<DeviceMsg>(f).unwrap().msg);
    assert_eq!(stored, Some(DeviceMsg::Result(one_call)));
}
