//! Sensor model for generated records, and the record generator.
//!
//! Channels as on the rig (chapter 2.2): laser vibrometer displacement and velocity (white noise),
//! 16-bit quantisation over each channel's full scale, piezo + charge-amplifier force channel with its
//! 300 Hz low-pass (2nd-order Butterworth) and an optional time lag (~3 ms observed, ch. 4.4),
//! thermocouple (drift + noise) and ECR (log10 Ω: steady high while a film separates the surfaces,
//! fluctuating by `fluctuation_decades` otherwise).

use crate::integrate::{simulate, Method, SimError};
use crate::invalid::InvalidParameter;
use crate::model::{Model, Rig};
use crate::record::{Record, Units};

// The generator lives with the other shared maths; it stays reachable here, where it always was.
pub use crate::stats::Rng;

/// Thermocouple channel: `T(t) = start_c + drift_c_per_s · t + noise`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Thermal {
    /// Initial temperature (°C).
    pub start_c: f64,
    /// Drift (°C/s).
    pub drift_c_per_s: f64,
    /// Noise standard deviation (°C).
    pub noise_c: f64,
}

/// ECR channel (Ω): `log10 R` is `log10_sliding` (+ Gaussian fluctuation of
/// `fluctuation_decades`) while sliding and `log10_rest` once stuck.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ecr {
    /// log10 R while sliding (≈ 7 for a full film).
    pub log10_sliding: f64,
    /// log10 R at rest after the stop.
    pub log10_rest: f64,
    /// Standard deviation of log10 R while sliding (0 = full film; ~1 = mixed).
    pub fluctuation_decades: f64,
}

/// Acquisition chain. `SensorModel::default()` is the real rig (16 bits, NI USB-6221 ranges).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorModel {
    /// Displacement noise, standard deviation (m).
    pub disp_noise_m: f64,
    /// Velocity noise, standard deviation (m/s).
    pub vel_noise_m_s: f64,
    /// Force noise, standard deviation (N).
    pub force_noise_n: f64,
    /// ADC resolution in bits (`None` = no quantisation).
    pub bits: Option<u32>,
    /// Displacement full scale ± (m).
    pub disp_range_m: f64,
    /// Velocity full scale ± (m/s).
    pub vel_range_m_s: f64,
    /// Force full scale ± (N).
    pub force_range_n: f64,
    /// Charge-amplifier low-pass cut-off (Hz), `None` = none.
    pub force_cutoff_hz: Option<f64>,
    /// Force channel time lag (s).
    pub force_lag_s: f64,
    /// Thermocouple channel, if any.
    pub thermal: Option<Thermal>,
    /// ECR channel, if any.
    pub ecr: Option<Ecr>,
    /// Seed of the noise.
    pub seed: u64,
}

impl Default for SensorModel {
    fn default() -> Self {
        SensorModel {
            disp_noise_m: 2e-8,
            vel_noise_m_s: 2e-5,
            force_noise_n: 2e-4,
            bits: Some(16),
            disp_range_m: 1e-3,
            vel_range_m_s: 0.2,
            force_range_n: 1.0,
            force_cutoff_hz: Some(300.0),
            force_lag_s: 0.0,
            thermal: None,
            ecr: None,
            seed: 1,
        }
    }
}

impl SensorModel {
    /// A perfect chain: no noise, no quantisation, no filter, no lag, no extra channels.
    pub fn ideal() -> SensorModel {
        SensorModel {
            disp_noise_m: 0.0,
            vel_noise_m_s: 0.0,
            force_noise_n: 0.0,
            bits: None,
            force_cutoff_hz: None,
            ..SensorModel::default()
        }
    }

    /// Checks ranges and finiteness.
    pub fn validate(&self) -> Result<(), InvalidParameter> {
        let vals = [
            self.disp_noise_m,
            self.vel_noise_m_s,
            self.force_noise_n,
            self.disp_range_m,
            self.vel_range_m_s,
            self.force_range_n,
            self.force_lag_s,
        ];
        if vals.iter().any(|v| !v.is_finite() || *v < 0.0) {
            return Err(InvalidParameter::SensorLevels);
        }
        if let Some(b) = self.bits {
            if !(2..=32).contains(&b) {
                return Err(InvalidParameter::AdcBits(b));
            }
            if self.disp_range_m <= 0.0 || self.vel_range_m_s <= 0.0 || self.force_range_n <= 0.0 {
                return Err(InvalidParameter::FullScale);
            }
        }
        if let Some(fc) = self.force_cutoff_hz {
            if !(fc.is_finite() && fc > 0.0) {
                return Err(InvalidParameter::ForceCutoff(fc));
            }
        }
        Ok(())
    }

    /// Applies the chain to ideal channels sampled at `t` (s): `x`, `v` in place, and returns the
    /// measured force from the true contact force `f_true` (N). `stuck[i]` tells whether the pin is
    /// at rest (ECR channel).
    pub fn apply(&self, rec: &mut Record, f_true: &[f64], stuck: &[bool]) {
        let mut rng = Rng::new(self.seed);
        let q = |range: f64| self.bits.map(|b| 2.0 * range / (1u64 << b) as f64);
        let quant = |v: f64, range: f64| match q(range) {
            Some(step) => ((v / step).round() * step).clamp(-range, range - step),
            None => v,
        };
        for x in rec.x.iter_mut() {
            *x = quant(*x + self.disp_noise_m * rng.normal(), self.disp_range_m);
        }
        for v in rec.v.iter_mut() {
            *v = quant(*v + self.vel_noise_m_s * rng.normal(), self.vel_range_m_s);
        }
        let dt = rec.dt();
        let mut f: Vec<f64> = f_true.to_vec();
        if let (Some(fc), true) = (self.force_cutoff_hz, dt > 0.0) {
            f = butterworth2(&f, fc, 1.0 / dt);
        }
        if self.force_lag_s > 0.0 && dt > 0.0 {
            f = delay(&f, self.force_lag_s / dt);
        }
        for v in f.iter_mut() {
            *v = quant(*v + self.force_noise_n * rng.normal(), self.force_range_n);
        }
        rec.ft = Some(f);
        rec.force_cutoff_hz = self.force_cutoff_hz.filter(|_| dt > 0.0);
        if let Some(th) = self.thermal {
            rec.temp = Some(
                rec.t
                    .iter()
                    .map(|&t| th.start_c + th.drift_c_per_s * t + th.noise_c * rng.normal())
                    .collect(),
            );
        }
        if let Some(e) = self.ecr {
            rec.ecr = Some(
                stuck
                    .iter()
                    .map(|&s| {
                        let l = if s {
                            e.log10_rest
                        } else {
                            e.log10_sliding + e.fluctuation_decades * rng.normal()
                        };
                        10f64.powf(l.clamp(0.0, 8.0))
                    })
                    .collect(),
            );
        }
    }
}

/// 2nd-order Butterworth low-pass (bilinear transform with pre-warping, cut-off at most 0.49 of
/// the rate), streaming: one sample in, one out. The charge amplifier's filter, for the records
/// ([`butterworth2`]) and the virtual rig's force channel alike.
#[derive(Debug, Clone)]
pub struct Butterworth2 {
    b: [f64; 3],
    a: [f64; 2],
    x: [f64; 2],
    y: [f64; 2],
}

impl Butterworth2 {
    /// A filter at rest at zero.
    pub fn new(cutoff_hz: f64, rate_hz: f64) -> Butterworth2 {
        let fc = cutoff_hz.min(0.49 * rate_hz);
        let k = (std::f64::consts::PI * fc / rate_hz).tan();
        let q = std::f64::consts::FRAC_1_SQRT_2;
        let norm = 1.0 / (1.0 + k / q + k * k);
        let b0 = k * k * norm;
        Butterworth2 {
            b: [b0, 2.0 * b0, b0],
            a: [2.0 * (k * k - 1.0) * norm, (1.0 - k / q + k * k) * norm],
            x: [0.0; 2],
            y: [0.0; 2],
        }
    }

    /// Settles the filter at a constant input `v` (its output then stays `v`).
    pub fn reset(&mut self, v: f64) {
        self.x = [v; 2];
        self.y = [v; 2];
    }

    /// Filters the next sample.
    pub fn step(&mut self, x: f64) -> f64 {
        let y = self.b[0] * x + self.b[1] * self.x[0] + self.b[2] * self.x[1]
            - self.a[0] * self.y[0]
            - self.a[1] * self.y[1];
        self.x = [x, self.x[0]];
        self.y = [y, self.y[0]];
        y
    }
}

/// Causal 2nd-order Butterworth low-pass of a whole signal ([`Butterworth2`], settled at its first
/// value).
pub fn butterworth2(x: &[f64], cutoff_hz: f64, rate_hz: f64) -> Vec<f64> {
    let mut f = Butterworth2::new(cutoff_hz, rate_hz);
    f.reset(x.first().copied().unwrap_or(0.0));
    x.iter().map(|&v| f.step(v)).collect()
}

/// Delays a uniformly sampled signal by `d` samples (linear interpolation, first value held).
pub fn delay(x: &[f64], d: f64) -> Vec<f64> {
    (0..x.len())
        .map(|i| {
            let p = i as f64 - d;
            if p <= 0.0 {
                x[0]
            } else {
                let j = p.floor() as usize;
                let fr = p - j as f64;
                if j + 1 < x.len() {
                    x[j] * (1.0 - fr) + x[j + 1] * fr
                } else {
                    x[x.len() - 1]
                }
            }
        })
        .collect()
}

/// What to generate.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSpec {
    /// Rig constants.
    pub rig: Rig,
    /// Initial displacement (m), e.g. 667e-6.
    pub x0_m: f64,
    /// Initial velocity (m/s), usually 0.
    pub v0_m_s: f64,
    /// Duration (s).
    pub duration_s: f64,
    /// Sampling rate (Hz).
    pub rate_hz: f64,
}

/// Simulates `model` on `spec.rig` and returns an SI record sampled at `rate_hz`, passed through
/// `sensor` (or ideal channels with the true friction force if `None`).
pub fn generate(
    spec: &RecordSpec,
    model: &Model,
    method: Method,
    sensor: Option<&SensorModel>,
) -> Result<Record, SimError> {
    spec.rig.validate()?;
    if !(spec.duration_s > 0.0 && spec.rate_hz > 0.0 && spec.duration_s.is_finite()) {
        return Err(SimError::Run("duration and rate must be > 0".into()));
    }
    if !(spec.x0_m.is_finite() && spec.v0_m_s.is_finite()) {
        return Err(SimError::Run("initial state must be finite".into()));
    }
    let n = (spec.duration_s * spec.rate_hz).round() as usize + 1;
    if n > 50_000_000 {
        return Err(SimError::Run(format!("{n} samples is too many")));
    }
    if let Some(s) = sensor {
        s.validate()?;
    }
    let rig = spec.rig;
    let dt = 1.0 / spec.rate_hz;
    let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let taus: Vec<f64> = t.iter().map(|&t| rig.tau_of_t(t)).collect();
    let tr = simulate(
        model,
        rig.y_of_x(spec.x0_m),
        rig.ydot_of_v(spec.v0_m_s),
        &taus,
        method,
    )?;
    let mut rec = Record::new(
        t,
        tr.y.iter().map(|&y| rig.x_of_y(y)).collect(),
        tr.ydot.iter().map(|&v| rig.v_of_ydot(v)).collect(),
        Some(rig),
        Units::Si,
    );
    let f_n: Vec<f64> = tr.f.iter().map(|&f| f * rig.load_n).collect();
    match sensor {
        Some(s) => {
            let stuck: Vec<bool> = tr
                .tau
                .iter()
                .map(|&tau| tr.stop_tau.is_some_and(|st| tau >= st))
                .collect();
            s.apply(&mut rec, &f_n, &stuck);
        }
        None => rec.ft = Some(f_n),
    }
    Ok(rec)
}
