//! The bundle generator (host only, `generate` feature): simulates the records with
//! `tribo-physics`, turns them into the 16-bit counts the rig's converters would give, runs the
//! firmware's own analysis over them on the host ([`crate::bundle::analyse`], the function the target
//! runs), and encodes the wire vectors. `cargo xtask target-test` writes the result to a file that
//! the binary embeds; `tests/host.rs` uses it in memory.

use crate::bundle::{analyse, Bytes, Header, Record, Stop, MAGIC, SAMPLE_BYTES};
use crate::tests::wire::{encode, vector};
use crate::Cost;
use tribo_firmware::analysis::{Pipeline, MU0_PRECISION, MU1_PRECISION};
use tribo_firmware::calib;
use tribo_firmware::wire::frame::MAX_FRAME;
use tribo_firmware::wire::{Channel, ChannelSet, Configure, Encoder, OnboardResult, Verdict};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec, Rng, SensorModel};
use tribo_physics::{FrictionLaw, Model, Rig};

/// Samples taken while the magnet holds the pin, before the release (0.2 s at 10 kS/s).
pub const HOLD: usize = 2_000;
/// What the ECR front end outputs during the records, V.
pub const ECR_V: f64 = 1.2;
/// Initial displacement, m (the rig's electromagnet position).
pub const X0_M: f64 = 667e-6;

/// One record to simulate.
#[derive(Debug, Clone)]
pub struct Spec {
    pub name: &'static str,
    pub about: &'static str,
    /// Normal load the analysis is configured with, N.
    pub load_n: f64,
    pub mu0: f64,
    pub mu1: f64,
    pub rate_hz: u32,
    /// The run's configured maximum duration, s.
    pub max_duration_s: f32,
    /// Seconds simulated after release (longer than the pipeline needs; the record is cut where
    /// the pipeline stopped).
    pub simulate_s: f64,
    /// The vibrometer and force sensor (noise; quantisation is the converters', below).
    pub sensor: SensorModel,
    /// Samples taken while the magnet holds the pin, before the release.
    pub hold: usize,
    /// Cubic spring coefficient k3, N/m³ (0: linear blades).
    pub k3: f64,
}

/// The records of the bundle: one unloaded, one Coulomb–viscous, one noisy; all five channels at
/// 10 kS/s through the board's converter ranges (`Configure::real_rig`).
pub fn specs() -> Vec<Spec> {
    let clean = SensorModel {
        bits: None,
        ..SensorModel::ideal()
    };
    vec![
        Spec {
            name: "unloaded",
            about:
                "apparatus alone (mu0 0, mu1 0.0011), analysed at a nominal N 0.05 N, cut at 3 s",
            load_n: 0.05,
            mu0: 0.0,
            mu1: 0.0011,
            rate_hz: 10_000,
            max_duration_s: 3.0,
            simulate_s: 3.1,
            sensor: clean.clone(),
            hold: HOLD,
            k3: 0.0,
        },
        Spec {
            name: "coulomb_viscous",
            about: "N 0.3 N, mu0 0.05, mu1 0.01, 16-bit quantisation only",
            load_n: 0.3,
            mu0: 0.05,
            mu1: 0.01,
            rate_hz: 10_000,
            max_duration_s: 5.0,
            simulate_s: 2.0,
            sensor: clean,
            hold: HOLD,
            k3: 0.0,
        },
        Spec {
            name: "noisy",
            about: "N 0.1 N, mu0 0.1, mu1 0.005, vibrometer noise twice the rig's",
            load_n: 0.1,
            mu0: 0.1,
            mu1: 0.005,
            rate_hz: 10_000,
            max_duration_s: 5.0,
            simulate_s: 2.0,
            sensor: SensorModel {
                vel_noise_m_s: 4e-5,
                bits: None,
                force_cutoff_hz: Some(300.0),
                seed: 11,
                ..SensorModel::default()
            },
            hold: HOLD,
            k3: 0.0,
        },
        // The release and the motion found where they were lost: a hold at 20 kS/s with a noisy
        // vibrometer (the first reversal was taken from the noise around the release), and a
        // spring whose stiffness depends on the amplitude (its drifting half periods were taken
        // for noise: "no oscillation").
        Spec {
            name: "held_20k",
            about: "N 0.1 N, mu0 0.05, mu1 0.004, 20 kS/s, held 0.3 s, vibrometer noise x5",
            load_n: 0.1,
            mu0: 0.05,
            mu1: 0.004,
            rate_hz: 20_000,
            max_duration_s: 5.0,
            simulate_s: 1.6,
            sensor: SensorModel {
                disp_noise_m: 1e-7,
                vel_noise_m_s: 1e-4,
                bits: None,
                force_cutoff_hz: Some(300.0),
                seed: 12,
                ..SensorModel::default()
            },
            hold: 6_000,
            k3: 0.0,
        },
        Spec {
            name: "cubic",
            about: "N 0.3 N, mu0 0.005, mu1 0.002, cubic stiffness k3 x0^2 / k = 3 %, 5 kS/s",
            load_n: 0.3,
            mu0: 0.005,
            mu1: 0.002,
            rate_hz: 5_000,
            max_duration_s: 8.0,
            simulate_s: 4.5,
            sensor: SensorModel {
                bits: None,
                seed: 13,
                ..SensorModel::default()
            },
            hold: 1_000,
            k3: 0.03 * 1150.0 / (X0_M * X0_M),
        },
        // A run of a few half-cycles (r = μ0 N / k = 61 µm of a 667 µm release): too short for
        // the averaging fit, analysed from its peaks alone (was refused: too few cycles).
        Spec {
            name: "short",
            about: "N 0.7 N, mu0 0.1, mu1 0.005, 5 kS/s, five half-cycles",
            load_n: 0.7,
            mu0: 0.1,
            mu1: 0.005,
            rate_hz: 5_000,
            max_duration_s: 5.0,
            simulate_s: 0.6,
            sensor: SensorModel {
                bits: None,
                seed: 14,
                ..SensorModel::default()
            },
            hold: 1_000,
            k3: 0.0,
        },
    ]
}

/// The configuration of a spec's run.
pub fn configure(s: &Spec) -> Configure {
    let mut c = Configure::real_rig(s.load_n as f32);
    c.sample_rate_hz = s.rate_hz;
    c.max_duration_s = s.max_duration_s;
    c.channels = ChannelSet::ALL;
    c
}

/// The counts of a spec: the hold, then the simulated motion; five channels per sample.
pub fn counts(s: &Spec, cfg: &Configure) -> Result<Vec<u8>, String> {
    let rig = Rig::new(0.04, 1150.0, s.load_n).map_err(|e| e.to_string())?;
    let model =
        Model::new(FrictionLaw::coulomb_viscous(s.mu0, s.mu1)).with_cubic(rig.kappa_of_k3(s.k3));
    let spec = RecordSpec {
        rig,
        x0_m: X0_M,
        v0_m_s: 0.0,
        duration_s: s.simulate_s,
        rate_hz: s.rate_hz as f64,
    };
    let rec = generate(&spec, &model, Method::dopri(1e-9), Some(&s.sensor))
        .map_err(|e| format!("{}: simulation failed: {e}", s.name))?;
    let cal = cfg.calibration;
    let count = |ch: Channel, si: f64| -> Result<u16, String> {
        calib::to_count(cal[ch.index()], si).ok_or_else(|| format!("bad {ch:?} calibration"))
    };
    let temp = cal[Channel::Temperature.index()].to_count(crate::tests::app::TEMP_C);
    let mut out = Vec::with_capacity((s.hold + rec.len()) * SAMPLE_BYTES);
    let mut push = |x: f64, v: f64, f: f64, ecr: f64| -> Result<(), String> {
        let s = [
            count(Channel::Displacement, x)?,
            count(Channel::Velocity, v)?,
            count(Channel::Force, f)?,
            count(Channel::Ecr, ecr)?,
            temp,
        ];
        for c in s {
            out.extend_from_slice(&c.to_le_bytes());
        }
        Ok(())
    };
    // The hold: the pin at rest at x0, with the sensors' noise.
    let mut rng = Rng::new(s.sensor.seed ^ 0x5EED);
    let sn = &s.sensor;
    for _ in 0..s.hold {
        push(
            X0_M + sn.disp_noise_m * rng.normal(),
            sn.vel_noise_m_s * rng.normal(),
            sn.force_noise_n * rng.normal(),
            ECR_V + 1e-4 * rng.normal(),
        )?;
    }
    let ft = rec.ft.as_ref();
    for i in 0..rec.len() {
        let f = ft.and_then(|f| f.get(i)).copied().unwrap_or(0.0);
        push(rec.x[i], rec.v[i], f, ECR_V + 1e-4 * rng.normal())?;
    }
    Ok(out)
}

/// The host's analysis of a record (no measurement).
fn host_analysis(rec: &Record<'_>) -> Result<crate::bundle::Analysis, String> {
    let mut p = Pipeline::new(&rec.configure).map_err(|e| format!("{}: {e}", rec.name))?;
    analyse(rec, &mut p, &mut |f| {
        f();
        Cost::default()
    })
    .map(|(a, _)| a)
    .map_err(|e| format!("{}: {e}", rec.name))
}

/// The whole bundle, ready to embed.
pub fn bundle() -> Result<Vec<u8>, String> {
    let mut frames = Vec::new();
    let mut enc = Encoder::new();
    let mut buf = [0u8; MAX_FRAME];
    let mut i = 0;
    while let Some((seq, v)) = vector(i) {
        let n = encode(&mut enc, seq, &v, &mut buf).ok_or(format!("vector {i} does not encode"))?;
        frames.extend_from_slice(&buf[..n]);
        i += 1;
    }
    let specs = specs();
    let mut records = Vec::new();
    for s in &specs {
        let cfg = configure(s);
        cfg.validate()
            .map_err(|f| format!("{}: configuration out of range: {f:?}", s.name))?;
        let mut data = counts(s, &cfg)?;
        let placeholder = crate::bundle::Analysis {
            pushed: 0,
            half_cycles: 0,
            stop: Stop::NotFinished,
            result: unanalysed(),
        };
        let rec_template = Record {
            name: s.name,
            about: s.about,
            configure: cfg,
            mu0: s.mu0,
            mu1: s.mu1,
            hold: s.hold as u32,
            counts: Bytes(&[]),
            host: placeholder,
        };
        let a = host_analysis(&Record {
            counts: Bytes(&data),
            ..rec_template
        })?;
        if a.stop == Stop::NotFinished {
            return Err(format!(
                "{}: the pipeline had not stopped after {} s of simulated motion: simulate longer",
                s.name, s.simulate_s
            ));
        }
        // The physics check: a bundle whose host result is wrong would make target == host prove
        // little.
        let r = a.result;
        let (d0, d1) = (
            (r.best.mu0 as f64 - s.mu0).abs(),
            (r.best.mu1 as f64 - s.mu1).abs(),
        );
        if r.verdict != Verdict::Ok || d0 > MU0_PRECISION || d1 > MU1_PRECISION {
            return Err(format!(
                "{}: the host's analysis is off the simulated law (|Δμ0| {d0:e}, |Δμ1| {d1:e}): {r:?}",
                s.name
            ));
        }
        // Keep the hold and what the pipeline took (the replay repeats the last sample after).
        data.truncate((s.hold + a.pushed as usize) * SAMPLE_BYTES);
        let rec = Record {
            counts: Bytes(&data),
            host: a,
            ..rec_template
        };
        let bytes = postcard::to_allocvec(&rec).map_err(|e| format!("{}: {e}", s.name))?;
        records.push(bytes);
    }
    let header = Header {
        magic: MAGIC,
        frames: Bytes(&frames),
        records: records.len() as u32,
    };
    let mut out = postcard::to_allocvec(&header).map_err(|e| format!("header: {e}"))?;
    for r in records {
        out.extend_from_slice(&r);
    }
    Ok(out)
}

fn unanalysed() -> OnboardResult {
    let none = tribo_firmware::wire::Estimate {
        mu0: f32::NAN,
        mu1: f32::NAN,
        mu0_se: f32::NAN,
        mu1_se: f32::NAN,
    };
    OnboardResult {
        run_id: 0,
        verdict: Verdict::NotAnalysed,
        cycles: 0,
        frequency_hz: f32::NAN,
        initial_amplitude_m: f32::NAN,
        duration_s: f32::NAN,
        best: none,
        averaging: none,
        decrement: none,
        shape: tribo_firmware::wire::EnvelopeShape::Straight,
        curvature: f32::NAN,
    }
}
