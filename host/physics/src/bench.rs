//! Records made the way a lab bench makes them (`shared/docs/real-bench.md`): the simulator's free
//! response, then what a bench adds around and on top of it, each row on its own switch:
//!
//! - the magnet's hold before the release (the record starts `held_s` early: displacement at `x0`,
//!   velocity zero, both with their noise) and the seconds at rest after the stop (the duration);
//! - vibrometer noise and 16-bit quantisation and clipping over the channels' ranges
//!   ([`SensorModel`]), the force channel's low-pass, lag and noise;
//! - speckle dropouts: isolated spikes in the velocity channel;
//! - floor motion: a slow sine (1–20 Hz) of the whole rig seen by the vibrometer;
//! - mains pickup on the force channel (50 Hz and its third harmonic);
//! - a thermocouple ramp.
//!
//! [`grid`] is the grid every estimator is checked over: noise levels × contacts (friction
//! laws and loads) × rigs × sample rates × seeds.

use crate::integrate::{Method, SimError};
use crate::law::FrictionLaw;
use crate::model::{Model, Rig};
use crate::record::Record;
use crate::sensor::{generate, RecordSpec, SensorModel, Thermal};
use crate::stats::Rng;
use std::f64::consts::PI;

/// What a bench adds beyond the acquisition chain.
#[derive(Debug, Clone, PartialEq)]
pub struct Bench {
    /// Time the record runs before the release, while the magnet holds (s).
    pub held_s: f64,
    /// Speckle dropouts per second: single-sample spikes in the velocity channel of up to the
    /// channel's full scale.
    pub dropouts_per_s: f64,
    /// Floor motion amplitude (m) seen on the displacement (and its derivative on the velocity).
    pub floor_m: f64,
    /// Floor motion frequency (Hz).
    pub floor_hz: f64,
    /// Mains pickup on the force channel (N amplitude at 50 Hz, a third of it at 150 Hz).
    pub mains_n: f64,
}

impl Default for Bench {
    /// Nothing beyond the acquisition chain.
    fn default() -> Self {
        Bench {
            held_s: 0.0,
            dropouts_per_s: 0.0,
            floor_m: 0.0,
            floor_hz: 7.0,
            mains_n: 0.0,
        }
    }
}

/// One bench record to make.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchRecord {
    /// Rig constants.
    pub rig: Rig,
    /// The contact.
    pub model: Model,
    /// Release displacement (m).
    pub x0_m: f64,
    /// Time after the release (s).
    pub after_release_s: f64,
    /// Sampling rate (Hz).
    pub rate_hz: f64,
    /// Acquisition chain (noise, quantisation, force channel, thermocouple).
    pub sensor: SensorModel,
    /// What the bench adds.
    pub bench: Bench,
}

impl BenchRecord {
    /// Makes the record: SI, with the force channel, `t = 0` at the start of the hold.
    pub fn make(&self) -> Result<Record, SimError> {
        let spec = RecordSpec {
            rig: self.rig,
            x0_m: self.x0_m,
            v0_m_s: 0.0,
            duration_s: self.after_release_s,
            rate_hz: self.rate_hz,
        };
        let motion = generate(&spec, &self.model, Method::dopri(1e-10), None)?;
        let dt = 1.0 / self.rate_hz;
        let held = (self.bench.held_s * self.rate_hz).round() as usize;
        let n = held + motion.len();
        let mut x = vec![self.x0_m; held];
        x.extend_from_slice(&motion.x);
        let mut v = vec![0.0; held];
        v.extend_from_slice(&motion.v);
        let f_true: Vec<f64> = std::iter::repeat_n(0.0, held)
            .chain(motion.ft.clone().unwrap_or_default())
            .collect();
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let b = &self.bench;
        if b.floor_m > 0.0 {
            let w = 2.0 * PI * b.floor_hz;
            for (i, (xi, vi)) in x.iter_mut().zip(v.iter_mut()).enumerate() {
                let ph = w * t[i] + 0.7;
                *xi += b.floor_m * ph.sin();
                *vi += b.floor_m * w * ph.cos();
            }
        }
        let mut rec = Record::new(t, x, v, Some(self.rig), crate::record::Units::Si);
        let stuck = vec![false; n];
        self.sensor.apply(&mut rec, &f_true, &stuck);
        let mut rng = Rng::new(self.sensor.seed ^ 0x5eed_5eed);
        if b.mains_n > 0.0 {
            if let Some(f) = rec.ft.as_mut() {
                for (i, fi) in f.iter_mut().enumerate() {
                    let ph = 2.0 * PI * 50.0 * i as f64 * dt;
                    *fi += b.mains_n * (ph.sin() + (3.0 * ph + 0.4).sin() / 3.0);
                }
            }
        }
        if b.dropouts_per_s > 0.0 {
            let p = b.dropouts_per_s * dt;
            let range = self.sensor.vel_range_m_s;
            for vi in rec.v.iter_mut() {
                if rng.uniform() < p {
                    *vi = range * (2.0 * rng.uniform() - 1.0);
                }
            }
        }
        Ok(rec)
    }
}

/// A vibrometer noise level of the grid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseLevel {
    /// Name in tables.
    pub name: &'static str,
    /// Displacement noise (m RMS).
    pub disp_m: f64,
    /// Velocity noise (m/s RMS).
    pub vel_m_s: f64,
}

/// The noise levels of `real-bench.md`, from the simulator's default to the noisiest bench.
pub const NOISE_LEVELS: [NoiseLevel; 4] = [
    NoiseLevel {
        name: "x1",
        disp_m: 2e-8,
        vel_m_s: 2e-5,
    },
    NoiseLevel {
        name: "x5",
        disp_m: 1e-7,
        vel_m_s: 1e-4,
    },
    NoiseLevel {
        name: "x15",
        disp_m: 3e-7,
        vel_m_s: 2.5e-4,
    },
    NoiseLevel {
        name: "x50",
        disp_m: 1e-6,
        vel_m_s: 5e-4,
    },
];

/// A contact of the grid: a law at a load.
#[derive(Debug, Clone, PartialEq)]
pub struct Contact {
    /// Name in tables.
    pub name: &'static str,
    /// The law.
    pub law: FrictionLaw,
    /// Normal load (N).
    pub load_n: f64,
}

/// The contacts of the grid: Coulomb–viscous from μ0 = 1e-4 to 0.1 over loads 0.05–0.7 N, and a
/// quadratic contact with the thesis's sign pattern (μ1 < 0, μ2 > 0).
pub fn contacts() -> Vec<Contact> {
    vec![
        Contact {
            name: "cv-1e-4",
            law: FrictionLaw::coulomb_viscous(1e-4, 0.006),
            load_n: 0.3,
        },
        Contact {
            name: "cv-0.008",
            law: FrictionLaw::coulomb_viscous(0.008, 0.004),
            load_n: 0.05,
        },
        Contact {
            name: "cv-0.02",
            law: FrictionLaw::coulomb_viscous(0.02, 0.01),
            load_n: 0.3,
        },
        Contact {
            name: "cv-0.1",
            law: FrictionLaw::coulomb_viscous(0.1, 0.002),
            load_n: 0.7,
        },
        Contact {
            name: "quad",
            law: FrictionLaw::quadratic(0.02, -0.004, 0.003),
            load_n: 0.3,
        },
    ]
}

/// The rigs of the grid: the 20 and 45 Hz ends of the range (60 g on 950 N/m blades, 30 g on
/// 2400 N/m).
pub fn rigs(load_n: f64) -> Vec<(&'static str, Rig)> {
    [("20Hz", 0.06, 950.0), ("45Hz", 0.03, 2400.0)]
        .into_iter()
        .map(|(n, m, k)| (n, Rig::new(m, k, load_n).expect("grid rig")))
        .collect()
}

/// Sample rates of the grid (Hz).
pub const RATES_HZ: [f64; 3] = [2_000.0, 10_000.0, 20_000.0];

/// Time after the release a grid record covers: until the Coulomb–viscous envelope of its law's
/// first two constants falls to 1 % of the release amplitude (or 400 cycles), then `rest_s` at
/// rest; at most 12 s.
pub fn after_release_s(rig: &Rig, law: &FrictionLaw, x0_m: f64, rest_s: f64) -> f64 {
    let mu = law
        .mu()
        .map(<[f64]>::to_vec)
        .unwrap_or_else(|| vec![0.02, 0.0]);
    let (mu0, mu1) = (
        mu.first().copied().unwrap_or(0.0).abs(),
        mu.get(1).copied().unwrap_or(0.0).abs(),
    );
    let y0 = rig.y_of_x(x0_m);
    let mut tau = 0.0;
    let limit = 400.0 * 2.0 * PI;
    while tau < limit && crate::envelope::coulomb_viscous_envelope(y0, mu0, mu1, tau) > 0.01 * y0 {
        tau += 0.5;
    }
    (rig.t_of_tau(tau) + rest_s).min(12.0)
}

/// One cell of the grid, ready to make.
#[derive(Debug, Clone)]
pub struct GridCase {
    /// Noise level.
    pub noise: NoiseLevel,
    /// Contact.
    pub contact: Contact,
    /// Rig name.
    pub rig_name: &'static str,
    /// The record to make.
    pub record: BenchRecord,
}

/// The grid: every noise level × contact × rig × rate × seed, each record held `held_s` before the
/// release and ending with `rest_s` at rest.
pub fn grid(seeds: std::ops::Range<u64>, held_s: f64, rest_s: f64) -> Vec<GridCase> {
    let mut out = Vec::new();
    for noise in NOISE_LEVELS {
        for contact in contacts() {
            for (rig_name, rig) in rigs(contact.load_n) {
                for rate in RATES_HZ {
                    for seed in seeds.clone() {
                        let x0 = 667e-6;
                        let sensor = SensorModel {
                            disp_noise_m: noise.disp_m,
                            vel_noise_m_s: noise.vel_m_s,
                            seed: seed * 7919 + (rate as u64),
                            thermal: Some(Thermal {
                                start_c: 25.0,
                                drift_c_per_s: 0.0,
                                noise_c: 0.05,
                            }),
                            ..SensorModel::default()
                        };
                        out.push(GridCase {
                            noise,
                            contact: contact.clone(),
                            rig_name,
                            record: BenchRecord {
                                rig,
                                model: Model::new(contact.law.clone()),
                                x0_m: x0,
                                after_release_s: after_release_s(&rig, &contact.law, x0, rest_s),
                                rate_hz: rate,
                                sensor,
                                bench: Bench {
                                    held_s,
                                    ..Bench::default()
                                },
                            },
                        });
                    }
                }
            }
        }
    }
    out
}
