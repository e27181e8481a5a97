//! A simulated record (`tribo sim`, the Python package's `simulate`): the rig's free damped
//! oscillation under a friction law, with the acquisition chain and a bench's faults when asked.

use anyhow::Result;
use serde::Deserialize;
use tribo_physics::bench::{Bench, BenchRecord};
use tribo_physics::identify::LawSpec;
use tribo_physics::integrate::Method;
use tribo_physics::law::FrictionLaw;
use tribo_physics::record::{Record, Units};
use tribo_physics::sensor::{generate, Ecr, RecordSpec, SensorModel, Thermal};
use tribo_physics::{Model, Rig};

/// What to simulate: `tribo sim`'s options (the same names, without `--` and with `_`), each
/// documented there; [`Default`] is `tribo sim`'s defaults, the real rig.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimOptions {
    /// Friction law: coulomb, viscous, coulomb-viscous, quadratic, poly:N or lugre.
    pub law: LawSpec,
    /// Dimensionless constants μ0, μ1, … in order of j.
    pub mu: Vec<f64>,
    /// Moving mass m (kg).
    pub mass_kg: f64,
    /// Blade stiffness k (N/m).
    pub stiffness: f64,
    /// Normal load N (N).
    pub load_n: f64,
    /// Initial displacement x0 (m).
    pub x0_m: f64,
    /// Duration (s).
    pub duration_s: f64,
    /// Sampling rate (Hz).
    pub rate_hz: f64,
    /// Apparatus viscous damping μ_a (dimensionless, = 2ζ).
    pub apparatus_mu1: f64,
    /// Cubic spring coefficient k3 (N/m³).
    pub k3: f64,
    /// Add the real acquisition chain: vibrometer noise, force low-pass, quantisation.
    pub noise: bool,
    /// ADC bits (with `noise`); 0: no quantisation.
    pub bits: u32,
    /// Displacement noise (m, standard deviation, with `noise`).
    pub disp_noise_m: f64,
    /// Velocity noise (m/s, with `noise`).
    pub vel_noise_m_s: f64,
    /// Force-channel lag (s, with `noise`).
    pub force_lag_s: f64,
    /// A thermocouple column at this temperature (°C).
    pub temp_c: Option<f64>,
    /// An ECR column: log10(Ω) while sliding.
    pub ecr_log10: Option<f64>,
    /// Noise seed.
    pub seed: u64,
    /// A bench's hold: the record starts this long before the release (s).
    pub held_s: f64,
    /// A bench's speckle dropouts: single-sample velocity spikes per second.
    pub dropouts_per_s: f64,
    /// A bench's floor motion: amplitude (m) of a slow sine.
    pub floor_m: f64,
    /// Frequency of the floor motion (Hz).
    pub floor_hz: f64,
    /// Write the dimensionless form `tau,y,ydot` instead of SI.
    pub dimensionless: bool,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            law: LawSpec::CoulombViscous,
            mu: vec![0.02, 0.01],
            mass_kg: 0.04,
            stiffness: 1150.0,
            load_n: 0.3,
            x0_m: 667e-6,
            duration_s: 4.0,
            rate_hz: 10000.0,
            apparatus_mu1: 0.0,
            k3: 0.0,
            noise: false,
            bits: 16,
            disp_noise_m: 2e-8,
            vel_noise_m_s: 2e-5,
            force_lag_s: 0.0,
            temp_c: None,
            ecr_log10: None,
            seed: 1,
            held_s: 0.0,
            dropouts_per_s: 0.0,
            floor_m: 0.0,
            floor_hz: 7.0,
            dimensionless: false,
        }
    }
}

/// The law of `--law` with constants `--mu`.
pub fn law_of(spec: LawSpec, mu: &[f64]) -> Result<FrictionLaw> {
    let need = match spec {
        LawSpec::Viscous => 1,
        s => s.n_params(),
    };
    if mu.len() != need {
        // The user's word against the law's: a usage error (status 2), as clap's own are.
        return Err(crate::exit::Usage(format!(
            "law {spec} needs {need} constant(s) in --mu, got {}",
            mu.len()
        ))
        .into());
    }
    Ok(match spec {
        LawSpec::Viscous => FrictionLaw::viscous(mu[0]),
        s => s.law(mu),
    })
}

/// The simulated record and the model it was made with. A value out of range is a
/// [`crate::exit::Usage`] error (status 2), as on the command line.
pub fn simulate(a: &SimOptions) -> Result<(Record, Model)> {
    let rig = Rig::new(a.mass_kg, a.stiffness, a.load_n)?;
    let law = law_of(a.law, &a.mu)?;
    let model = Model::new(law)
        .with_apparatus_damping(a.apparatus_mu1)
        .with_cubic(rig.kappa_of_k3(a.k3));
    model.validate()?;
    let spec = RecordSpec {
        rig,
        x0_m: a.x0_m,
        v0_m_s: 0.0,
        duration_s: a.duration_s,
        rate_hz: a.rate_hz,
    };
    let sensor = if a.noise || a.temp_c.is_some() || a.ecr_log10.is_some() {
        let base = if a.noise {
            SensorModel {
                bits: (a.bits > 0).then_some(a.bits),
                disp_noise_m: a.disp_noise_m,
                vel_noise_m_s: a.vel_noise_m_s,
                force_lag_s: a.force_lag_s,
                ..SensorModel::default()
            }
        } else {
            SensorModel::ideal()
        };
        Some(SensorModel {
            thermal: a.temp_c.map(|t| Thermal {
                start_c: t,
                drift_c_per_s: 0.0,
                noise_c: if a.noise { 0.05 } else { 0.0 },
            }),
            ecr: a.ecr_log10.map(|l| Ecr {
                log10_sliding: l,
                log10_rest: 3.0,
                fluctuation_decades: 0.0,
            }),
            seed: a.seed,
            ..base
        })
    } else {
        None
    };
    for (name, v) in [
        ("--held-s", a.held_s),
        ("--dropouts-per-s", a.dropouts_per_s),
        ("--floor-m", a.floor_m),
        ("--floor-hz", a.floor_hz),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(
                crate::exit::Usage(format!("{name} must be finite and ≥ 0 (got {v})")).into(),
            );
        }
    }
    let bench = Bench {
        held_s: a.held_s,
        dropouts_per_s: a.dropouts_per_s,
        floor_m: a.floor_m,
        floor_hz: a.floor_hz,
        ..Bench::default()
    };
    let mut rec = if bench == Bench::default() {
        generate(&spec, &model, Method::default(), sensor.as_ref())?
    } else {
        BenchRecord {
            rig,
            model: model.clone(),
            x0_m: a.x0_m,
            after_release_s: a.duration_s,
            rate_hz: a.rate_hz,
            sensor: sensor.clone().unwrap_or_else(|| SensorModel {
                seed: a.seed,
                ..SensorModel::ideal()
            }),
            bench,
        }
        .make()?
    };
    if a.dimensionless {
        let (t, y, v) = rec.dimensionless()?;
        rec = Record::new(t, y, v, Some(Rig::UNIT), Units::Dimensionless);
    }
    Ok((rec, model))
}
