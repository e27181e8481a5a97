//! `tribo sim`: generate a record (CSV) of the rig's free response from a chosen friction law.

use anyhow::{Context, Result};
use clap::Parser;
use std::path::PathBuf;
use tribo_physics::bench::{Bench, BenchRecord};
use tribo_physics::identify::LawSpec;
use tribo_physics::integrate::Method;
use tribo_physics::law::FrictionLaw;
use tribo_physics::record::{Record, Units};
use tribo_physics::sensor::{generate, Ecr, RecordSpec, SensorModel, Thermal};
use tribo_physics::{Model, Rig};

/// Simulate the rig's free damped oscillation and write it as a record.
///
/// The model is `m x'' + c x' + k x = −N μ(v)` with μ given by `--law` and its dimensionless constants
/// `--mu μ0,μ1,…` (seed eq. 10–13: f = Σ μ_j y'^j, y = k x / N, τ = Ω t). Defaults are the real
/// rig: m = 0.04 kg, k = 1150 N/m, N = 0.3 N, released from 667 µm at rest, 4 s at 10 kHz.
///
/// Example: `tribo sim --law coulomb-viscous --mu 0.02,0.01 --load-n 0.3 --noise -o rec.csv`
/// then `tribo fit rec.csv --law coulomb-viscous`.
#[derive(Parser, Debug)]
pub struct Args {
    /// Friction law: coulomb, viscous, coulomb-viscous, quadratic, poly:N or lugre.
    #[arg(long, default_value = "coulomb-viscous")]
    pub law: LawSpec,
    /// Dimensionless constants μ0,μ1,… in order of j (for `viscous` give μ1 alone; for `lugre`:
    /// μ_c,μ_s,σ2 with σ0, σ1, v_s fixed as in `tribo fit`).
    #[arg(
        long,
        value_delimiter = ',',
        allow_hyphen_values = true,
        default_value = "0.02,0.01"
    )]
    pub mu: Vec<f64>,
    /// Moving mass m (kg).
    #[arg(long, default_value_t = 0.04)]
    pub mass_kg: f64,
    /// Blade stiffness k (N/m).
    #[arg(long, default_value_t = 1150.0)]
    pub stiffness: f64,
    /// Normal load N (N).
    #[arg(long, default_value_t = 0.3)]
    pub load_n: f64,
    /// Initial displacement x0 (m).
    #[arg(long, default_value_t = 667e-6)]
    pub x0_m: f64,
    /// Duration (s).
    #[arg(long, default_value_t = 4.0)]
    pub duration_s: f64,
    /// Sampling rate (Hz).
    #[arg(long, default_value_t = 10000.0)]
    pub rate_hz: f64,
    /// Apparatus viscous damping μ_a (dimensionless, = 2ζ; the real apparatus ≈ 0.0011).
    #[arg(long, default_value_t = 0.0)]
    pub apparatus_mu1: f64,
    /// Cubic spring coefficient k3 (N/m³).
    #[arg(long, default_value_t = 0.0)]
    pub k3: f64,
    /// Add the real acquisition chain: vibrometer noise, 300 Hz force low-pass, 16-bit quantisation.
    #[arg(long)]
    pub noise: bool,
    /// ADC bits (with --noise); 0 = no quantisation.
    #[arg(long, default_value_t = 16)]
    pub bits: u32,
    /// Displacement noise (m, standard deviation, with --noise).
    #[arg(long, default_value_t = 2e-8)]
    pub disp_noise_m: f64,
    /// Velocity noise (m/s, with --noise).
    #[arg(long, default_value_t = 2e-5)]
    pub vel_noise_m_s: f64,
    /// Force-channel lag (s, with --noise), e.g. 0.003.
    #[arg(long, default_value_t = 0.0)]
    pub force_lag_s: f64,
    /// Add a thermocouple column at this temperature (°C).
    #[arg(long)]
    pub temp_c: Option<f64>,
    /// Add an ECR column: log10(Ω) while sliding (≈ 7 full film).
    #[arg(long)]
    pub ecr_log10: Option<f64>,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// A bench's hold: the record starts this long before the release (s), the carriage held at
    /// x0 by the magnet; `--duration-s` counts from the release.
    #[arg(long, default_value_t = 0.0)]
    pub held_s: f64,
    /// A bench's speckle dropouts: single-sample spikes in the velocity channel, per second.
    #[arg(long, default_value_t = 0.0)]
    pub dropouts_per_s: f64,
    /// A bench's floor motion seen by the vibrometer: amplitude (m) of a slow sine.
    #[arg(long, default_value_t = 0.0)]
    pub floor_m: f64,
    /// Frequency of the floor motion (Hz).
    #[arg(long, default_value_t = 7.0)]
    pub floor_hz: f64,
    /// Write the dimensionless form `tau,y,ydot` instead of SI.
    #[arg(long)]
    pub dimensionless: bool,
    /// Output CSV file (`-`: standard output).
    #[arg(short, long)]
    pub output: PathBuf,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
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

/// Runs `tribo sim`.
pub fn run(a: Args) -> Result<()> {
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
    if a.output.as_os_str() == "-" {
        // `-o -`: the CSV on standard output (a pipe into another tool).
        crate::out!("{}", rec.to_csv_string())?;
    } else {
        rec.save(&a.output)
            .with_context(|| format!("writing {}", a.output.display()))?;
    }
    if !a.quiet {
        crate::errln!(
            "wrote {} samples ({} law, μ = {:?}) to {}",
            rec.len(),
            model.law.name(),
            a.mu,
            a.output.display()
        );
    }
    Ok(())
}
