//! Host tests of the application through the hardware traits, with a small kinematic rig.

use super::*;
use crate::hal::*;
use crate::runstore::BlockMeta;
use crate::wire::frame::decode_one;

fn encode_vec(seq: u32, msg: &HostMsg) -> Result<Vec<u8>, crate::wire::EncodeError> {
    let mut out = vec![0u8; MAX_FRAME];
    let n = Encoder::new().encode(seq, msg, &mut out)?.len();
    out.truncate(n);
    Ok(out)
}
use crate::wire::{ChannelSet, Field, HeaterFault, HeaterSetpoint, BLOCK_LEN};
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
            _ => None,
        })
        .collect()
}

/// The run's on-board result among the messages, if it came.
fn onboard_result<M: core::borrow::Borrow<DeviceMsg>>(msgs: &[M]) -> Option<OnboardResult> {
    msgs.iter().find_map(|m| match m.borrow() {
        DeviceMsg::Result(r) => Some(*r),
        _ => None,
    })
}

/// A rig whose pin, once released, oscillates at 26 Hz with an amplitude decaying linearly to rest
/// (Coulomb-like) in `stop_s`. The ADC converts on demand up to the time set by the test.
struct Mock {
    now_us: u64,
    cal: [crate::wire::ChannelCal; CHANNELS],
    drives: Vec<(u64, MagnetDrive)>,
    released_at: Option<u64>,
    temp: Result<f32, ThermocoupleFault>,
    heater_duty: f32,
    ecr_r: f32,
    ecr_range: u8,
    ecr_source: f32,
    adc_ok: bool,
    adc_on: bool,
    rate: u32,
    next_sample_us: f64,
    ring: crate::acquisition::Ring<4096>,
    button: bool,
    connected: bool,
    out: Vec<u8>,
    lamps: Lamps,
    stop_s: f64,
}

impl Mock {
    fn new() -> Self {
        Mock {
            now_us: 0,
            cal: Configure::real_rig(0.3).calibration,
            drives: Vec::new(),
            released_at: None,
            temp: Ok(25.0),
            heater_duty: 0.0,
            ecr_r: 1e7,
            ecr_range: 0,
            ecr_source: 0.0,
            adc_ok: true,
            adc_on: false,
            rate: 0,
            next_sample_us: 0.0,
            ring: crate::acquisition::Ring::new(),
            button: false,
            connected: true,
            out: Vec::new(),
            lamps: Lamps::default(),
            stop_s: 0.5,
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

    /// Converts every sample due up to `now_us` into the ring.
    fn convert(&mut self) {
        if !self.adc_on {
            return;
        }
        let dt = 1e6 / self.rate as f64;
        while self.next_sample_us <= self.now_us as f64 {
            let (x, v) = self.x_v(self.next_sample_us);
            let s = [
                self.cal[0].to_count(x as f32),
                self.cal[1].to_count(v as f32),
                self.cal[2].to_count(0.01),
                self.cal[3].to_count(self.ecr_out()),
            ];
            self.ring.push(s);
            self.next_sample_us += dt;
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
    fn read_thermocouple(&mut self) -> Result<f32, ThermocoupleFault> {
        self.temp
    }
}
impl HeaterOutput for Mock {
    fn set_heater_duty(&mut self, d: f32) {
        self.heater_duty = d;
    }
}
impl EcrFrontEnd for Mock {
    fn set_ecr_source(&mut self, v: f32) {
        self.ecr_source = v;
    }
    fn set_ecr_range(&mut self, r: u8) {
        self.ecr_range = r;
    }
    fn read_ecr_output(&mut self) -> f32 {
        self.ecr_out()
    }
}
impl SampleSource for Mock {
    fn adc_start(&mut self, rate_hz: u32) -> bool {
        if !self.adc_ok {
            return false;
        }
        self.adc_on = true;
        self.rate = rate_hz;
        self.next_sample_us = self.now_us as f64;
        self.ring.clear();
        true
    }
    fn adc_stop(&mut self) {
        self.adc_on = false;
    }
    fn adc_running(&self) -> bool {
        self.adc_on
    }
    fn adc_read(&mut self, out: &mut [AnalogSample]) -> usize {
        self.convert();
        self.ring.pop_into(out)
    }
    fn adc_lost(&self) -> u32 {
        self.ring.lost()
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

struct Bench {
    app: App<'static>,
    hw: Mock,
    seq: u32,
}

fn store(counts: usize) -> RunStore<'static> {
    let c = Box::leak(vec![0u16; counts].into_boxed_slice());
    let m = Box::leak(vec![BlockMeta::default(); counts / (2 * BLOCK_LEN) + 1].into_boxed_slice());
    RunStore::new(c, m)
}

impl Bench {
    fn new() -> Self {
        Self::with_store(200_000)
    }

    fn with_store(counts: usize) -> Self {
        let mut b = Bench {
            app: App::new(AppConfig::new(42), store(counts)),
            hw: Mock::new(),
            seq: 100,
        };
        b.poll();
        b
    }

    fn poll(&mut self) {
        self.hw.convert();
        let now = self.hw.now_us;
        self.app.poll(&mut self.hw, now);
    }

    /// Advances time in 1 ms polls.
    fn run_for(&mut self, ms: u64) {
        for _ in 0..ms {
            self.hw.now_us += 1000;
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
    b.hw.temp = Err(ThermocoupleFault::Open);
    b.run_for(200);
    assert!(errors(&b.msgs()).contains(&ErrorCode::Heater(HeaterFault::OpenThermocouple)));
    assert_eq!(b.app.state(), RigState::Fault);
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::HeaterUnhealthy))
    );
    assert!(b.hw.released_at.is_none(), "an interlock let the pin go");
    // Healthy again, cleared by HeaterOff: the release goes through.
    b.hw.temp = Ok(25.0);
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
    assert!(errors(&b.msgs()).contains(&ErrorCode::HoldTimeExceeded));
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(
        !b.hw.adc_on,
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

/// Runs to the end (the run's end frame sent) and returns all frames sent.
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
    let blocks: Vec<&SampleBlock> = msgs
        .iter()
        .filter_map(|m| {
            if let DeviceMsg::Samples(s) = m {
                Some(s)
            } else {
                None
            }
        })
        .collect();
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
        // The autoranger starts cold at arming (least gain, low source): a few blocks to settle.
        if k >= 8 {
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
    let last_block = msgs
        .iter()
        .rposition(|m| matches!(m, DeviceMsg::Samples(_)))
        .unwrap();
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
    b.hw.temp = Ok(60.0);
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
    b.hw.temp = Ok(111.0);
    b.run_for(150);
    let msgs = b.msgs();
    assert!(errors(&msgs).contains(&ErrorCode::Heater(HeaterFault::OverTemperature)));
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
    b.hw.temp = Err(ThermocoupleFault::Shorted);
    assert_eq!(
        b.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 50.0,
            ramp_c_per_min: 10.0
        }))
        .0,
        Ok(())
    );
    b.run_for(200);
    assert!(errors(&b.msgs()).contains(&ErrorCode::Heater(HeaterFault::ShortedThermocouple)));
    assert_eq!(b.hw.heater_duty, 0.0);
}

#[test]
fn overrun_is_reported_and_ends_the_run() {
    let mut b = Bench::new();
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(100);
    // The consumer stalls for 0.5 s: 5000 samples for a 4096-sample ring.
    b.hw.now_us += 500_000;
    b.hw.convert();
    let lost = b.hw.ring.lost();
    assert!(lost > 800, "{lost}");
    b.poll();
    let samples = b.app.status().samples;
    // the end-of-run analysis and the frames still to send take a few more polls
    b.run_for(100);
    assert_eq!(
        b.app.status().samples,
        samples,
        "no sample taken after the overrun"
    );
    let msgs = b.msgs();
    assert!(
        errors(&msgs).contains(&ErrorCode::Overrun { lost_samples: lost }),
        "{:?}",
        errors(&msgs)
    );
    let end = run_end(&msgs).unwrap();
    assert_eq!((end.reason, end.overruns), (EndReason::Overrun, lost));
    // No block reaches past the samples read before the loss was seen: ≈ 100 ms at 10 kS/s.
    assert!(end.samples <= 1100, "{}", end.samples);
    assert_eq!(b.app.status().overruns, lost);
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
        let mut b = Bench::with_store(20_000);
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
        let mut b = Bench::with_store(20_000);
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
    let n_blocks = run_frames.len() - 3;
    assert!(n_blocks > 20);
    for from in [0, 1, n_blocks / 2, n_blocks - 1, n_blocks + 5] {
        b.send(HostMsg::Pull {
            run_id: 1,
            from_block: from as u32,
        });
        // three polls per frame
        b.run_for(400);
        let mut again = b.take();
        assert!(matches!(again.remove(0).1.msg, DeviceMsg::Ack { .. }));
        let expect: Vec<&Vec<u8>> = std::iter::once(&run_frames[0].0)
            .chain(run_frames[1 + from.min(n_blocks)..].iter().map(|f| &f.0))
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

#[test]
fn a_long_run_keeps_its_last_blocks_and_says_which() {
    // Room for 20 blocks of the 5-channel run.
    let mut b = Bench::with_store(20 * 5 * BLOCK_LEN);
    let frames = full_run(&mut b);
    let total = frames
        .iter()
        .filter(|f| matches!(f.1.msg, DeviceMsg::Samples(_)))
        .count() as u32;
    assert!(total > 40);
    assert_eq!(b.app.store().oldest_block(), total - 20);
    b.send(HostMsg::Pull {
        run_id: 1,
        from_block: 0,
    });
    b.run_for(100);
    let again = b.take();
    let blocks: Vec<u32> = block_indices(again.iter().map(|f| &f.1.msg));
    assert_eq!(blocks, (total - 20..total).collect::<Vec<_>>());
    // The held blocks are the very frames first sent.
    for f in again
        .iter()
        .filter(|f| matches!(f.1.msg, DeviceMsg::Samples(_)))
    {
        assert!(frames.iter().any(|g| g.0 == f.0));
    }
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
    assert!(!b.hw.adc_on);
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
    b.hw.temp = Err(ThermocoupleFault::Open);
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

/// The end-of-run fit is spread over polls: once the pin has stopped the run stays `Running`
/// (no new run can be configured or armed) until the result and end frames exist, a few polls
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
                assert!(b.app.store().frame(Item::End).is_none());
            }
        }
        if b.app.state() == RigState::Finished {
            break;
        }
    }
    let half_cycles = b.app.pipeline.as_ref().unwrap().half_cycles().len();
    assert!(half_cycles > 10, "{half_cycles}");
    // 4 rows per poll over ~35 passes of the half-cycles
    assert!(analysing_polls > half_cycles, "{analysing_polls} polls");
    let one_call = b.app.pipeline.as_ref().unwrap().finish(b.app.run_id());
    let stored = b.app.store().frame(Item::Result).map(|f| f.1);
    assert_eq!(stored, Some(DeviceMsg::Result(one_call)));
}

/// A poll after the application was held up takes a bounded number of samples (twice what arrives
/// per poll at 10 kS/s: 20) and sends no frame; the backlog is caught up over the next polls.
#[test]
fn a_backlog_is_caught_up_in_bounded_polls() {
    let mut b = Bench::new();
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(20);
    b.take();
    let before = b.app.status().samples;
    b.hw.now_us += 30_000; // 300 samples wait
    b.poll();
    assert_eq!(b.app.status().samples - before, 20);
    assert!(b.take().is_empty(), "no frame while catching up");
    for _ in 0..40 {
        b.run_for(1);
    }
    // caught up: the 300 of the stall and 40 polls × 10 since, all taken
    assert_eq!(b.app.status().samples - before, 300 + 400);
}
