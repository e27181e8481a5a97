//! The firmware application against the simulated rig, end to end, through wire frames (how the
//! rig is served to a host: `serve.rs`).

use tribo_rig::{LawConfig, VirtualRig, VirtualRigConfig};
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

    fn wait(&mut self, ms: u64) {
        let t = self.rig.now_us() + ms * 1000;
        self.rig.advance_to(t);
        self.collect();
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
                DeviceMsg::Samples(b) => blocks.push(b.clone()),
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
            law: LawConfig::CoulombViscous { mu0, mu1 },
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
    let l: Vec<f64> = blocks[10..blocks.len() / 2]
        .iter()
        .map(|b| b.log10_ecr_ohm as f64)
        .collect();
    let mean = l.iter().sum::<f64>() / l.len() as f64;
    let sd = (l.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / l.len() as f64).sqrt();
    assert!((mean - 4.0).abs() < 0.5, "{mean}");
    // Block readings are instantaneous values of an AR(1) with σ = 1 decade: spread well above 0.3.
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
        DeviceMsg::Error(DeviceError {
            code: ErrorCode::Heater(HeaterFault::OverTemperature),
            about_seq: None
        })
    )));
    assert_eq!(h.rig.hardware().heater_duty(), 0.0);
    assert_eq!(h.rig.app().state(), RigState::Fault);
    h.rig
        .set_thermocouple_fault(Some(tribo_firmware::hal::ThermocoupleFault::Open));
    assert_eq!(
        h.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 45.0,
            ramp_c_per_min: 30.0
        })),
        Ok(())
    );
    h.wait(300);
    assert!(h.frames.iter().any(|f| matches!(
        f.1.msg,
        DeviceMsg::Error(DeviceError {
            code: ErrorCode::Heater(HeaterFault::OpenThermocouple),
            ..
        })
    )));
    assert_eq!(h.rig.hardware().heater_duty(), 0.0);
}

#[test]
fn an_overrun_in_the_simulated_converter_is_reported() {
    let mut h = Host::new(VirtualRigConfig::default());
    let mut c = Configure::real_rig(0.3);
    c.max_duration_s = 6.0;
    assert_eq!(h.command(HostMsg::Configure(c)), Ok(()));
    assert_eq!(h.command(HostMsg::Arm), Ok(()));
    h.wait(100);
    assert_eq!(h.command(HostMsg::Release), Ok(()));
    h.wait(100);
    h.rig.hardware().flood(5000);
    let lost = h.rig.hardware().lost();
    assert!(lost > 0);
    h.wait(10);
    assert!(h.frames.iter().any(|f| f.1.msg
        == DeviceMsg::Error(DeviceError {
            code: ErrorCode::Overrun { lost_samples: lost },
            about_seq: None
        })));
    let end = h
        .frames
        .iter()
        .find_map(|f| {
            if let DeviceMsg::RunEnded(e) = f.1.msg {
                Some(e)
            } else {
                None
            }
        })
        .unwrap();
    assert_eq!((end.reason, end.overruns), (EndReason::Overrun, lost));
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
        LawConfig::Quadratic {
            mu0: 0.01,
            mu1: 0.002,
            mu2: 0.001
        }
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
