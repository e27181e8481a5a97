//! The extended model: a base polynomial friction law plus any set of [`Effect`]s, its simulation
//! and its residuals against a prepared record.
//!
//! Parameter vector layout: the base law's `μ_j` (for [`Spec::powers`]), the initial amplitude's
//! relative correction `s` (the simulation starts from `(1 + s)` × the first sample's state: that
//! sample is as noisy as any other), the apparatus damping `μ_a` when [`Spec::apparatus`] (the
//! blades' own damping slows the motion but the force sensor, under the contact, does not see it:
//! with a force channel the two are told apart), then each effect's parameters in the order of
//! [`Spec::effects`] (see [`Effect::param_names`]).

use tribo_physics::integrate::{Method, SimError, Simulator};
use tribo_physics::law::FrictionLaw;
use tribo_physics::model::{Model, Rig};
use tribo_physics::record::{Record, RecordError, Units};
use tribo_physics::sensor::{butterworth2, delay};
use tribo_physics::uncertainty::noise_sigma;
use tribo_physics::InvalidParameter;

pub mod chain;
mod lowpass;
mod simulate;
mod spec;
pub use lowpass::{lowpass, lowpass_1pole, lowpass_of_order};
pub use simulate::*;
pub use spec::*;

/// Half-width (segments of [`THERMAL_SEGMENT`]) of the local straight line that smooths the
/// temperature thermal drift follows: 13 segments are 6.5 rad, about one oscillation period.
pub const TEMP_SMOOTH_SEGMENTS: usize = 13;

/// The temperature a plate's Coulomb level follows, from the segment means of the temperature
/// channel: at each segment the value of a straight line fitted to the means within
/// [`TEMP_SMOOTH_SEGMENTS`] of it (fewer at the ends of the record, where the line keeps the
/// slope a mean over a one-sided window would lose). The plate's temperature changes over its
/// thermal time constant (0.3 s and more: `shared/docs/real-bench.md`), many oscillation
/// periods, while the channel's noise is independent from one segment to the next; a Coulomb
/// level that followed the raw segment means would carry that noise (0.05 K on the grid's
/// channel is 1e-4 of μ0 at 8e-3/K, at each segment), and the force channel sees it (grid #115:
/// a 0.3 s cooling ramp, where a running-in of the same time constant fitted the force channel
/// 154 units of `−2 ln L` better than the thermal drift it stood for).
pub fn smooth_temperature(seg: &[f64]) -> Vec<f64> {
    let n = seg.len();
    (0..n)
        .map(|k| {
            let lo = k.saturating_sub(TEMP_SMOOTH_SEGMENTS);
            let hi = (k + TEMP_SMOOTH_SEGMENTS).min(n - 1);
            let m = (hi - lo + 1) as f64;
            if m < 3.0 {
                return seg[k];
            }
            let xs = (lo..=hi).map(|j| j as f64);
            let mx = xs.clone().sum::<f64>() / m;
            let my = seg[lo..=hi].iter().sum::<f64>() / m;
            let sxx: f64 = xs.clone().map(|x| (x - mx) * (x - mx)).sum();
            let sxy: f64 = xs
                .zip(&seg[lo..=hi])
                .map(|(x, y)| (x - mx) * (y - my))
                .sum();
            let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
            my + b * (k as f64 - mx)
        })
        .collect()
}

/// A record prepared for the comparison: dimensionless, uniformly sampled, with the compared
/// envelope and force points.
#[derive(Debug, Clone)]
pub struct Prepared {
    /// Rig constants.
    pub rig: Rig,
    /// τ of every sample (starting at 0).
    pub tau: Vec<f64>,
    /// Measured displacement y.
    pub y: Vec<f64>,
    /// Measured velocity y'.
    pub ydot: Vec<f64>,
    /// Sample interval in τ.
    pub dtau: f64,
    /// Sampling rate (Hz, or per unit τ for dimensionless records).
    pub rate_hz: f64,
    /// Indices of the compared envelope points.
    pub env_idx: Vec<usize>,
    /// Measured Mark & Crandall envelope at `env_idx`.
    pub a_meas: Vec<f64>,
    /// Measured dimensionless friction force `F/N`, every sample, if the record has `ft_n`.
    pub f_meas: Option<Vec<f64>>,
    /// Indices of the compared force points.
    pub f_idx: Vec<usize>,
    /// Every force point of the compared motion [`Prepared::f_idx`] is chosen from (it leaves out
    /// the samples at a reference model's velocity reversals: `crate::without_reversal_samples`).
    pub f_idx_all: Vec<usize>,
    /// Linear fit of the temperature channel: `T(τ) = t0 + slope · τ` (°C, °C per unit τ).
    pub temp: Option<(f64, f64)>,
    /// Mean temperature of each [`THERMAL_SEGMENT`] of τ (°C), if the record has `temp_c`.
    pub temp_seg: Option<Vec<f64>>,
    /// The plate's temperature at each segment of [`Prepared::temp_seg`] that thermal drift
    /// follows: the segment means smoothed by a local straight line over
    /// [`TEMP_SMOOTH_SEGMENTS`] segments either side ([`smooth_temperature`]).
    pub temp_smooth: Option<Vec<f64>>,
    /// Initial amplitude (the gap's normaliser).
    pub a0: f64,
    /// Charge-amplifier low-pass applied to simulated force (Hz), if any.
    pub force_cutoff_hz: Option<f64>,
    /// What the force channel reads at zero tangential force (`F/N`), when the record
    /// (`# force_zero_n`) or the caller states it. Stated, the force channel's constant offset is
    /// held there and a direction asymmetry of μ0 can be measured; not stated, the offset is a
    /// fitted nuisance that a direction asymmetry cannot be told from ([`chain`]).
    pub force_zero: Option<f64>,
    /// The standard error of [`Prepared::force_zero`] (`F/N`): 0 when stated, the hold's ± when
    /// measured over the magnet's hold ([`Prepared::hold_zero`]).
    pub force_zero_se: f64,
    /// What the force channel reads while the magnet holds the head before the release (`F/N`),
    /// with its standard error and the number of samples: the magnet carries the spring, so no
    /// tangential force acts on the contact and the channel reads its zero. The mean of the held
    /// samples up to [`FORCE_SETTLE_S`] before the first moving one (at least
    /// [`HOLD_ZERO_MIN_SAMPLES`]), its ± from their scatter with their correlation
    /// ([`tribo_physics::uncertainty::effective_count`]: a slow drift of the zero widens it).
    /// `None` for a record that starts in motion, or without a force channel.
    pub hold_zero: Option<(f64, f64, usize)>,
    /// Whether the force channel's low-pass is known (from the record or the caller); if not,
    /// [`crate::explain_prepared`] picks the better of none and [`RIG_FORCE_CUTOFF_HZ`] and says so.
    pub force_cutoff_known: bool,
    /// The noise model of the likelihood the fits, the evidence and the excess rule share
    /// ([`NoiseModel`]; `None`: every channel's noise at its floor, residuals independent — the
    /// model before any fit).
    pub noise: Option<NoiseModel>,
    /// Measurement noise of the envelope (every sample of the compared part) / `a0`.
    pub env_noise: f64,
    /// Measurement noise of the force channel (`F/N`, every sample of the compared part) / `a0`;
    /// 0 without a force channel.
    pub force_noise: f64,
    /// How many samples [`Prepared::env_noise`] and [`Prepared::force_noise`] were read from
    /// (their own uncertainty: [`Prepared::floor_rel_se`]).
    pub noise_samples: (usize, usize),
    /// Whether the record holds still before the release (the motion starts after its first
    /// sample): the release then falls between two samples, at [`Prepared::release_shift`].
    pub held: bool,
    /// Where the release falls relative to the first compared sample (τ units; positive: before
    /// it). The sample nearest the release is only known to a sample or so, and a force step at
    /// every reversal a fraction of a sample off reads as an effect, so on a held record it is a
    /// fitted nuisance ([`crate::explain_prepared`]): the simulation starts at rest at the release
    /// and sample `k` is compared with it at `τ_k + shift`. 0 for a record that starts in motion.
    pub release_shift: f64,
    /// Index in [`Prepared::record`] of the first compared sample (the motion's first, as
    /// [`tribo_physics::identify::motion_span`] finds it; 0 for a record that starts in motion).
    pub start: usize,
    /// The standard error of [`Prepared::release_shift`] as the motion measures it (τ units;
    /// infinite for a record that starts in motion): the prior of the release instant's offset in
    /// every model ([`Spec::release`], [`Prepared::release_prior`]).
    pub release_se: f64,
    /// Integrator.
    pub method: Method,
    /// The whole record, dimensionless (τ, y, y'), as `tribo fit` takes it: the base law is
    /// fitted on it by the one estimator of a law from a record.
    pub record: (Vec<f64>, Vec<f64>, Vec<f64>),
}

/// The rig's charge-amplifier low-pass (Hz): what a force channel that does not state its own has
/// if it is filtered at all.
pub const RIG_FORCE_CUTOFF_HZ: f64 = 300.0;

/// The force channel is compared from this long after the first sample on (s): longer than the
/// largest sensor lag considered (3 rad of τ ≈ 18 ms on the real rig) and the charge amplifier's
/// settling, so that the force before the record (the magnet's hold) does not matter.
pub const FORCE_SETTLE_S: f64 = 0.02;

/// Smallest noise level of a channel (relative to the initial amplitude): the resolution of the
/// simulations compared with the record (Dormand–Prince at rtol 1e-8), so that a noiseless record
/// is not "explained" by fitting integration error.
pub const NUMERICAL_FLOOR: f64 = 1e-6;

/// Why the workflow stopped.
#[derive(Debug, thiserror::Error)]
pub enum ExplainError {
    /// The record cannot be analysed (no oscillation, too few half cycles, a saturated channel, a
    /// non-finite sample): nothing to explain, and nothing wrong with the workflow.
    #[error("not analysable: {0}")]
    NotAnalysable(String),
    /// The record is not usable as given (its rig constants, its columns).
    #[error(transparent)]
    Record(#[from] RecordError),
    /// The record is not uniformly sampled.
    #[error("{0}")]
    Sampling(String),
    /// A model's constants are out of range.
    #[error(transparent)]
    Invalid(#[from] InvalidParameter),
    /// A candidate could not be simulated.
    #[error(transparent)]
    Simulation(#[from] SimError),
    /// A candidate's parameters leave their range, or need too many integration steps.
    #[error("{0}")]
    Candidate(String),
    /// The base law cannot be used (not polynomial) or could not be fitted.
    #[error("{0}")]
    BaseLaw(String),
    /// A figure could not be drawn.
    #[error("figure: {0}")]
    Figure(#[from] tribo_report::ReportError),
    /// The report could not be written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file that could not be written.
        path: std::path::PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
}

impl ExplainError {
    /// The error for a record that cannot be analysed.
    pub fn not_analysable(why: impl std::fmt::Display) -> ExplainError {
        ExplainError::NotAnalysable(why.to_string())
    }
    /// True if the record cannot be analysed (rather than the workflow failing).
    pub fn is_not_analysable(&self) -> bool {
        matches!(self, ExplainError::NotAnalysable(_))
    }
}

/// The comparison stops where the measured envelope first falls below this fraction of its
/// initial value.
pub const CUT_FRACTION: f64 = 0.1;

/// Fewest held samples the force channel's zero is measured from ([`Prepared::hold_zero`]).
pub const HOLD_ZERO_MIN_SAMPLES: usize = 32;

fn stride(n: usize, max: usize) -> usize {
    n.div_ceil(max.max(1)).max(1)
}

impl Prepared {
    /// Prepares a record: validates it, checks uniform sampling, converts it to dimensionless
    /// form, picks at most `max_env` envelope and `max_force` force points, reads the noise of each
    /// channel. The force channel's low-pass is `force_cutoff_hz` if given, else the record's
    /// (`# force_cutoff_hz=…`), else unknown ([`Prepared::force_cutoff_known`]).
    pub fn new(
        rec: &Record,
        max_env: usize,
        max_force: usize,
        force_cutoff_hz: Option<f64>,
    ) -> Result<Prepared, ExplainError> {
        rec.validate().map_err(|e| match e.kind() {
            tribo_physics::record::RecordErrorKind::NonFinite => ExplainError::not_analysable(e),
            _ => ExplainError::Record(e),
        })?;
        let rig = rec.rig()?;
        let dt = rec.dt();
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ExplainError::Sampling(
                "cannot tell the sampling interval".into(),
            ));
        }
        if let Some(w) = rec
            .t
            .windows(2)
            .find(|w| ((w[1] - w[0]) / dt - 1.0).abs() > 0.01)
        {
            return Err(ExplainError::Sampling(format!(
                "the record is not uniformly sampled (interval {} at t = {}, mean {dt})",
                w[1] - w[0],
                w[0]
            )));
        }
        let (tau_all, y_all, ydot_all) = rec.dimensionless()?;
        // From the release on (the rule of `tribo fit`: a bench record may start while the magnet
        // holds).
        let span = tribo_physics::identify::motion_span(&tau_all, &y_all, &ydot_all);
        let s0 = span.start;
        let t0 = tau_all[s0];
        let mut tau: Vec<f64> = tau_all[s0..].iter().map(|t| t - t0).collect();
        let mut y = y_all[s0..].to_vec();
        let mut ydot = ydot_all[s0..].to_vec();
        let mut a_all = tribo_physics::envelope::mark_crandall(&y, &ydot);
        let a0 = a_all[0];
        if a0.is_nan() || a0 <= 0.0 {
            return Err(ExplainError::not_analysable(
                "the record starts at rest at equilibrium: nothing to explain",
            ));
        }
        // Compare the motion down to CUT_FRACTION of the release amplitude: the final stop (and the
        // half cycle it falls on) makes the misfit jump with the parameters.
        let n = a_all
            .iter()
            .position(|&a| a < CUT_FRACTION * a0)
            .unwrap_or(a_all.len());
        if n < 64 {
            return Err(ExplainError::not_analysable(format!(
                "only {n} samples before the motion decays below {} % of its start",
                CUT_FRACTION * 100.0
            )));
        }
        for v in [&mut tau, &mut y, &mut ydot, &mut a_all] {
            v.truncate(n);
        }
        // Samples at a converter's rail (a few clipped peaks, which the screening lets through)
        // are not compared, as in `tribo fit`.
        let clip = tribo_physics::identify::clipped(&y, &ydot);
        let env_idx: Vec<usize> = (0..n)
            .step_by(stride(n, max_env))
            .filter(|&i| i == 0 || !clip[i])
            .collect();
        let a_meas = env_idx.iter().map(|&i| a_all[i]).collect();
        let f_meas = match (&rec.ft, rec.units) {
            (Some(f), _) => Some(
                f[s0..s0 + n]
                    .iter()
                    .map(|v| v / rig.load_n)
                    .collect::<Vec<f64>>(),
            ),
            _ => None,
        };
        // The force channel's first moments carry what happened before the record (the magnet's
        // hold, the charge amplifier's state, a lag that still shows the force before the
        // release): not compared.
        let f_start = (rig.tau_of_t(FORCE_SETTLE_S) / rig.tau_of_t(dt)).ceil() as usize;
        let f_idx: Vec<usize> = if f_meas.is_some() {
            (f_start.min(n)..n).step_by(stride(n, max_force)).collect()
        } else {
            Vec::new()
        };
        let temp = rec.temp.as_ref().and_then(|tc| {
            let (s, c) = linreg(&tau, &tc[s0..s0 + n])?;
            Some((c, s))
        });
        let temp_seg = rec.temp.as_ref().map(|tc| {
            let segs = (tau[n - 1] / THERMAL_SEGMENT) as usize + 1;
            let (mut sum, mut cnt) = (vec![0.0; segs], vec![0usize; segs]);
            for (t, v) in tau.iter().zip(&tc[s0..s0 + n]) {
                let k = ((t / THERMAL_SEGMENT) as usize).min(segs - 1);
                sum[k] += v;
                cnt[k] += 1;
            }
            // Empty segments (sampling coarser than a segment) repeat the previous mean.
            let mut out = Vec::with_capacity(segs);
            let mut last = tc[s0];
            for (s, c) in sum.iter().zip(&cnt) {
                if *c > 0 {
                    last = s / *c as f64;
                }
                out.push(last);
            }
            out
        });
        // The force channel during the magnet's hold reads its zero (no tangential force acts on
        // the contact while the magnet carries the spring); the samples closer to the release
        // than the force channel's settling time are left out.
        let hold_zero = match (&rec.ft, s0) {
            (Some(ft), s0) if s0 > 0 => {
                let margin = (FORCE_SETTLE_S / dt).ceil() as usize;
                let held = &ft[..s0.saturating_sub(margin)];
                (held.len() >= HOLD_ZERO_MIN_SAMPLES && held.iter().all(|v| v.is_finite())).then(
                    || {
                        let n = held.len() as f64;
                        let mean = held.iter().sum::<f64>() / n;
                        let dev: Vec<f64> = held.iter().map(|v| v - mean).collect();
                        let var = dev.iter().map(|d| d * d).sum::<f64>() / (n - 1.0);
                        let n_eff = tribo_physics::uncertainty::effective_count(&dev).max(1.0);
                        let load = rig.load_n;
                        (mean / load, (var / n_eff).sqrt() / load, held.len())
                    },
                )
            }
            _ => None,
        };
        let env_noise = noise_sigma(&a_all).unwrap_or(0.0) / a0;
        let force_noise = f_meas.as_ref().and_then(|f| noise_sigma(f)).unwrap_or(0.0) / a0;
        let noise_samples = (a_all.len(), f_meas.as_ref().map_or(0, |f| f.len()));
        let dtau = rig.tau_of_t(dt);
        let rate_hz = 1.0 / dt;
        let si = rec.units == Units::Si;
        let stated = force_cutoff_hz.or(rec.force_cutoff_hz);
        Ok(Prepared {
            rig,
            tau,
            y,
            ydot,
            dtau,
            rate_hz,
            env_idx,
            a_meas,
            f_meas,
            f_idx_all: f_idx.clone(),
            f_idx,
            temp,
            temp_smooth: temp_seg.as_deref().map(smooth_temperature),
            temp_seg,
            a0,
            force_cutoff_hz: if si { stated } else { None },
            force_zero: match (si, rec.ft.is_some(), rec.force_zero_n) {
                (true, true, Some(z)) => Some(z / rig.load_n),
                _ => None,
            },
            force_zero_se: 0.0,
            noise: None,
            hold_zero: if si { hold_zero } else { None },
            force_cutoff_known: !si || stated.is_some() || rec.ft.is_none(),
            env_noise,
            force_noise,
            noise_samples,
            held: s0 > 0,
            release_shift: 0.0,
            start: s0,
            release_se: f64::INFINITY,
            method: Method::dopri(1e-8),
            record: (tau_all, y_all, ydot_all),
        })
    }

    /// Noise floor of the envelope channel (at least [`NUMERICAL_FLOOR`]), relative to `a0`.
    pub fn env_floor(&self) -> f64 {
        self.env_noise.max(NUMERICAL_FLOOR)
    }

    /// Noise floor of the force channel (at least [`NUMERICAL_FLOOR`]; 0 without one).
    pub fn force_floor(&self) -> f64 {
        if self.has_force() {
            self.force_noise.max(NUMERICAL_FLOOR)
        } else {
            0.0
        }
    }

    /// The relative standard error of a channel's noise floor² (`force`: the force channel's,
    /// else the envelope's), as [`noise_sigma`] reads it from `N` samples: the mean square of
    /// third differences, whose neighbours are correlated (−3/4, 3/10, −1/20), so that for white
    /// noise its relative variance is `2 (1 + 2 (0.75² + 0.3² + 0.05²)) / N = 4.62 / N`.
    pub fn floor_rel_se(&self, force: bool) -> f64 {
        let n = if force {
            self.noise_samples.1
        } else {
            self.noise_samples.0
        };
        if n == 0 {
            f64::INFINITY
        } else {
            (4.62 / n as f64).sqrt()
        }
    }

    /// The gap a model that describes the record leaves: `√(env_floor² + force_floor²)`.
    pub fn noise_floor(&self) -> f64 {
        self.env_floor().hypot(self.force_floor())
    }

    /// Initial state of the simulations: the first sample, with a velocity below 1 % of the
    /// amplitude taken as the release from rest (0) rather than as noise with a sliding direction.
    /// A held record starts at rest at the release ([`Prepared::release_shift`]).
    pub fn initial_state(&self) -> (f64, f64) {
        if self.held {
            return (self.y[0], 0.0);
        }
        let v = self.ydot[0];
        (self.y[0], if v.abs() < 0.01 * self.a0 { 0.0 } else { v })
    }

    /// The release instant's prior as one residual: the model's offset of the instant from the one
    /// measured from the motion in units of that measurement's ± (`None` when the instant is not a
    /// parameter of `spec`). Its square is a term of every `−2 ln L` ([`Prepared::chi2`] of the
    /// channels plus it), so a fit moves the instant from the motion's measurement only as far as
    /// the channels it compares pay for: not by a sensor lag's worth, which the force channel
    /// cannot tell from it.
    pub fn release_prior(&self, spec: &Spec, p: &[f64]) -> Option<f64> {
        (spec.release && self.release_se > 0.0 && self.release_se.is_finite())
            .then(|| spec.release_delta(p) / self.release_se)
    }

    /// Where the release falls before the first compared sample in the model `spec`/`p` (τ units):
    /// the motion's measurement plus the model's offset from it. Sample `k` is at `τ_k` plus this
    /// on the simulator's clock.
    pub fn release_shift_of(&self, spec: &Spec, p: &[f64]) -> f64 {
        self.release_shift + spec.release_delta(p)
    }

    /// The square of [`Prepared::release_prior`] (0 without one).
    pub fn release_chi2(&self, spec: &Spec, p: &[f64]) -> f64 {
        self.release_prior(spec, p).map_or(0.0, |r| r * r)
    }

    /// True if a force channel is compared.
    pub fn has_force(&self) -> bool {
        self.f_meas.is_some()
    }

    /// True if a temperature channel is known.
    pub fn has_temp(&self) -> bool {
        self.temp.is_some()
    }
}

/// Ordinary least-squares line (defined in the physics crate).
pub use tribo_physics::stats::linreg;

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_physics::sensor::{generate, RecordSpec};

    fn spec_rec(model: &Model, duration_s: f64) -> Record {
        let sp = RecordSpec {
            rig: Rig::REAL,
            x0_m: 667e-6,
            v0_m_s: 0.0,
            duration_s,
            rate_hz: 10_000.0,
        };
        generate(&sp, model, Method::dopri(1e-10), None).unwrap()
    }

    /// A held record's release instant is a lead parameter after the chain's nuisances: its
    /// offset from the motion's measurement, started at 0, in range within RELEASE_DELTA_MAX,
    /// and in the simulation's clock (a later release delays the whole motion).
    #[test]
    fn the_release_instant_is_a_nuisance_of_every_model() {
        let mut s = Spec::base(vec![0, 1]);
        s.apparatus = true;
        s.lowpass = true;
        s.release = true;
        let s = s.with(Effect::SensorLag);
        assert_eq!(
            s.param_names(),
            [
                "mu0",
                "mu1",
                "start_scale",
                "apparatus_mu1",
                "force_lowpass_tau",
                "release_shift_delta",
                "delay_tau"
            ]
        );
        let p = s.start_with(&[0.02, 0.001], 0.05);
        assert_eq!(p.len(), 6);
        assert_eq!(s.release_index(), Some(5));
        assert_eq!(s.release_delta(&p), 0.0);
        let mut q = p.clone();
        q.push(0.1);
        assert!(s.in_range(&q, 1.0));
        q[5] = 1.5 * RELEASE_DELTA_MAX;
        assert!(!s.in_range(&q, 1.0));
        // The simulation's clock: a release δ later is the same motion δ later.
        let rec = spec_rec(&Model::new(FrictionLaw::coulomb_viscous(0.02, 0.001)), 0.3);
        let mut data = Prepared::new(&rec, 400, 4000, None).unwrap();
        data.held = true;
        data.release_se = data.dtau;
        let b = Spec {
            release: true,
            ..Spec::base(vec![0, 1])
        };
        let at = |d: f64| simulate_spec(&data, &b, &[0.02, 0.001, 0.0, d]).unwrap();
        let (a0, a1) = (at(0.0), at(-3.0 * data.dtau));
        assert!(
            (a1.y[10] - a0.y[7]).abs() < 1e-6,
            "{} {}",
            a1.y[10],
            a0.y[7]
        );
        assert_eq!(
            data.release_prior(&b, &[0.02, 0.001, 0.0, -3.0 * data.dtau]),
            Some(-3.0)
        );
    }

    #[test]
    fn parameter_layout_and_laws() {
        let s = Spec::base(vec![0, 1])
            .with(Effect::QuadraticVelocity)
            .with(Effect::CubicStiffness)
            .with(Effect::SensorLag);
        assert_eq!(s.n_params(), 6);
        assert_eq!(
            s.param_names(),
            ["mu0", "mu1", "start_scale", "mu2", "kappa", "delay_tau"]
        );
        let p = [0.02, 0.002, 0.0, 0.004, 1e-3, 0.5];
        assert_eq!(s.mu(&p), vec![0.02, 0.002, 0.004]);
        assert_eq!(s.law(&p, 0.0), FrictionLaw::quadratic(0.02, 0.002, 0.004));
        assert_eq!(
            s.effect_params(Effect::CubicStiffness, &p),
            Some(&[1e-3][..])
        );
        // Stribeck takes a law up to the quadratic term, and the quadratic term beside it, not
        // a cubic one.
        assert!(s.can_add(Effect::Stribeck, true, true));
        assert!(!s
            .with(Effect::QuadraticVelocity)
            .can_add(Effect::Stribeck, true, true));
        let sq = Spec::base(vec![0, 1]).with(Effect::Stribeck);
        assert!(sq.can_add(Effect::QuadraticVelocity, true, true));
        let sq = sq.with(Effect::QuadraticVelocity);
        assert!(!sq.can_add(Effect::QuadraticVelocity, true, true));
        assert_eq!(
            sq.law(&[0.02, 0.002, 0.0, 0.03, 0.3, 4e-4], 0.0),
            FrictionLaw::Stribeck {
                mu_c: 0.02,
                mu_s: 0.03,
                v_s: 0.3,
                delta: 2.0,
                mu_v: 0.002,
                mu2: 4e-4
            }
        );
        // The exponent chosen is the law's.
        let sq1 = Spec {
            stribeck_delta: 1.0,
            ..sq.clone()
        };
        assert!(matches!(
            sq1.law(&[0.02, 0.002, 0.0, 0.03, 0.3, 4e-4], 0.0),
            FrictionLaw::Stribeck { delta, .. } if delta == 1.0
        ));
        assert!(s.can_add(Effect::FrictionalLag, true, true));
        assert!(!s.can_add(Effect::SensorLag, true, true));
        let b = Spec::base(vec![0, 1]);
        assert!(b.can_add(Effect::Stribeck, false, false));
        assert!(!b.can_add(Effect::SensorLag, false, false));
        assert!(!b.can_add(Effect::ThermalDrift, true, false));
        let st = b.with(Effect::Stribeck).with(Effect::FrictionalLag);
        // A memory over a Stribeck curve, thermal shift applied to both levels.
        match st.law(&[0.02, 0.002, 0.0, 0.03, 0.3, 0.5], 0.001) {
            FrictionLaw::Lagged { steady, memory } => {
                assert_eq!(memory, 0.5);
                assert_eq!(
                    *steady,
                    FrictionLaw::Stribeck {
                        mu_c: 0.021,
                        mu_s: 0.031,
                        v_s: 0.3,
                        delta: 2.0,
                        mu_v: 0.002,
                        mu2: 0.0
                    }
                );
            }
            other => panic!("expected a lagged law, got {other:?}"),
        }
        for e in Effect::ALL {
            assert_eq!(Effect::from_name(e.name()), Some(e));
        }
    }

    #[test]
    fn the_true_model_reproduces_an_ideal_record() {
        // Ideal channels carry the true contact force: no charge-amplifier filter to apply.
        let m = Model::new(FrictionLaw::coulomb_viscous(0.02, 0.002)).with_cubic(1e-3);
        let rec = spec_rec(&m, 0.6);
        let data = Prepared::new(&rec, 400, 3000, None).unwrap();
        let s = Spec::base(vec![0, 1]).with(Effect::CubicStiffness);
        let sim = simulate_spec(&data, &s, &[0.02, 0.002, 0.0, 1e-3]).unwrap();
        let (e, f) = residuals(&data, &sim);
        assert!(gap_of(&e, &f) < 1e-7, "gap {}", gap_of(&e, &f));
        // …and a wrong one does not.
        let sim = simulate_spec(&data, &s, &[0.021, 0.002, 0.0, 1e-3]).unwrap();
        let (e, f) = residuals(&data, &sim);
        assert!(gap_of(&e, &f) > 1e-3);
    }

    #[test]
    fn bad_records_are_clear_errors() {
        let m = Model::new(FrictionLaw::coulomb_viscous(0.02, 0.002));
        let mut rec = spec_rec(&m, 0.2);
        rec.t[100] += 0.5 * rec.dt();
        let e = Prepared::new(&rec, 400, 3000, None).unwrap_err();
        assert!(
            matches!(&e, ExplainError::Sampling(m) if m.contains("uniformly")),
            "{e:?}"
        );
        let mut rec = spec_rec(&m, 0.2);
        rec.x[3] = f64::NAN;
        let e = Prepared::new(&rec, 400, 3000, None).unwrap_err();
        assert!(e.is_not_analysable(), "a NaN sample: {e:?}");
        let mut rec = spec_rec(&m, 0.2);
        rec.x.iter_mut().for_each(|x| *x = 0.0);
        rec.v.iter_mut().for_each(|v| *v = 0.0);
        let e = Prepared::new(&rec, 400, 3000, None).unwrap_err();
        assert!(
            matches!(&e, ExplainError::NotAnalysable(m) if m.contains("rest")),
            "{e:?}"
        );
        let mut rec = spec_rec(&m, 0.2);
        rec.rig = None;
        let e = Prepared::new(&rec, 400, 3000, None).unwrap_err();
        assert!(
            matches!(e, ExplainError::Record(_)),
            "no rig constants: {e:?}"
        );
    }

    #[test]
    fn gap_combines_the_channels() {
        assert_eq!(gap_of(&[3.0, 3.0], &[4.0]), 5.0);
    }

    /// A cubic spring is explored up to a stiffness change of a quarter of k at the release
    /// amplitude, whatever the record's `a0 = k x0 / N`: grid #421's −7.9 % softening at a0 0.79
    /// (κ = −0.128) and a 20 % hardening at a0 1 are in the range (`|κ| ≤ 0.05` cut both off);
    /// κ = 0.05 at a0 10 (five times k) and κ = −0.5 at a0 0.79 are not.
    #[test]
    fn cubic_range_is_the_stiffness_change_at_the_release_amplitude() {
        let spec = Spec::base(vec![0, 1]).with(Effect::CubicStiffness);
        // μ0, μ1, start correction, κ
        let p = |kappa: f64| vec![0.0034, 0.001, 0.0, kappa];
        assert!(spec.in_range(&p(-0.128), 0.79));
        assert!(spec.in_range(&p(0.2), 1.0));
        assert!(spec.in_range(&p(4.6e-5), 15.2));
        assert!(!spec.in_range(&p(0.05), 10.0));
        assert!(!spec.in_range(&p(-0.5), 0.79));
    }
}
