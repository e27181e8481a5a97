//! The firmware application against the simulated rig, end to end, through wire frames (how the
//! rig is served to a host: `serve.rs`).

use tribo_rig::{VirtualRig, VirtualRigConfig};
use tribo_wire::frame::{decode_one, encode_vec};
use tribo_wire::*;

/// A host talking to a rig in-process.
struct Host {
    rig: VirtualRig,
    seq: u32,
    frames: Vec<(Vec<u8>, Frame<DeviceMsg>)>,
}

impl Host {
    fn new(cfg: VirtualRigConfig) -> Host {
        Host {
            rig: VirtualRig::new(cfg).unwrap(),
            seq: 0,
            frames: Vec::new(),
        }
    }

    fn send(&mut self, msg: HostMsg) -> u32 {
        self.seq += 1;
        self.rig.input(&encode_vec(self.seq, &msg).unwrap());
        self.collect();
        self.seq
    }

    fn collect(&mut self) {
        let out = self.rig.take_output();
        for f in out.split_inclusive(|&b| b == 0) {
            self.frames.push((
                f.to_vec(),
                decode_one(f).expect("the rig sends valid frames"),
            ));
        }
    }

    /// Waits `ms` of device time as a live host does: with a heartbeat every second, so that the
    /// rig's lease holds while it heats or holds the magnet.
    fn wait(&mut self, ms: u64) {
        let end = self.rig.now_us() + ms * 1000;
        let beat = limits::HEARTBEAT_MS as u64 * 1000;
        while self.rig.now_us() < end {
            let t = (self.rig.now_us() + beat).min(end);
            self.rig.advance_to(t);
            self.collect();
            if t < end {
                self.send(HostMsg::Heartbeat);
            }
        }
    }

    fn answer(&self, seq: u32) -> Option<Result<(), ErrorCode>> {
        self.frames.iter().find_map(|f| match &f.1.msg {
            DeviceMsg::Ack { seq: s } if *s == seq => Some(Ok(())),
            DeviceMsg::Error(DeviceError {
                code,
                about_seq: Some(s),
            }) if *s == seq => Some(Err(*code)),
            _ => None,
        })
    }

    fn command(&mut self, msg: HostMsg) -> Result<(), ErrorCode> {
        let s = self.send(msg);
        self.answer(s).expect("answered")
    }

    /// Configures, arms, releases and waits for the end of the run.
    fn run(&mut self, load: f32) -> (RunHeader, Vec<SampleBlock>, OnboardResult, RunEnd) {
        let mut c = Configure::real_rig(load);
        c.max_duration_s = 6.0;
        assert_eq!(self.command(HostMsg::Configure(c)), Ok(()));
        assert_eq!(self.command(HostMsg::Arm), Ok(()));
        self.wait(300);
        assert_eq!(self.command(HostMsg::Release), Ok(()));
        for _ in 0..700 {
            self.wait(10);
            if self
                .frames
                .iter()
                .any(|f| matches!(f.1.msg, DeviceMsg::RunEnded(_)))
            {
                break;
            }
        }
        let mut header = None;
        let mut blocks = Vec::new();
        let mut result = None;
        let mut end = None;
        for f in &self.frames {
            match &f.1.msg {
                DeviceMsg::RunStarted(h) => header = Some(*h),
                DeviceMsg::Samples(_) | DeviceMsg::Packed(_) => {
                    blocks.push(f.1.msg.sample_block().unwrap().expect("blocks unpack"))
                }
                DeviceMsg::Result(r) => result = Some(*r),
                DeviceMsg::RunEnded(e) => end = Some(*e),
                _ => {}
            }
        }
        (
            header.expect("run started"),
            blocks,
            result.expect("result"),
            end.expect("run ended"),
        )
    }
}

#[test]
fn onboard_mu0_mu1_match_the_simulated_contact() {
    for (mu0, mu1, seed) in [(0.02, 0.004, 1u64), (0.005, 0.01, 2)] {
        let cfg = VirtualRigConfig {
            law: tribo_physics::FrictionLaw::coulomb_viscous(mu0, mu1),
            seed,
            ..Default::default()
        };
        let mut h = Host::new(cfg);
        let (true0, true1) = h.rig.truth().unwrap();
        let (header, blocks, result, end) = h.run(0.3);
        assert_eq!(end.reason, EndReason::Stopped, "{end:?}");
        assert_eq!(end.blocks as usize, blocks.len());
        assert_eq!(end.overruns, 0);
        assert_eq!(result.verdict, Verdict::Ok, "{result:?}");
        // Natural frequency sqrt(k/m)/2π = 26.97 Hz (damping shifts it by < 0.01 %).
        assert!((result.frequency_hz - 26.97).abs() < 0.1, "{result:?}");
        // The thesis's stated precision of the method: μ0 ± 0.001, μ1 ± 0.0002.
        let b = result.best;
        assert!(
            (b.mu0 as f64 - true0).abs() < 1e-3,
            "μ0 {} vs {true0} ({result:?})",
            b.mu0
        );
        assert!(
            (b.mu1 as f64 - true1).abs() < 2e-4,
            "μ1 {} vs {true1} ({result:?})",
            b.mu1
        );
        // The stream starts at x0 and the displacement count decodes to it.
        let x = header.config.calibration[0].to_si(blocks[0].sample(0).unwrap()[0]);
        assert!((x - 667e-6).abs() < 3e-6, "{x}");
        // Full film: log10 R ≈ 7 while sliding once the autoranger has settled.
        let sliding: Vec<f32> = blocks[10..blocks.len() / 2]
            .iter()
            .map(|b| b.log10_ecr_ohm)
            .collect();
        assert!(
            sliding.iter().all(|l| (l - 7.0).abs() < 0.05),
            "{sliding:?}"
        );
    }
}

#[test]
fn mixed_lubrication_shows_as_a_fluctuating_ecr() {
    let cfg = VirtualRigConfig {
        ecr: tribo_rig::EcrModel {
            log10_film: 4.0,
            fluctuation_decades: 1.0,
            correlation_s: 0.01,
            log10_rest: 9.0,
        },
        ..Default::default()
    };
    let mut h = Host::new(cfg);
    let (_, blocks, _, _) = h.run(0.3);
    let all: Vec<f64> = blocks[10..blocks.len() / 2]
        .iter()
        .map(|b| b.log10_ecr_ohm as f64)
        .collect();
    // A contact that wanders over decades overruns any one range (a span of ×120) often: such a
    // block, or one whose samples were all settling from a range change, reads nothing (NaN)
    // rather than a wrong value, and the range follows. A good part of the blocks still read.
    let l: Vec<f64> = all.iter().copied().filter(|x| x.is_finite()).collect();
    assert!(3 * l.len() > all.len(), "{all:?}");
    let mean = l.iter().sum::<f64>() / l.len() as f64;
    let sd = (l.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / l.len() as f64).sqrt();
    assert!((mean - 4.0).abs() < 0.5, "{mean}");
    // Block readings are block means of an AR(1) with σ = 1 decade correlated over 10 ms (about
    // one and a half blocks): spread well above 0.3.
    assert!(sd > 0.4, "{sd}");
}

#[test]
fn heater_regulates_the_plate_and_cuts_off_when_it_overheats() {
    let mut h = Host::new(VirtualRigConfig::default());
    assert_eq!(
        h.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 45.0,
            ramp_c_per_min: 30.0
        })),
        Ok(())
    );
    h.wait(400_000);
    let t = h.rig.hardware().plate_temp_c();
    assert!((t - 45.0).abs() < 0.3, "plate at {t}");
    h.rig.hardware().set_plate_temp_c(112.0);
    h.wait(300);
    assert!(h.frames.iter().any(|f| matches!(
        f.1.msg,
        DeviceMsg::Fault(FaultReport {
            reason: FaultReason::Heater(HeaterFault::OverTemperature),
            ..
        })
    )));
    assert_eq!(h.rig.hardware().heater_duty(), 0.0);
    assert_eq!(h.rig.app().state(), RigState::Fault);
    h.rig
        .set_thermocouple_fault(Some(tribo_rig::ConverterFault::Open));
    assert_eq!(
        h.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 45.0,
            ramp_c_per_min: 30.0
        })),
        Ok(())
    );
    h.wait(400);
    assert!(h.frames.iter().any(|f| matches!(
        f.1.msg,
        DeviceMsg::Fault(FaultReport {
            reason: FaultReason::Heater(HeaterFault::OpenThermocouple),
            ..
        })
    )));
    assert_eq!(h.rig.hardware().heater_duty(), 0.0);
}

/// Asserts that every sample of every block is the one the simulated converter made at that
/// index of its stream, that blocks are numbered on and hold consecutive samples, and that the
/// samples between blocks are exactly the gaps the rig reported. Returns the samples held.
fn assert_in_place(h: &mut Host, blocks: &[SampleBlock], gaps: &[Gap]) -> u64 {
    let base = h.rig.app().run_first_index();
    let truth = h.rig.hardware().converted().expect("recording").to_vec();
    let mut next = 0u64;
    let mut gaps_seen = Vec::new();
    for (k, b) in blocks.iter().enumerate() {
        assert_eq!(b.block as usize, k);
        let first = b.first_sample as u64;
        if first != next {
            gaps_seen.push(Gap {
                run_id: b.run_id,
                first_sample: next as u32,
                count: (first - next) as u32,
            });
        }
        for i in 0..b.samples() {
            let t = truth[(base + first + i as u64) as usize];
            let want: Vec<u16> = b
                .channels
                .iter()
                .filter(|c| *c != Channel::Temperature)
                .map(|c| t[c.index()])
                .collect();
            let got: Vec<u16> = b
                .channels
                .iter()
                .zip(b.sample(i).unwrap())
                .filter(|(c, _)| *c != Channel::Temperature)
                .map(|(_, &v)| v)
                .collect();
            assert_eq!(got, want, "block {k}, sample {i}");
        }
        next = first + b.samples() as u64;
    }
    assert_eq!(
        gaps_seen, gaps,
        "the gap frames are exactly the samples missing"
    );
    blocks.iter().map(|b| b.samples() as u64).sum()
}

fn gaps_of(h: &Host) -> Vec<Gap> {
    h.frames
        .iter()
        .filter_map(|f| match f.1.msg {
            DeviceMsg::Gap(g) => Some(g),
            _ => None,
        })
        .collect()
}

#[test]
fn every_sample_is_read_in_place_across_the_ring_s_half_and_full_boundaries() {
    let mut h = Host::new(VirtualRigConfig::default());
    h.rig.hardware().record_truth(true);
    let (header, blocks, _, end) = h.run(0.3);
    assert_eq!(end.reason, EndReason::Stopped);
    assert!(gaps_of(&h).is_empty());
    let held = assert_in_place(&mut h, &blocks, &[]);
    assert_eq!(held, end.samples as u64);
    // The run went many times round the 2048-scan ring, through every half and full mark.
    let ring = tribo_firmware::acquisition::RING_SCANS as u64;
    assert!(held > 4 * ring, "{held} samples");
    assert!(header.clock.is_exactly(10_000));
}

#[test]
fn an_induced_reader_stall_is_a_gap_frame_with_the_exact_missing_samples() {
    let cfg = VirtualRigConfig {
        acquisition: tribo_rig::AcquisitionFaults {
            stall_reader_after_ms: Some(500),
            stall_reader_ms: 300,
            adc_overrun_after_ms: None,
        },
        ..Default::default()
    };
    let mut h = Host::new(cfg);
    h.rig.hardware().record_truth(true);
    let (_, blocks, result, end) = h.run(0.3);
    let gaps = gaps_of(&h);
    assert_eq!(gaps.len(), 1, "{gaps:?}");
    // 300 ms at 10 kS/s is 3000 samples; the ring kept the last 2048 of them.
    let ring = tribo_firmware::acquisition::RING_SCANS as u32;
    assert!(
        (3000 - ring - 10..=3000 - ring + 10).contains(&gaps[0].count),
        "{gaps:?}"
    );
    assert!((4_990..=5_010).contains(&gaps[0].first_sample), "{gaps:?}");
    assert_in_place(&mut h, &blocks, &gaps);
    // The run went on to its natural end, and says what it lost.
    assert_eq!(end.reason, EndReason::Stopped, "{end:?}");
    assert_eq!(end.overruns, gaps[0].count);
    // The on-board analysis used what came before the gap: still within its verdicts.
    assert!(result.cycles >= 5, "{result:?}");
}

#[test]
fn an_induced_adc_overrun_restarts_the_converter_and_is_a_gap_not_a_shift() {
    let cfg = VirtualRigConfig {
        acquisition: tribo_rig::AcquisitionFaults {
            adc_overrun_after_ms: Some(700),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut h = Host::new(cfg);
    h.rig.hardware().record_truth(true);
    let (_, blocks, _, end) = h.run(0.3);
    let gaps = gaps_of(&h);
    assert_eq!(gaps.len(), 1, "{gaps:?}");
    // The scan the overrun struck and the ones until the next 1 ms poll restarted the converter.
    assert!((1..=11).contains(&gaps[0].count), "{gaps:?}");
    assert_in_place(&mut h, &blocks, &gaps);
    assert_eq!(end.reason, EndReason::Stopped);
}

#[test]
fn a_rate_the_timer_cannot_make_is_answered_with_the_rate_used() {
    let mut h = Host::new(VirtualRigConfig::default());
    let mut c = Configure::real_rig(0.3);
    c.sample_rate_hz = 7_777;
    c.max_duration_s = 1.0;
    assert_eq!(h.command(HostMsg::Configure(c)), Ok(()));
    assert_eq!(h.command(HostMsg::Arm), Ok(()));
    h.wait(300);
    assert_eq!(h.command(HostMsg::Release), Ok(()));
    // Released 0.3 s after the boot: RunStarted waits for the boot's erase ahead (1.1 s), then
    // for the run's header to be in flash.
    h.wait(1_200);
    let header = h
        .frames
        .iter()
        .find_map(|f| match f.1.msg {
            DeviceMsg::RunStarted(h) => Some(h),
            _ => None,
        })
        .unwrap();
    // 200 MHz / 7 777 = 25 716.83 ticks: the timer counts 25 717, 7 776.95 S/s.
    assert_eq!(header.clock.ticks_per_sample, 25_717);
    assert!(!header.clock.is_exactly(7_777));
    assert!((header.clock.rate_hz() - 200e6 / 25_717.0).abs() < 1e-9);
}

#[test]
fn toml_configuration_reads_and_refuses_nonsense() {
    let c = VirtualRigConfig::from_toml(
        "load_n = 0.5\nseed = 9\n[law]\nkind = \"quadratic\"\nmu0 = 0.01\nmu1 = 0.002\nmu2 = 0.001\n[ecr]\nfluctuation_decades = 1.0\n",
    )
    .unwrap();
    assert_eq!((c.load_n, c.seed), (0.5, 9));
    assert_eq!(
        c.law,
        tribo_physics::FrictionLaw::quadratic(0.01, 0.002, 0.001)
    );
    assert_eq!(c.ecr.fluctuation_decades, 1.0);
    assert_eq!(c.mass_kg, VirtualRigConfig::default().mass_kg);
    assert_eq!(
        VirtualRigConfig::from_toml("").unwrap(),
        VirtualRigConfig::default()
    );
    for bad in [
        "mass_kg = -1.0",
        "load_n = nan",
        "lod_n = 0.3",
        "[law]\nkind = \"magic\"",
        "[noise]\nforce_n = -1.0",
        "x0_m = ",
    ] {
        assert!(VirtualRigConfig::from_toml(bad).is_err(), "{bad} accepted");
    }
}

#[test]
fn a_refused_configuration_says_which_setting_and_keeps_the_parser_s_detail_as_its_source() {
    use std::error::Error;
    use tribo_rig::RigError;
    // A law out of range is refused as the file is read; the TOML error (line, rule) is the source.
    let e = VirtualRigConfig::from_toml(
        "[law]\nkind = \"stribeck\"\nmu_c = 0.02\nmu_s = 0.03\nv_s = -1.0\ndelta = 2.0\nmu_v = 0.0\n",
    )
    .unwrap_err();
    assert!(matches!(e, RigError::Toml(_)), "{e:?}");
    let detail = e.source().map(|s| s.to_string()).unwrap_or_default();
    assert!(
        detail.contains("v_s > 0") && detail.contains("line 1"),
        "{detail}"
    );
    // A setting out of range names itself, its rule and its value.
    let e = VirtualRigConfig::from_toml("mass_kg = -1.0").unwrap_err();
    match &e {
        RigError::Setting { name, value, .. } => assert_eq!((*name, *value), ("mass_kg", -1.0)),
        other => panic!("{other:?}"),
    }
    assert_eq!(e.to_string(), "mass_kg must be a positive number, got -1");
    // Rig constants the model refuses (a NaN load cannot come through TOML, but through code).
    let cfg = VirtualRigConfig {
        load_n: f64::NAN,
        ..Default::default()
    };
    assert!(matches!(
        VirtualRig::new(cfg),
        Err(RigError::Setting { name: "load_n", .. })
    ));
}

/// Every kind `tribo rig --help` names reads from TOML as that law (the help stays true).
#[test]
fn every_law_kind_the_help_names_reads_from_toml() {
    let laws = [
        ("kind = \"coulomb\"\nmu0 = 0.02", "coulomb"),
        ("kind = \"viscous\"\nmu1 = 0.004", "viscous"),
        ("kind = \"coulomb_viscous\"\nmu0 = 0.02\nmu1 = 0.004", "coulomb-viscous"),
        ("kind = \"quadratic\"\nmu0 = 0.02\nmu1 = 0.004\nmu2 = 1e-4", "quadratic"),
        ("kind = \"polynomial\"\nmu = [0.02, 0.004, 1e-4, 1e-6]", "poly:3"),
        (
            "kind = \"stribeck\"\nmu_c = 0.02\nmu_s = 0.03\nv_s = 0.5\ndelta = 2.0\nmu_v = 0.004",
            "stribeck",
        ),
        (
            "kind = \"stribeck_power\"\nk_ehl = 0.01\nn_ehl = 0.5\nh_bl = 0.1\np_bl = 0.0\nb = 0.3\nm = 2.0",
            "stribeck-power",
        ),
        ("kind = \"hess_soom\"\nmu_b = 0.05\nc1 = 2.0\nc2 = 0.004", "hess-soom"),
        ("kind = \"dahl\"\nsigma = 100.0\nmu_c = 0.02\nalpha = 1.0", "dahl"),
        (
            "kind = \"lugre\"\nsigma0 = 200.0\nsigma1 = 2.0\nsigma2 = 0.004\nmu_c = 0.02\nmu_s = 0.03\nv_s = 1.0\na = 2.0",
            "lugre",
        ),
        (
            "kind = \"modified_lugre\"\nsigma0 = 200.0\nsigma1 = 2.0\nsigma2 = 0.004\nmu_c = 0.02\nalpha0 = 0.02\nalpha1 = 0.01\nv_s = 1.0\nl1 = 0.01\nl2 = 0.1",
            "modified-lugre",
        ),
        (
            "kind = \"lagged\"\nmemory = 0.5\n[law.steady]\nkind = \"coulomb\"\nmu0 = 0.02",
            "lagged",
        ),
    ];
    for (law, name) in laws {
        let text = format!("[law]\n{law}\n");
        let c = VirtualRigConfig::from_toml(&text).unwrap_or_else(|e| panic!("{text}: {e:?}"));
        assert_eq!(c.law.name(), name, "{text}");
    }
}
