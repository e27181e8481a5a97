//! Identification of a friction law from a record (thesis ch. 3.5).
//!
//! The thesis way: simulate the response of a candidate law, compare its Mark & Crandall envelope
//! with that of the measurement, and adjust the constants by Levenberg–Marquardt. Starting points
//! come from the fast estimators: the exact half-cycle decrement regression (Coulomb + viscous)
//! and the averaging-law regression of `dA/dτ` on powers of `A` (any polynomial order).
//!
//! Every fit says how far it can be trusted:
//! - a record is first *screened* ([`screen`]): non-finite samples, a saturated displacement or
//!   velocity channel, no oscillation at the rig's natural period above the noise, or fewer than
//!   [`MIN_HALF_CYCLES`] half cycles make it [`NotAnalysable`], and no constant is fitted;
//! - besides the law's constants, the initial amplitude is fitted (scale of the first sample's
//!   state): the first sample is as noisy as any other, and holding the simulation to it would
//!   bias the constants and hide a correlated error from their standard errors;
//! - standard errors come from the Jacobian at the optimum, with the residuals' correlation taken
//!   into account ([`crate::uncertainty`]); the *noise floor* is the envelope's own measurement
//!   noise, read from the record without any model;
//! - the [`FitVerdict`] compares the gap with that floor: a law that describes the record leaves
//!   residuals at the noise (gap ≈ floor); a gap above [`ADEQUATE_RATIO`] × the floor means the
//!   misfit is at least as large as the noise itself — the law misses something (`tribo explain`).

use crate::envelope::{classify_shape, mark_crandall, peaks, Shape};
use crate::integrate::{simulate, Method};
use crate::law::{mu_from_averaging, FrictionLaw};
pub use crate::law_spec::{LawSpec, LUGRE_FIXED};
use crate::model::{Model, Rig};
use crate::record::{Record, RecordErrorKind};
use crate::stats::linreg;
use crate::uncertainty::{effective_count, hac_covariance, jacobian, noise_sigma, standard_errors};
use serde::Serialize;
use std::f64::consts::PI;

/// Fewest half cycles (successive extrema about the rig's natural half period apart, above the
/// noise) a record needs to be fitted: two cycles, so that the decay has a shape and two constants
/// can be told apart. (The on-board analysis asks for five cycles; the thesis's rule of thumb.)
pub const MIN_HALF_CYCLES: usize = 4;

/// A fit is adequate while its gap is at most this many times the record's noise floor. With the
/// residuals at the noise the ratio is 1 within a few percent (the ratio's spread over noise
/// repeats is about `1/√(2 n_eff)`); at 1.5 the misfit of the law, `√(1.5² − 1) ≈ 1.1` noise
/// standard deviations, is as large as the noise itself and no longer chance.
pub const ADEQUATE_RATIO: f64 = 1.5;

/// Smallest noise floor used in the verdict (relative to the initial amplitude): the resolution of
/// the simulation inside the fit (Dormand–Prince at rtol 1e-10, amplitudes compared in f64), so that
/// a noiseless record is not called inadequate for the integrator's last digits.
pub const NUMERICAL_FLOOR: f64 = 1e-6;

/// Fit options.
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Integrator used inside the fit.
    pub method: Method,
    /// Envelope points compared (the record is decimated to at most this many).
    pub max_points: usize,
    /// Levenberg–Marquardt iteration limit.
    pub max_iter: usize,
    /// Convergence: relative parameter step and relative cost decrease.
    pub tol: f64,
    /// Known apparatus damping μ_a kept fixed in the model (0 = fit total damping).
    pub apparatus_mu1: f64,
    /// Starting point (parameters of the law); `None` = fast estimators.
    pub start: Option<Vec<f64>>,
    /// Also fit the initial amplitude (the first sample is as noisy as any other). Windowed fits
    /// start each window from its first sample as measured (thesis Tables 6–7) and do not.
    pub fit_initial_amplitude: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            method: Method::Dopri45 {
                rtol: 1e-10,
                atol: 1e-11,
                h_max: 0.5,
            },
            max_points: 2000,
            max_iter: 60,
            tol: 1e-12,
            apparatus_mu1: 0.0,
            start: None,
            fit_initial_amplitude: true,
        }
    }
}

/// Why a record cannot be analysed: no constant is fitted for it.
#[derive(Debug, Clone, PartialEq)]
pub enum NotAnalysable {
    /// A sample is NaN or infinite (`what` says where).
    NonFinite {
        /// The channel and sample (or file, line and column) of the first one.
        what: String,
    },
    /// Nothing oscillates at the rig's natural period above the noise.
    NoOscillation {
        /// What was found instead.
        reason: String,
    },
    /// Too short a decay to fit.
    TooFewHalfCycles {
        /// Half cycles found.
        found: usize,
        /// Half cycles needed ([`MIN_HALF_CYCLES`]).
        need: usize,
    },
    /// A channel stays at its extreme value (the converter's full scale) while the pin moves.
    Saturated {
        /// `displacement` or `velocity`.
        channel: &'static str,
        /// First sample of the flat run.
        sample: usize,
        /// Length of the run (samples).
        samples: usize,
    },
}

impl NotAnalysable {
    /// Short kebab-case name (`non-finite`, `no-oscillation`, `too-few-half-cycles`, `saturated`).
    pub fn name(&self) -> &'static str {
        match self {
            NotAnalysable::NonFinite { .. } => "non-finite",
            NotAnalysable::NoOscillation { .. } => "no-oscillation",
            NotAnalysable::TooFewHalfCycles { .. } => "too-few-half-cycles",
            NotAnalysable::Saturated { .. } => "saturated",
        }
    }
}

impl std::fmt::Display for NotAnalysable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotAnalysable::NonFinite { what } => write!(f, "non-finite sample: {what}"),
            NotAnalysable::NoOscillation { reason } => write!(f, "no oscillation: {reason}"),
            NotAnalysable::TooFewHalfCycles { found, need } => write!(
                f,
                "too few half cycles: {found} above the noise, a fit needs at least {need}"
            ),
            NotAnalysable::Saturated {
                channel,
                sample,
                samples,
            } => write!(
                f,
                "the {channel} channel is saturated: it stays at its extreme value for {samples} \
                 samples from sample {sample} while the pin moves (widen the converter's range)"
            ),
        }
    }
}

/// Fit failure.
#[derive(Debug, Clone, PartialEq)]
pub enum FitError {
    /// The record cannot be analysed (the reason); nothing was fitted.
    NotAnalysable(NotAnalysable),
    /// The fit could not be carried out (bad options, a model that cannot be simulated…).
    Failed(String),
}

impl FitError {
    fn failed(msg: impl Into<String>) -> FitError {
        FitError::Failed(msg.into())
    }
}

impl std::fmt::Display for FitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FitError::NotAnalysable(n) => write!(f, "not analysable: {n}"),
            FitError::Failed(m) => write!(f, "fit failed: {m}"),
        }
    }
}
impl std::error::Error for FitError {}

impl From<NotAnalysable> for FitError {
    fn from(n: NotAnalysable) -> Self {
        FitError::NotAnalysable(n)
    }
}

impl From<crate::record::RecordError> for FitError {
    fn from(e: crate::record::RecordError) -> Self {
        match e.kind() {
            RecordErrorKind::NonFinite => NotAnalysable::NonFinite { what: e.0 }.into(),
            _ => FitError::Failed(e.0),
        }
    }
}

/// How a converged fit describes the record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FitVerdict {
    /// Converged, and the residuals are at the record's noise floor.
    Adequate,
    /// Converged, but the gap is well above the noise floor: the law misses something.
    Inadequate,
    /// Levenberg–Marquardt stopped at its iteration limit: the constants are not at an optimum.
    NotConverged,
}

impl FitVerdict {
    /// kebab-case name (as in JSON).
    pub fn name(&self) -> &'static str {
        match self {
            FitVerdict::Adequate => "adequate",
            FitVerdict::Inadequate => "inadequate",
            FitVerdict::NotConverged => "not-converged",
        }
    }
    /// One sentence for the terminal.
    pub fn sentence(&self) -> &'static str {
        match self {
            FitVerdict::Adequate => "converged and adequate: the residuals are at the noise floor",
            FitVerdict::Inadequate => {
                "converged but inadequate: the gap is well above the noise floor, the law misses \
                 something (`tribo explain` looks for what)"
            }
            FitVerdict::NotConverged => {
                "NOT converged: the iteration limit was reached before the optimum; the constants \
                 are not trustworthy"
            }
        }
    }
}

/// The record passed [`screen`]: what was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Screening {
    /// Half cycles above the noise at the natural period.
    pub half_cycles: usize,
    /// Noise standard deviation of the Mark & Crandall envelope (dimensionless).
    pub envelope_noise: f64,
}

/// Runs of consecutive samples equal to the channel's maximum or minimum (start, length), counting
/// only runs where `moving(i)` holds somewhere, longest first.
fn flat_extreme_runs(c: &[f64], moving: impl Fn(usize) -> bool) -> Vec<(usize, usize)> {
    let hi = c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
    if hi <= lo || hi.is_nan() || lo.is_nan() {
        return Vec::new();
    }
    let mut runs = Vec::new();
    for ext in [hi, lo] {
        let mut i = 0;
        while i < c.len() {
            if c[i] == ext {
                let start = i;
                while i < c.len() && c[i] == ext {
                    i += 1;
                }
                if (start..i).any(&moving) {
                    runs.push((start, i - start));
                }
            } else {
                i += 1;
            }
        }
    }
    runs.sort_by_key(|r| std::cmp::Reverse(r.1));
    runs
}

/// A channel is saturated when it stays on its extreme value (the converter's rail) while the pin
/// moves, for at least one long run (`long` samples) or for two runs of [`SATURATION_RUN`]: a
/// quantised noisy sinusoid sampled 60+ times a cycle sits on its extreme code for one to four
/// samples, once (seen on 1 record in 200 at the rig's noise for four).
fn saturated(runs: &[(usize, usize)], long: usize) -> Option<(usize, usize)> {
    let first = *runs.first()?;
    let repeated = runs.iter().filter(|r| r.1 >= SATURATION_RUN).count() >= 2;
    (first.1 >= long || repeated).then_some(first)
}

/// Shortest flat run at a channel's extreme that counts, when it recurs.
const SATURATION_RUN: usize = 3;

/// Checks that dimensionless samples can be fitted: finite, not saturated, oscillating at the natural
/// half period π (in τ) above the noise for at least [`MIN_HALF_CYCLES`] half cycles.
pub fn screen(tau: &[f64], y: &[f64], ydot: &[f64]) -> Result<Screening, NotAnalysable> {
    for (name, c) in [("time", tau), ("displacement", y), ("velocity", ydot)] {
        if let Some(i) = c.iter().position(|v| !v.is_finite()) {
            return Err(NotAnalysable::NonFinite {
                what: format!("{name} is {} at sample {i}", c[i]),
            });
        }
    }
    let n = tau.len().min(y.len()).min(ydot.len());
    if n < 8 {
        return Err(NotAnalysable::NoOscillation {
            reason: format!("only {n} samples"),
        });
    }
    let (tau, y, ydot) = (&tau[..n], &y[..n], &ydot[..n]);
    let vmax = ydot.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // A displacement flat at its extreme while the velocity says the pin moves fast (not the
    // magnet's hold before the release, when both are still).
    let moving = |i: usize| ydot[i].abs() > 0.05 * vmax;
    // A long run: a fortieth of a cycle (9 samples at the rig's 10 kHz), at least 6.
    let dtau = (tau[n - 1] - tau[0]) / (n - 1) as f64;
    let long = ((2.0 * PI / dtau / 40.0).ceil() as usize).max(6);
    if let Some((sample, samples)) = saturated(&flat_extreme_runs(y, moving), long) {
        return Err(NotAnalysable::Saturated {
            channel: "displacement",
            sample,
            samples,
        });
    }
    if let Some((sample, samples)) = saturated(&flat_extreme_runs(ydot, |i| ydot[i] != 0.0), long) {
        return Err(NotAnalysable::Saturated {
            channel: "velocity",
            sample,
            samples,
        });
    }
    let a = mark_crandall(y, ydot);
    let noise = noise_sigma(&a).unwrap_or(0.0);
    // Extrema: displacement (signed) at each velocity sign change, at least π/8 apart (the noise
    // dithers the sign of the velocity about each reversal). A half cycle swings from one side to
    // the other by more than 10 × the noise; after the stop the noise only dithers about the rest
    // position.
    let mut ext: Vec<(f64, f64)> = Vec::new();
    for i in 1..n {
        let (p, q) = (ydot[i - 1], ydot[i]);
        if (p > 0.0 && q <= 0.0) || (p < 0.0 && q >= 0.0) {
            let j = if p.abs() < q.abs() { i - 1 } else { i };
            if ext.last().is_none_or(|e| tau[j] - e.0 >= PI / 8.0) {
                ext.push((tau[j], y[j]));
            }
        }
    }
    // A record that starts at rest (the release) starts at an extremum.
    if ydot[0].abs() <= 0.05 * vmax && ext.first().is_none_or(|e| e.0 - tau[0] >= PI / 8.0) {
        ext.insert(0, (tau[0], y[0]));
    }
    // The swing is a displacement: compare it with the displacement's own noise (the envelope's
    // mixes in the velocity's, and a large ripple when the rig constants are wrong).
    let level = 10.0 * noise_sigma(y).unwrap_or(0.0);
    let (mut regular, mut significant) = (0usize, Vec::new());
    for w in ext.windows(2) {
        let swing = (w[1].1 - w[0].1).abs();
        if swing > level && swing > 0.0 && w[0].1 * w[1].1 < 0.0 {
            let dt = w[1].0 - w[0].0;
            significant.push(dt);
            if (0.5 * PI..=2.0 * PI).contains(&dt) {
                regular += 1;
            }
        }
    }
    if regular == 0 {
        let reason = if significant.is_empty() {
            if vmax == 0.0 {
                "the velocity is zero throughout: the pin never moves".to_string()
            } else {
                "no swing of the displacement from one side to the other rises above 10 × the \
                 noise"
                    .to_string()
            }
        } else {
            significant.sort_by(f64::total_cmp);
            let med = significant[significant.len() / 2];
            format!(
                "the extrema are {:.2} natural half periods apart, not one: check the rig \
                 constants (mass_kg, stiffness_n_per_m)",
                med / PI
            )
        };
        return Err(NotAnalysable::NoOscillation { reason });
    }
    if regular < MIN_HALF_CYCLES {
        return Err(NotAnalysable::TooFewHalfCycles {
            found: regular,
            need: MIN_HALF_CYCLES,
        });
    }
    Ok(Screening {
        half_cycles: regular,
        envelope_noise: noise,
    })
}

/// Result of a fit. Standard errors are `NaN` (JSON `null`) when the Jacobian at the optimum is
/// singular (a constant the record cannot determine).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitResult {
    /// Law name (`coulomb`, …, `poly:N`, `lugre`).
    pub law: String,
    /// How far the fit can be trusted.
    pub verdict: FitVerdict,
    /// Dimensionless constants μ_j in order of j (seed eq. 10–13).
    pub mu: Vec<f64>,
    /// Standard errors of `mu` (0 for powers that are not fitted).
    pub mu_se: Vec<f64>,
    /// RMS(measured − fitted envelope) / initial amplitude.
    pub gap: f64,
    /// RMS measurement noise of the envelope / initial amplitude, read from the record (at least
    /// [`NUMERICAL_FLOOR`]); the gap of a law that describes the record.
    pub noise_floor: f64,
    /// SI coefficients `p_j = μ_j (k/(NΩ))^j` of `μ(v) = Σ p_j v^j` (v in m/s).
    pub p_si: Vec<f64>,
    /// Standard errors of `p_si`.
    pub p_si_se: Vec<f64>,
    /// Raw fitted parameters (equal to `mu` except for LuGre: `[μ_c, μ_s, σ2]`).
    pub params: Vec<f64>,
    /// Standard errors of `params`.
    pub params_se: Vec<f64>,
    /// LM iterations.
    pub iterations: usize,
    /// Whether LM met its tolerance.
    pub converged: bool,
    /// Envelope shape predicted by the fitted law over the measured amplitudes.
    pub shape: Shape,
    /// Initial amplitude Y0 (dimensionless), as fitted.
    pub y0: f64,
    /// Standard error of `y0`.
    pub y0_se: f64,
    /// Number of envelope points compared.
    pub points: usize,
    /// Effective number of independent residuals (their correlation accounted for).
    pub n_eff: f64,
    /// Half cycles found by the screening (0 for fits on a window of a record).
    pub half_cycles: usize,
}

impl FitResult {
    /// The fitted law.
    pub fn friction_law(&self) -> FrictionLaw {
        match self.law.parse::<LawSpec>() {
            Ok(spec) => spec.law(&self.params),
            Err(_) => FrictionLaw::Polynomial {
                mu: self.mu.clone(),
            },
        }
    }

    /// Gap relative to the noise floor (1 = residuals at the noise).
    pub fn gap_ratio(&self) -> f64 {
        self.gap / self.noise_floor
    }

    /// Scale of the fitted initial state relative to the first sample's.
    pub fn initial_scale(&self, data: &EnvelopeData) -> f64 {
        self.y0 / data.a0().max(1e-300)
    }

    /// One JSON object with every field of [`FitResult`] (`NaN` as `null`).
    pub fn to_json(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string(self)
    }
}

impl Serialize for Shape {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

/// Measured envelope prepared for fitting (dimensionless, decimated).
#[derive(Debug, Clone, PartialEq)]
pub struct EnvelopeData {
    /// τ of the compared points (starting at 0).
    pub tau: Vec<f64>,
    /// Mark & Crandall envelope there.
    pub a: Vec<f64>,
    /// Initial state (y, y') of the simulation.
    pub y0: f64,
    /// Initial velocity.
    pub ydot0: f64,
    /// Noise standard deviation of the envelope over the compared part of the record (every
    /// sample, before decimation).
    pub noise: f64,
}

impl EnvelopeData {
    /// From dimensionless samples (τ shifted to start at 0), keeping at most `max_points`.
    pub fn new(tau: &[f64], y: &[f64], ydot: &[f64], max_points: usize) -> Result<Self, FitError> {
        let n = tau.len();
        if n < 8 || y.len() != n || ydot.len() != n {
            return Err(FitError::failed(format!(
                "need ≥ 8 samples of τ, y, y' (got {n})"
            )));
        }
        if tau.iter().chain(y).chain(ydot).any(|v| !v.is_finite()) {
            return Err(NotAnalysable::NonFinite {
                what: "a sample of τ, y or y'".into(),
            }
            .into());
        }
        // Compare only while the pin moves: after the stop the rest position is a saw-tooth
        // function of the constants and would make the cost landscape rugged.
        let vmax = ydot.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let a_start = y[0].hypot(ydot[0]);
        let thr = (2e-3 * a_start).max(1e-3 * vmax);
        let last = ydot.iter().rposition(|v| v.abs() > thr).unwrap_or(n - 1);
        let n_used = (last + 2).clamp(8.min(n), n);
        let stride = n_used.div_ceil(max_points.max(8));
        let a_all = mark_crandall(y, ydot);
        let idx: Vec<usize> = (0..n_used).step_by(stride).collect();
        Ok(EnvelopeData {
            tau: idx.iter().map(|&i| tau[i] - tau[0]).collect(),
            a: idx.iter().map(|&i| a_all[i]).collect(),
            y0: y[0],
            ydot0: ydot[0],
            noise: noise_sigma(&a_all[..n_used]).unwrap_or(0.0),
        })
    }
    /// Initial amplitude.
    pub fn a0(&self) -> f64 {
        self.y0.hypot(self.ydot0)
    }
}

/// Envelope of the response of `law` from the data's initial state at the data's times.
pub fn simulated_envelope(
    data: &EnvelopeData,
    law: FrictionLaw,
    opts: &FitOptions,
) -> Result<Vec<f64>, FitError> {
    scaled_envelope(data, law, 1.0, opts)
}

/// [`simulated_envelope`] from the initial state scaled by `scale` (the fitted initial amplitude:
/// [`FitResult::initial_scale`]).
pub fn scaled_envelope(
    data: &EnvelopeData,
    law: FrictionLaw,
    scale: f64,
    opts: &FitOptions,
) -> Result<Vec<f64>, FitError> {
    let model = Model::new(law).with_apparatus_damping(opts.apparatus_mu1);
    let tr = simulate(
        &model,
        scale * data.y0,
        scale * data.ydot0,
        &data.tau,
        opts.method,
    )
    .map_err(|e| FitError::failed(e.to_string()))?;
    Ok(mark_crandall(&tr.y, &tr.ydot))
}

/// Fits `spec` to an SI or dimensionless record (its rig constants must be known), after
/// [`screen`]ing it.
pub fn fit(rec: &Record, spec: LawSpec, opts: &FitOptions) -> Result<FitResult, FitError> {
    rec.validate()?;
    let rig = rec.rig()?;
    let (tau, y, ydot) = rec.dimensionless()?;
    let mut r = fit_dimensionless(&tau, &y, &ydot, spec, opts)?;
    r.p_si = rig.p_of_mu(&r.mu);
    r.p_si_se = rig.p_of_mu(&r.mu_se);
    Ok(r)
}

/// Screens ([`screen`]) and fits `spec` to dimensionless samples.
pub fn fit_dimensionless(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    spec: LawSpec,
    opts: &FitOptions,
) -> Result<FitResult, FitError> {
    let sc = screen(tau, y, ydot)?;
    let mut r = fit_unscreened(tau, y, ydot, spec, opts)?;
    r.half_cycles = sc.half_cycles;
    Ok(r)
}

/// Fits without screening (windows of an already screened record).
fn fit_unscreened(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    spec: LawSpec,
    opts: &FitOptions,
) -> Result<FitResult, FitError> {
    let data = EnvelopeData::new(tau, y, ydot, opts.max_points)?;
    let p0 = match &opts.start {
        Some(p) if p.len() == spec.n_params() => p.clone(),
        Some(p) => {
            return Err(FitError::failed(format!(
                "start has {} parameters, {} needs {}",
                p.len(),
                spec.name(),
                spec.n_params()
            )))
        }
        None => start_point(tau, y, ydot, spec),
    };
    fit_envelope(&data, spec, p0, opts)
}

/// Levenberg–Marquardt fit of `spec` (and of the initial amplitude) to prepared envelope data from
/// `p0`, with standard errors, noise floor and verdict.
pub fn fit_envelope(
    data: &EnvelopeData,
    spec: LawSpec,
    p0: Vec<f64>,
    opts: &FitOptions,
) -> Result<FitResult, FitError> {
    let np = spec.n_params();
    let free_start = opts.fit_initial_amplitude;
    // Parameters: the law's, then (if fitted) `s`, the initial state's relative scale − 1.
    let resid = |p: &[f64]| -> Option<Vec<f64>> {
        let scale = if free_start { 1.0 + p[np] } else { 1.0 };
        let a = scaled_envelope(data, spec.law(&p[..np]), scale, opts).ok()?;
        Some(a.iter().zip(&data.a).map(|(s, m)| s - m).collect())
    };
    let mut q0 = p0;
    if free_start {
        q0.push(0.0);
    }
    let lm = levenberg_marquardt(resid, &q0, opts.max_iter, opts.tol).ok_or_else(|| {
        FitError::failed("the model could not be simulated at the starting point")
    })?;
    let a0 = data.a0();
    let n = data.a.len();
    let gap = (lm.cost * 2.0 / n as f64).sqrt() / a0.max(1e-300);
    let params = lm.p[..np].to_vec();
    let mu = spec.mu(&params);
    let a_lo = data.a.iter().copied().fold(f64::INFINITY, f64::min);
    // Standard errors from the Jacobian at the optimum (a coarser step than the search's, well
    // above the integrator's resolution).
    let r_opt = resid(&lm.p);
    let scales = vec![1e-2; q0.len()];
    let mut se: Vec<f64> = r_opt
        .as_ref()
        .and_then(|r0| {
            let jac = jacobian(resid, &lm.p, r0, 1e-5, &scales)?;
            hac_covariance(&jac, r0)
        })
        .map(|c| standard_errors(&c))
        .unwrap_or_else(|| vec![f64::NAN; q0.len()]);
    let s_fit = if free_start { lm.p[np] } else { 0.0 };
    se.push(0.0); // the initial scale's, when it is held
    let n_eff = r_opt.as_deref().map_or(n as f64, effective_count);
    let params_se = se[..np].to_vec();
    let mu_se = spec.mu_se(&params_se);
    let noise_floor = (data.noise / a0.max(1e-300)).max(NUMERICAL_FLOOR);
    let verdict = if !lm.converged {
        FitVerdict::NotConverged
    } else if gap > ADEQUATE_RATIO * noise_floor {
        FitVerdict::Inadequate
    } else {
        FitVerdict::Adequate
    };
    Ok(FitResult {
        law: spec.name(),
        verdict,
        shape: classify_shape(&mu, a_lo, a0),
        p_si: mu.clone(),
        p_si_se: mu_se.clone(),
        mu,
        mu_se,
        gap,
        noise_floor,
        params,
        params_se,
        iterations: lm.iterations,
        converged: lm.converged,
        y0: a0 * (1.0 + s_fit),
        y0_se: a0 * se[np],
        points: n,
        n_eff,
        half_cycles: 0,
    })
}

/// Starting parameters for `spec` from the fast estimators.
pub fn start_point(tau: &[f64], y: &[f64], ydot: &[f64], spec: LawSpec) -> Vec<f64> {
    let pw = spec.powers();
    let mu = estimate_averaging(tau, y, ydot, &pw).unwrap_or_else(|| vec![0.01; pw.len()]);
    match spec {
        LawSpec::LuGre => vec![mu[0].abs().max(1e-3), mu[0].abs().max(1e-3) * 1.2, mu[1]],
        _ => mu,
    }
}

/// Half-cycle peak magnitudes `(τ, |y|)` of dimensionless samples (velocity sign changes at least
/// 1 rad apart).
pub fn half_cycle_peaks(tau: &[f64], y: &[f64], ydot: &[f64]) -> Vec<(f64, f64)> {
    peaks(tau, y, ydot, 1.0)
}

/// Exact half-cycle decrement regression for Coulomb + viscous friction:
/// `X_{n+1} = D X_n − μ0 (1 + D)`, `D = exp(−π ζ / √(1 − ζ²))`, `μ1 = 2ζ`.
/// Returns `(μ0, μ1)`, or `None` with fewer than 3 half cycles.
pub fn estimate_decrement(tau: &[f64], y: &[f64], ydot: &[f64]) -> Option<(f64, f64)> {
    let pk = half_cycle_peaks(tau, y, ydot);
    decrement_from_peaks(&pk.iter().map(|p| p.1).collect::<Vec<_>>())
}

/// [`estimate_decrement`] from successive half-cycle peak magnitudes.
pub fn decrement_from_peaks(x: &[f64]) -> Option<(f64, f64)> {
    if x.len() < 3 {
        return None;
    }
    let (xs, ys) = (&x[..x.len() - 1], &x[1..]);
    let (slope, icpt) = linreg(xs, ys)?;
    let d = slope;
    if !(d > 0.0 && d.is_finite()) {
        return None;
    }
    let mu0 = -icpt / (1.0 + d);
    let l = -d.ln() / std::f64::consts::PI;
    let zeta = l / (1.0 + l * l).sqrt();
    Some((mu0, 2.0 * zeta))
}

/// Averaging-law regression: `dA/dτ` (from successive half-cycle peaks) regressed on `A^j`,
/// `j ∈ powers`, then `μ_j = −a_j / c_j` (eq. 27–28). Returns μ for the listed powers.
pub fn estimate_averaging(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    powers: &[usize],
) -> Option<Vec<f64>> {
    let pk = half_cycle_peaks(tau, y, ydot);
    if pk.len() < powers.len() + 2 {
        return None;
    }
    let mut rows = Vec::new();
    let mut rhs = Vec::new();
    for w in pk.windows(2) {
        let dt = w[1].0 - w[0].0;
        if dt <= 0.0 {
            continue;
        }
        let rate = (w[1].1 - w[0].1) / dt;
        // Midpoint amplitude, averaging A^j over the half cycle.
        let (a, b) = (w[0].1, w[1].1);
        rows.push(
            powers
                .iter()
                .map(|&j| {
                    if (b - a).abs() < 1e-12 {
                        a.powi(j as i32)
                    } else {
                        (b.powi(j as i32 + 1) - a.powi(j as i32 + 1)) / ((j as f64 + 1.0) * (b - a))
                    }
                })
                .collect::<Vec<f64>>(),
        );
        rhs.push(rate);
    }
    let coef = least_squares(&rows, &rhs)?;
    let mut a_full = vec![0.0; powers.iter().max().map_or(0, |m| m + 1)];
    for (i, &j) in powers.iter().enumerate() {
        a_full[j] = coef[i];
    }
    let mu_full = mu_from_averaging(&a_full);
    Some(powers.iter().map(|&j| mu_full[j]).collect())
}

/// Linear least squares by normal equations (small problems).
pub fn least_squares(rows: &[Vec<f64>], rhs: &[f64]) -> Option<Vec<f64>> {
    let p = rows.first()?.len();
    let mut a = vec![vec![0.0; p]; p];
    let mut b = vec![0.0; p];
    for (r, &y) in rows.iter().zip(rhs) {
        for i in 0..p {
            b[i] += r[i] * y;
            for j in 0..p {
                a[i][j] += r[i] * r[j];
            }
        }
    }
    solve(a, b)
}

/// Solves a small dense system by Gaussian elimination with partial pivoting.
#[allow(clippy::needless_range_loop)]
pub fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for c in 0..n {
        let piv = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[piv][c].abs() < 1e-300 || !a[piv][c].is_finite() {
            return None;
        }
        a.swap(c, piv);
        b.swap(c, piv);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Outcome of [`levenberg_marquardt`].
#[derive(Debug, Clone, PartialEq)]
pub struct LmResult {
    /// Parameters at the minimum.
    pub p: Vec<f64>,
    /// Cost ½ Σ r².
    pub cost: f64,
    /// Iterations.
    pub iterations: usize,
    /// Tolerance met.
    pub converged: bool,
}

/// How [`levenberg_marquardt_with`] differentiates and when it stops.
#[derive(Debug, Clone, PartialEq)]
pub struct LmOptions {
    /// Iteration limit.
    pub max_iter: usize,
    /// Convergence: relative cost decrease (and relative parameter step below `√tol / 100`).
    pub tol: f64,
    /// Finite-difference step of parameter `j`: `rel_step · max(|p_j|, scale_j)`.
    pub rel_step: f64,
    /// Typical magnitude of each parameter, used for the step when `p_j` is near 0 (missing
    /// entries: 1e-4).
    pub scales: Vec<f64>,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iter: 60,
            tol: 1e-12,
            rel_step: 1e-7,
            scales: Vec::new(),
        }
    }
}

/// Levenberg–Marquardt on residuals `r(p)` (`None` = could not evaluate: treated as a rejected
/// step), forward-difference Jacobian, Marquardt diagonal scaling. `None` if `r(p0)` fails.
pub fn levenberg_marquardt(
    r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    p0: &[f64],
    max_iter: usize,
    tol: f64,
) -> Option<LmResult> {
    levenberg_marquardt_with(
        r,
        p0,
        &LmOptions {
            max_iter,
            tol,
            ..LmOptions::default()
        },
    )
}

/// [`levenberg_marquardt`] with the difference step chosen per parameter. A coarser step than the
/// default 1e-7 is needed when the residuals are only piecewise smooth at fine scales (an adaptive
/// integrator's steps, the stick events of Coulomb friction on long records). Where the forward
/// point cannot be evaluated the backward difference is used.
pub fn levenberg_marquardt_with(
    mut r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    p0: &[f64],
    opts: &LmOptions,
) -> Option<LmResult> {
    let (max_iter, tol) = (opts.max_iter, opts.tol);
    let n = p0.len();
    let mut p = p0.to_vec();
    let mut res = r(&p)?;
    let cost = |v: &[f64]| 0.5 * v.iter().map(|x| x * x).sum::<f64>();
    let mut c = cost(&res);
    let mut lambda = 1e-3;
    let mut converged = false;
    let mut it = 0;
    while it < max_iter {
        it += 1;
        // Jacobian.
        let mut jac: Vec<Vec<f64>> = Vec::with_capacity(n);
        for j in 0..n {
            let scale = opts.scales.get(j).copied().unwrap_or(1e-4);
            let h = opts.rel_step * p[j].abs().max(scale);
            let mut q = p.clone();
            q[j] += h;
            let col = match r(&q) {
                Some(rq) => rq.iter().zip(&res).map(|(a, b)| (a - b) / h).collect(),
                None => {
                    q[j] = p[j] - h;
                    let rq = r(&q)?;
                    rq.iter().zip(&res).map(|(a, b)| (b - a) / h).collect()
                }
            };
            jac.push(col);
        }
        let mut jtj = vec![vec![0.0; n]; n];
        let mut jtr = vec![0.0; n];
        for i in 0..n {
            jtr[i] = jac[i].iter().zip(&res).map(|(a, b)| a * b).sum();
            for k in 0..n {
                jtj[i][k] = jac[i].iter().zip(&jac[k]).map(|(a, b)| a * b).sum();
            }
        }
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[i][i] += lambda * jtj[i][i].max(1e-30);
            }
            let Some(step) = solve(a, jtr.iter().map(|v| -v).collect()) else {
                lambda *= 10.0;
                continue;
            };
            let q: Vec<f64> = p.iter().zip(&step).map(|(a, b)| a + b).collect();
            if let Some(rq) = r(&q) {
                let cq = cost(&rq);
                if cq.is_finite() && cq < c {
                    let rel_step = step
                        .iter()
                        .zip(&q)
                        .map(|(s, v)| s.abs() / v.abs().max(1e-6))
                        .fold(0.0, f64::max);
                    let rel_cost = (c - cq) / c.max(1e-300);
                    p = q;
                    res = rq;
                    c = cq;
                    lambda = (lambda * 0.2).max(1e-12);
                    improved = true;
                    if rel_step < tol.sqrt() * 1e-2 || rel_cost < tol || c < 1e-28 {
                        converged = true;
                    }
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved {
            // No downhill step at any damping: a (numerical) minimum.
            converged = true;
            break;
        }
        if converged {
            break;
        }
    }
    Some(LmResult {
        p,
        cost: c,
        iterations: it,
        converged,
    })
}

/// A fit restricted to an amplitude window (thesis Tables 6–7).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowFit {
    /// Amplitude at the window start.
    pub a_start: f64,
    /// Amplitude at the window end.
    pub a_end: f64,
    /// τ of the window start (in the record).
    pub tau_start: f64,
    /// τ of the window end.
    pub tau_end: f64,
    /// The fit on that window.
    pub fit: FitResult,
}

impl WindowFit {
    /// One JSON object: `{"a_start", "a_end", "tau_start", "tau_end", "fit": {…}}` (amplitudes and
    /// times dimensionless; `fit` as [`FitResult::to_json`]).
    pub fn to_json(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string(self)
    }
}

/// [`windowed_fits`] on a record (SI or dimensionless; each window's `p_si` filled in).
pub fn fit_windows(
    rec: &Record,
    spec: LawSpec,
    windows: usize,
    opts: &FitOptions,
) -> Result<Vec<WindowFit>, FitError> {
    rec.validate()?;
    let rig = rec.rig()?;
    let (tau, y, ydot) = rec.dimensionless()?;
    let mut w = windowed_fits(&tau, &y, &ydot, spec, windows, opts)?;
    for x in &mut w {
        x.fit.p_si = rig.p_of_mu(&x.fit.mu);
        x.fit.p_si_se = rig.p_of_mu(&x.fit.mu_se);
    }
    Ok(w)
}

/// Splits the motion (until the envelope falls below 2 % of its start) into `windows` parts of
/// equal amplitude drop and fits `spec` on each, starting each simulation from the window's
/// first sample. Constants that drift from window to window mean the law misses something. The
/// whole record is [`screen`]ed first; the windows are not (each may hold only a few half cycles).
pub fn windowed_fits(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    spec: LawSpec,
    windows: usize,
    opts: &FitOptions,
) -> Result<Vec<WindowFit>, FitError> {
    if windows == 0 {
        return Err(FitError::failed("need at least one window"));
    }
    screen(tau, y, ydot)?;
    let a = mark_crandall(y, ydot);
    let a0 = *a.first().ok_or_else(|| FitError::failed("empty record"))?;
    let a_min = a
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        .max(0.02 * a0);
    let opts = &FitOptions {
        fit_initial_amplitude: false,
        ..opts.clone()
    };
    let mut out = Vec::new();
    let mut start = 0usize;
    for w in 1..=windows {
        let level = a0 - (a0 - a_min) * w as f64 / windows as f64;
        let end = a.iter().position(|&v| v <= level).unwrap_or(a.len() - 1);
        if end <= start + 8 {
            continue;
        }
        let r = fit_unscreened(
            &tau[start..=end],
            &y[start..=end],
            &ydot[start..=end],
            spec,
            opts,
        )?;
        out.push(WindowFit {
            a_start: a[start],
            a_end: a[end],
            tau_start: tau[start],
            tau_end: tau[end],
            fit: r,
        });
        start = end;
    }
    Ok(out)
}

/// Convenience: SI rig of a record or the unit rig.
pub fn rig_of(rec: &Record) -> Rig {
    rec.rig().unwrap_or(Rig::UNIT)
}
