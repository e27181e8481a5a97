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
use crate::uncertainty::{
    effective_count, hac_covariance, jacobian_par, noise_sigma, standard_errors,
};
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

mod classical;
mod drift;
mod screen;
mod solver;
mod span;
mod windows;
pub use classical::*;
pub use drift::*;
pub use screen::*;
pub use solver::*;
pub use span::*;
pub use windows::*;

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
    /// start each window from its first sample as measured (thesis Tables 6–7) and do not; that
    /// sample's noise is then added to the constants' covariance instead.
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
            RecordErrorKind::NonFinite => NotAnalysable::NonFinite {
                what: e.to_string(),
            }
            .into(),
            _ => FitError::Failed(e.to_string()),
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
    /// Converged, but the force channel shows μ0 drifting over the motion ([`Mu0Trend`]:
    /// running-in, or thermal): the constants are averages over a moving contact, whatever the
    /// envelope's gap says.
    Drifting,
}

impl FitVerdict {
    /// kebab-case name (as in JSON).
    pub fn name(&self) -> &'static str {
        match self {
            FitVerdict::Adequate => "adequate",
            FitVerdict::Inadequate => "inadequate",
            FitVerdict::NotConverged => "not-converged",
            FitVerdict::Drifting => "drifting",
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
            FitVerdict::Drifting => {
                "converged, but NOT adequate: μ0 drifts over the motion (the force channel's \
                 trend); the constants are averages over a changing contact (`tribo explain` \
                 names the drift)"
            }
        }
    }
}

/// Result of a fit. Standard errors are `NaN` (JSON `null`) when the Jacobian at the optimum is
/// singular (a constant the record cannot determine).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitResult {
    /// The law fitted (serialised as its name: `coulomb`, …, `poly:N`, `lugre`).
    pub law: LawSpec,
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
    /// The part of the record compared: from the release to where the motion sinks into the
    /// noise, with the noise levels read from the record that placed it.
    pub span: MotionSpan,
    /// The force channel's trend of μ0 over the compared motion, for a record with a force
    /// channel and a law with a Coulomb level ([`mu0_trend`]); `null` otherwise. A significant
    /// one makes the verdict [`FitVerdict::Drifting`].
    pub mu0_trend: Option<Mu0Trend>,
}

impl FitResult {
    /// The fitted law.
    pub fn friction_law(&self) -> FrictionLaw {
        self.law.law(&self.params)
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
    /// What the measurement noise adds to the envelope's square on average
    /// ([`MotionSpan::envelope_bias_var`]): the simulated envelope is compared as `√(A² + this)`.
    pub bias_var: f64,
    /// Samples of the compared span left out as spikes ([`spikes`]: a speckle dropout of the
    /// vibrometer, a glitch).
    pub spikes: usize,
    /// Samples of the compared span left out at a converter's rail ([`clipped`]).
    pub clipped: usize,
}

/// Samples of an envelope that stand out from the median of their 9 neighbours by more than
/// [`SPIKE_SIGMAS`] × the noise (plus 10⁻⁴ of the largest value: the resolution of a noiseless
/// record): a vibrometer's speckle dropouts and glitches, one to a few samples long, which a least-
/// squares fit would follow. The envelope itself varies far less over 9 samples.
pub fn spikes(a: &[f64], noise: f64) -> Vec<bool> {
    let n = a.len();
    let amax = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let thr = SPIKE_SIGMAS * noise + 1e-4 * amax;
    let mut out = vec![false; n];
    let mut w: Vec<f64> = Vec::with_capacity(9);
    for i in 0..n {
        let (lo, hi) = (i.saturating_sub(4), (i + 5).min(n));
        w.clear();
        w.extend_from_slice(&a[lo..hi]);
        let med = crate::uncertainty::median(&mut w);
        out[i] = (a[i] - med).abs() > thr;
    }
    out
}

/// How many noise standard deviations make a spike ([`spikes`]).
pub const SPIKE_SIGMAS: f64 = 8.0;

impl EnvelopeData {
    /// From dimensionless samples, over the part of them that is free motion ([`motion_span`]
    /// with the release taken at the first sample: windows of a record), keeping at most
    /// `max_points`.
    pub fn new(tau: &[f64], y: &[f64], ydot: &[f64], max_points: usize) -> Result<Self, FitError> {
        let n = tau.len();
        if n < 8 || y.len() != n || ydot.len() != n {
            return Err(FitError::failed(format!(
                "need ≥ 8 samples of τ, y, y' (got {n})"
            )));
        }
        Self::over(tau, y, ydot, &motion_span_from(tau, y, ydot, 0), max_points)
    }

    /// From dimensionless samples over `span` (τ shifted to start at 0 at its first sample),
    /// keeping at most `max_points`.
    pub fn over(
        tau: &[f64],
        y: &[f64],
        ydot: &[f64],
        span: &MotionSpan,
        max_points: usize,
    ) -> Result<Self, FitError> {
        let n = tau.len();
        if n < 8 || y.len() != n || ydot.len() != n || span.end > n || span.end < span.start + 8 {
            return Err(FitError::failed(format!(
                "need ≥ 8 samples of τ, y, y' in the compared span (got {} of {n})",
                span.end.saturating_sub(span.start)
            )));
        }
        if tau.iter().chain(y).chain(ydot).any(|v| !v.is_finite()) {
            return Err(NotAnalysable::NonFinite {
                what: "a sample of τ, y or y'".into(),
            }
            .into());
        }
        let (s, e) = (span.start, span.end);
        let stride = (e - s).div_ceil(max_points.max(8));
        let a_all = mark_crandall(&y[s..e], &ydot[s..e]);
        let noise = noise_sigma(&a_all).unwrap_or(0.0);
        let spike = spikes(&a_all, noise);
        let clip = clipped(&y[s..e], &ydot[s..e]);
        // The first sample starts the simulation: never dropped.
        let idx: Vec<usize> = (0..e - s)
            .step_by(stride)
            .filter(|&i| i == 0 || !(spike[i] || clip[i]))
            .collect();
        Ok(EnvelopeData {
            tau: idx.iter().map(|&i| tau[s + i] - tau[s]).collect(),
            a: idx.iter().map(|&i| a_all[i]).collect(),
            y0: y[s],
            ydot0: ydot[s],
            noise,
            bias_var: span.envelope_bias_var(),
            spikes: spike.iter().filter(|&&b| b).count(),
            clipped: clip.iter().filter(|&&b| b).count(),
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
    let b = data.bias_var;
    Ok(tr
        .y
        .iter()
        .zip(&tr.ydot)
        .map(|(y, v)| (y * y + v * v + b).sqrt())
        .collect())
}

/// The law a record can be fitted with when `asked` is: the apparatus alone (load 0,
/// [`Record::apparatus`]) has no friction law, only the blades' damping (viscous).
pub fn law_for(rec: &Record, asked: LawSpec) -> LawSpec {
    if rec.apparatus {
        LawSpec::Viscous
    } else {
        asked
    }
}

/// Fits `spec` to an SI or dimensionless record (its rig constants must be known), after
/// [`screen`]ing it.
pub fn fit(rec: &Record, spec: LawSpec, opts: &FitOptions) -> Result<FitResult, FitError> {
    rec.validate()?;
    let rig = rec.rig()?;
    let (tau, y, ydot) = rec.dimensionless()?;
    // The force channel's trend of μ0 reads of the fit only its span, its law and which of its
    // constants are zero ([`mu0_trend`]): it is searched beside the fit's simulations, for the
    // law's constants all non-zero, and kept when the fitted ones are (else searched again for
    // them), so it is what [`mu0_trend`] gives for the result.
    let guess = spec.mu(&vec![1.0; spec.n_params()]);
    let (mut r, beside) = fit_dimensionless_beside(&tau, &y, &ydot, spec, opts, |span| {
        mu0_trend_for(rec, spec, &guess, span.range())
    })?;
    r.p_si = rig.p_of_mu(&r.mu);
    r.p_si_se = rig.p_of_mu(&r.mu_se);
    let zeros = |mu: &[f64]| mu.iter().map(|&m| m == 0.0).collect::<Vec<bool>>();
    r.mu0_trend = match beside {
        Some(t) if r.law == spec && zeros(&r.mu) == zeros(&guess) => t,
        _ => mu0_trend(rec, &r),
    };
    // Only an adequate fit turns *drifting*: an inadequate one already says the law misses
    // something, and a law without the force's velocity dependence (a Coulomb–viscous fit of a
    // quadratic contact) leaves a trend in the force channel that is no drift.
    if r.verdict == FitVerdict::Adequate && r.mu0_trend.as_ref().is_some_and(|t| t.significant) {
        r.verdict = FitVerdict::Drifting;
    }
    Ok(r)
}

/// [`fit`] of every record on every core ([`map_on_every_core`]), the results in input order,
/// each what [`fit`] gives for it alone.
pub fn fit_many(
    recs: &[Record],
    spec: LawSpec,
    opts: &FitOptions,
) -> Vec<Result<FitResult, FitError>> {
    map_on_every_core(recs, |r| fit(r, spec, opts), || {})
}

/// Screens ([`screen`]) and fits `spec` to dimensionless samples.
pub fn fit_dimensionless(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    spec: LawSpec,
    opts: &FitOptions,
) -> Result<FitResult, FitError> {
    fit_dimensionless_beside(tau, y, ydot, spec, opts, |_| ()).map(|(r, _)| r)
}

/// [`fit_dimensionless`], with `beside` run on the record's motion span on a thread of its own
/// (and on that thread alone) while the record is screened and the law fitted (`None` when the
/// fits on this thread keep to one thread, [`set_fit_threads`]).
fn fit_dimensionless_beside<B: Send>(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    spec: LawSpec,
    opts: &FitOptions,
    beside: impl FnOnce(&MotionSpan) -> B + Send,
) -> Result<(FitResult, Option<B>), FitError> {
    let n = tau.len().min(y.len()).min(ydot.len());
    let (tau, y, ydot) = (&tau[..n], &y[..n], &ydot[..n]);
    check_finite(tau, y, ydot)?;
    let span = motion_span(tau, y, ydot);
    let r = span.range();
    // The rest of the fit, on this thread: the motion is screened (not the hold before it or the
    // rest after it), its envelope taken, the law fitted.
    let fit_span = || -> Result<(FitResult, usize, EnvelopeData), FitError> {
        let sc = screen_with(&tau[r.clone()], &y[r.clone()], &ydot[r.clone()], true)?;
        let data = EnvelopeData::over(tau, y, ydot, &span, opts.max_points)?;
        let p0 = start_of(opts, spec, || {
            start_point(&tau[r.clone()], &y[r.clone()], &ydot[r.clone()], spec)
        })?;
        let res = fit_envelope(&data, spec, p0, opts)?;
        Ok((res, sc.half_cycles, data))
    };
    let threads = fit_threads();
    let (fitted, b) = if threads > 1 {
        // `beside` starts with the screening (its work is lost when the record is refused).
        std::thread::scope(|s| {
            // `beside` keeps to its one thread: the fit's difference columns take the others
            // (measured on the 40 s fit, idle machine: 0.96× the wall time of `beside` on every
            // core, and 6 MB less).
            let h = s.spawn(|| {
                set_fit_threads(1);
                beside(&span)
            });
            let fitted = fit_span();
            let b = match h.join() {
                Ok(b) => b,
                Err(e) => std::panic::resume_unwind(e),
            };
            (fitted, Some(b))
        })
    } else {
        (fit_span(), None)
    };
    let (mut res, half_cycles, data) = fitted?;
    res.half_cycles = half_cycles;
    res.span = MotionSpan {
        spikes: data.spikes,
        clipped: data.clipped,
        ..span
    };
    Ok((res, b))
}

/// The starting point: the caller's, checked, or the fast estimators'.
fn start_of(
    opts: &FitOptions,
    spec: LawSpec,
    estimate: impl FnOnce() -> Vec<f64>,
) -> Result<Vec<f64>, FitError> {
    match &opts.start {
        Some(p) if p.len() == spec.n_params() => Ok(p.clone()),
        Some(p) => Err(FitError::failed(format!(
            "start has {} parameters, {} needs {}",
            p.len(),
            spec.name(),
            spec.n_params()
        ))),
        None => Ok(estimate()),
    }
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
    let p0 = start_of(opts, spec, || start_point(tau, y, ydot, spec))?;
    let mut r = fit_envelope(&data, spec, p0, opts)?;
    r.span = MotionSpan::whole(tau.len());
    Ok(r)
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
    let lm_opts = LmOptions {
        max_iter: opts.max_iter,
        tol: opts.tol,
        ..LmOptions::default()
    };
    let lm = levenberg_marquardt_par(resid, &q0, &lm_opts).ok_or_else(|| {
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
    // The residuals at the optimum are the last accepted evaluation's (`resid` is deterministic:
    // evaluating it again gave the same bits for one more simulation).
    let r_opt = Some(lm.residuals.clone());
    let scales = vec![1e-2; q0.len()];
    let mut se: Vec<f64> = r_opt
        .as_ref()
        .and_then(|r0| {
            let jac = jacobian_par(resid, &lm.p, r0, 1e-5, &scales)?;
            let mut cov = hac_covariance(&jac, r0)?;
            if !free_start {
                add_initial_state_noise(data, spec, &lm.p, &jac, r0, opts, &mut cov)?;
            }
            Some(cov)
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
        law: spec,
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
        span: MotionSpan::whole(data.a.len()),
        mu0_trend: None,
    })
}

/// When the simulation starts from the first sample as measured, that sample's noise moves every
/// fitted constant together: `Δp = −(JᵀJ)⁻¹ Jᵀ ∂r/∂s · Δs`, with `s` the initial state's relative
/// scale and `Var(Δs)` the envelope's per-sample noise over the initial amplitude, squared. Added
/// to the covariance (the residuals' own spread cannot show an error common to all of them).
fn add_initial_state_noise(
    data: &EnvelopeData,
    spec: LawSpec,
    p: &[f64],
    jac: &crate::uncertainty::Jacobian,
    r0: &[f64],
    opts: &FitOptions,
    cov: &mut [Vec<f64>],
) -> Option<()> {
    let h = 1e-5;
    let law = spec.law(&p[..spec.n_params()]);
    let a = scaled_envelope(data, law, 1.0 + h, opts).ok()?;
    let js: Vec<f64> = a
        .iter()
        .zip(&data.a)
        .zip(r0)
        .map(|((s, m), r)| ((s - m) - r) / h)
        .collect();
    let np = jac.len();
    let jtj: Vec<Vec<f64>> = (0..np)
        .map(|i| {
            (0..np)
                .map(|j| jac[i].iter().zip(&jac[j]).map(|(x, y)| x * y).sum())
                .collect()
        })
        .collect();
    let inv = crate::uncertainty::invert(&jtj)?;
    let g: Vec<f64> = (0..np)
        .map(|i| jac[i].iter().zip(&js).map(|(x, y)| x * y).sum())
        .collect();
    let dp: Vec<f64> = (0..np)
        .map(|i| -(0..np).map(|j| inv[i][j] * g[j]).sum::<f64>())
        .collect();
    let var_s = (data.noise / data.a0().max(1e-300)).powi(2);
    for i in 0..np {
        for j in 0..np {
            cov[i][j] += dp[i] * dp[j] * var_s;
        }
    }
    Some(())
}

/// Convenience: SI rig of a record or the unit rig.
pub fn rig_of(rec: &Record) -> Rig {
    rec.rig().unwrap_or(Rig::UNIT)
}
