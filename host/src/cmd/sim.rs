//! `tribo sim`: generate a record (CSV) of the rig's free response from a chosen friction law.

use crate::simulate::{simulate, SimOptions};
use anyhow::{Context, Result};
use clap::Parser;
use std::path::PathBuf;
use tribo_physics::identify::LawSpec;

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

impl Args {
    /// The simulation these arguments ask for.
    pub fn options(&self) -> SimOptions {
        SimOptions {
            law: self.law,
            mu: self.mu.clone(),
            mass_kg: self.mass_kg,
            stiffness: self.stiffness,
            load_n: self.load_n,
            x0_m: self.x0_m,
            duration_s: self.duration_s,
            rate_hz: self.rate_hz,
            apparatus_mu1: self.apparatus_mu1,
            k3: self.k3,
            noise: self.noise,
            bits: self.bits,
            disp_noise_m: self.disp_noise_m,
            vel_noise_m_s: self.vel_noise_m_s,
            force_lag_s: self.force_lag_s,
            temp_c: self.temp_c,
            ecr_log10: self.ecr_log10,
            seed: self.seed,
            held_s: self.held_s,
            dropouts_per_s: self.dropouts_per_s,
            floor_m: self.floor_m,
            floor_hz: self.floor_hz,
            dimensionless: self.dimensionless,
        }
    }
}

/// Runs `tribo sim`.
pub fn run(a: Args) -> Result<()> {
    let (rec, model) = simulate(&a.options())?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// `tribo sim`'s defaults are the library's: the Python package simulates with the latter.
    #[test]
    fn the_command_line_defaults_are_the_librarys() {
        let a = Args::try_parse_from(["sim", "-o", "x.csv"]).unwrap();
        assert_eq!(a.options(), SimOptions::default());
    }
}
