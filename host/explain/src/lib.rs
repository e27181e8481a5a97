//! The discrepancy workflow of the oscillating tribometer (thesis ch. 3.7 and 4).
//!
//! A base friction law (Coulomb–viscous by default) is fitted to a record, simulated and compared
//! with it on every channel the record has: the Mark & Crandall envelope (displacement and velocity)
//! and the friction force (`ft_n`), with the temperature (`temp_c`) as the input of thermal drift.
//! Disagreement measures follow ([`diag`]). Then every candidate [`Effect`] the model could be
//! missing is added in turn, the extended model is refitted by Levenberg–Marquardt on the same
//! residual vector, and judged by how much it shrinks the misfit **compared with what chance
//! would** ([`Evidence`]):
//!
//! - each channel's noise is modelled from its own residuals: their level (never below the
//!   channel's measurement noise read from the record, nor the simulation's resolution) and their
//!   correlation, as an effective sample count `n_eff` (the residuals of a slightly wrong model are
//!   smooth curves, not independent numbers; counting them as independent is what made ΔBIC reach
//!   hundreds for effects that are not there);
//! - the fits, the evidence and the excess-misfit rule are **one likelihood**
//!   ([`model::NoiseModel`], derived there): each channel's squared residuals weighted by
//!   `w = n_eff / (n · s²)`, with `s²` and `n_eff` measured on the current model's residuals at
//!   the start of each round and held while the candidates are fitted (Levenberg–Marquardt
//!   minimises `Σ_channels w · RSS`) and scored;
//! - the evidence is twice the log-likelihood ratio of that likelihood with each channel's
//!   variance profiled (never below its floor): `Σ_channels w · (RSS_before − RSS_after)` near the
//!   floor, `n_eff · ln(RSS_before / RSS_after)` far above it; a χ² with as many degrees of freedom
//!   as the effect adds parameters when the effect is absent; it must exceed the χ² quantile of a
//!   10⁻³ false-alarm rate per round, shared among the candidates (Bonferroni);
//! - the effect must also remove a material part (by default 30 %) of the misfit in excess of the
//!   noise floor (the deviance above the floor's, as well as the floor is known: the same
//!   likelihood's units), so that
//!   a systematic misfit from outside the vocabulary is not partly soaked up by a wrong name; and
//!   beat the runner-up by a likelihood ratio of e⁵ (evidence margin 10).
//!
//! The force channel's low-pass, when the record does not state it, is a nuisance parameter of
//! every model (its time constant, [`model::lowpass`]), fitted with the law and the effect being
//! tried, never a guess; the result prints it with its ± ([`ForceLowpass`]). Its order (1-pole,
//! [`model::lowpass_1pole`], or the 2-pole Butterworth) is chosen from the record at the base law,
//! chosen again with the model each step leaves (where the other order fits it better by the
//! evidence a change needs: a base law that misses a strong effect can choose it wrongly, and a
//! later effect is then named to make up the order's shape), held in the models each round
//! compares but for a sensor lag (a pure delay, fitted with either order: beside a 1-pole filter
//! it is what a 2-pole's extra phase mimics, and it is tried again at the floor after a change
//! from 1 pole to 2), and checked against the other order at the final model
//! (`ForceLowpass::poles`, `ForceLowpass::order_evidence`). A stated cut-off is the 2-pole
//! filter.
//!
//! The best candidate is added and the search repeats. Once the model is at the noise floor (1.5 ×
//! it in every channel), only the effects whose misfit that rule weighs poorly are still tried:
//! those that change the motion (cubic stiffness, frictional lag, which must then be seen in the
//! envelope), the quadratic term, a direction asymmetry where the force channel's zero is known,
//! thermal drift when the temperature column moves over the motion
//! ([`diag::Diagnostics::temperature_moves`]), and the drifts and velocity terms where the force
//! channel's level drifts against the model, and a sensor lag where its level differs across the
//! track against the model ([`diag::position_dependence`]). (The first round tries every
//! candidate, at the floor or not.) Running-in, and a cubic stiffness the envelope does not see,
//! are named only where a stripe of the track does not fit the force channel's level better, nor
//! (running-in) stand beside it ([`diag::drift_or_stripe`]). When nothing more qualifies
//! and the misfit is still above 1.5 × the noise floor in some channel, the answer is
//! "unexplained: N % of the gap remains; not one of the known effects" — never a name the
//! evidence does not support.
//!
//! The gap is the one of `tribo fit`: RMS(measured − simulated envelope) / initial amplitude,
//! extended to the force channel as `√(gap_env² + gap_force²)`, the force residual being
//! expressed in the same units (force relative to the initial spring force `k x0`).
//!
//! ```no_run
//! use tribo_explain::{explain, ExplainOptions};
//! let rec = tribo_physics::Record::load(std::path::Path::new("run.csv")).unwrap();
//! let e = explain(&rec, &ExplainOptions::default()).unwrap();
//! println!("{}", e.to_json().unwrap());
//! ```

#![warn(missing_docs)]

pub mod diag;
pub mod model;
pub mod release;
pub mod report;

pub use model::{Effect, ExplainError, Prepared, Spec};
/// Re-exported so that users can read [`Explanation::to_json`] output with the same version.
pub use serde_json;

use model::{
    gap_of, objective, residuals, rms, sandwich_blocks, simulate_spec, LOWPASS_TAU_MAX,
    MEMORY_TAU_MIN, RIG_FORCE_CUTOFF_HZ,
};
use serde::Serialize;
use std::collections::BTreeMap;
use tribo_physics::identify::{
    estimate_averaging, fit_dimensionless, levenberg_marquardt_with, FitError, FitOptions, LawSpec,
    LmOptions, ADEQUATE_RATIO,
};
use tribo_physics::uncertainty::{
    chi2_upper_quantile, effective_count, hac_covariance_blocks, jacobian,
};
use tribo_physics::Record;

mod evidence;
mod explanation;
mod fitting;
pub use evidence::*;
pub use explanation::*;
pub use fitting::*;

/// Options of [`explain`].
#[derive(Debug, Clone, PartialEq)]
pub struct ExplainOptions {
    /// Base law (polynomial laws only: coulomb, viscous, coulomb-viscous, quadratic, poly:N).
    pub base: LawSpec,
    /// Effects considered.
    pub candidates: Vec<Effect>,
    /// At most this many effects are added.
    pub max_steps: usize,
    /// False-alarm rate of one round of the search (shared among the candidates).
    pub false_alarm: f64,
    /// Smallest fraction of the excess misfit (the `−2 ln L` above what noise at each channel's
    /// floor leaves, [`Evidence::excess_removed`]) an effect must remove to be named.
    pub min_excess_reduction: f64,
    /// Evidence margin the best candidate needs over the runner-up to be named.
    pub min_margin: f64,
    /// Compared envelope points.
    pub max_env_points: usize,
    /// Compared force points (at most; every sample of the compared motion up to this many, one
    /// in `⌈n / max⌉` above). The likelihood is of every sample the record has: a subsample
    /// throws away what the force channel says about a slow drift of the level (grid #213, a
    /// running-in of 7 % over the motion at 6σ in the force channel's trend, was 0.5 units of
    /// evidence from 2859 force points of 31 k).
    pub max_force_points: usize,
    /// Levenberg–Marquardt iterations per fit.
    pub max_iter: usize,
    /// Low-pass of the force channel (Hz, a 2-pole filter) applied to simulated force, overriding
    /// the record's (`None`: the record's `# force_cutoff_hz`, or, if it says nothing, fitted with
    /// its order: a parameter of every model, estimated with its ± —
    /// [`Explanation::force_lowpass`]).
    pub force_cutoff_hz: Option<f64>,
    /// What the force channel reads at zero tangential force (N), overriding the record's
    /// (`None`: the record's `# force_zero_n`, or, if it says nothing, a fitted nuisance that a
    /// direction asymmetry of μ0 cannot be told from — [`model::chain`]).
    pub force_zero_n: Option<f64>,
}

impl Default for ExplainOptions {
    fn default() -> Self {
        ExplainOptions {
            base: LawSpec::CoulombViscous,
            candidates: Effect::ALL.to_vec(),
            max_steps: 3,
            false_alarm: 1e-3,
            min_excess_reduction: 0.3,
            min_margin: 10.0,
            max_env_points: 400,
            max_force_points: 100_000,
            max_iter: 15,
            force_cutoff_hz: None,
            force_zero_n: None,
        }
    }
}

impl ExplainOptions {
    /// Evidence an effect adding `k` parameters needs: the χ²_k quantile of the false-alarm rate
    /// shared among the candidates.
    pub fn threshold(&self, k: usize) -> f64 {
        let m = self.candidates.len().max(1) as f64;
        chi2_upper_quantile(k, self.false_alarm / m)
    }
}

/// Runs the whole workflow on a record.
pub fn explain(rec: &Record, opts: &ExplainOptions) -> Result<Explanation, ExplainError> {
    let data = Prepared::new(
        rec,
        opts.max_env_points,
        opts.max_force_points,
        opts.force_cutoff_hz,
    )?;
    explain_prepared(&data, opts).map(|(e, _)| e)
}

/// The workflow's messages of progress (for a progress display): `(what, done, of)`.
pub type Progress<'a> = &'a mut dyn FnMut(&str, usize, usize);

/// [`explain`] on a prepared record. Returns the explanation and the prepared data as used (the
/// force channel's low-pass settled).
pub fn explain_prepared(
    data: &Prepared,
    opts: &ExplainOptions,
) -> Result<(Explanation, Prepared), ExplainError> {
    explain_with_progress(data, opts, &mut |_, _, _| {})
}

/// [`explain_prepared`] reporting its progress.
pub fn explain_with_progress(
    data: &Prepared,
    opts: &ExplainOptions,
    progress: Progress,
) -> Result<(Explanation, Prepared), ExplainError> {
    let powers = base_powers(opts.base)?;
    let mut data = data.clone();
    let zero_source = if !data.has_force() {
        "none"
    } else if let Some(z) = opts.force_zero_n {
        data.force_zero = Some(z / data.rig.load_n);
        "option"
    } else if data.force_zero.is_some() {
        "record"
    } else if let Some((z, se, _)) = data.hold_zero {
        // Measured over the magnet's hold, with its ±: held in every model like a stated zero,
        // its ± carried into a direction asymmetry's (below, in the search).
        data.force_zero = Some(z);
        data.force_zero_se = se;
        "hold"
    } else {
        "fitted"
    };
    // A record held before its release: where the release falls between two samples is measured
    // from the motion channels about it ([`release::release_from_motion`]; not from the force
    // channel, where it is the same thing as a sensor lag, nor from a law's phase, which any
    // effect missing from the law moves), and is a parameter of every model under that
    // measurement as a prior ([`Spec::release`], [`Prepared::release_prior`]): the force channel
    // is far more sensitive to it than the motion's ± (CI-grid #9, clean: held at the motion's
    // measurement, 0.10 ± 0.21 sample off, a cubic stiffness got evidence 77), and a fit moves
    // the instant only as far as the channels pay for. A record too coarse or too short for the
    // motion's fit has its release at the first compared sample to within half a sample
    // (uniform).
    if data.held {
        progress("measuring the release instant", 0, 1);
        let (tau_all, y_all, ydot_all) = &data.record;
        let (shift, se) = match release::release_from_motion(tau_all, y_all, ydot_all, data.start) {
            Some(r) => (tau_all[data.start] - r.tau, r.se),
            None => (0.0, data.dtau / 12f64.sqrt()),
        };
        data.release_shift = shift;
        data.release_se = se;
    }
    let data = data;
    let mut spec = Spec::base(powers.clone());
    spec.apparatus = data.has_force();
    spec.release = data.held;
    // The force channel's low-pass, when neither the record nor the caller states it, is a
    // parameter of every model of the search, fitted with the law and the effects it can be
    // mistaken for (frictional lag, sensor lag): never a guess held fixed.
    let source = if !data.has_force() {
        "none"
    } else if opts.force_cutoff_hz.is_some() {
        "option"
    } else if data.force_cutoff_known {
        "record"
    } else {
        spec.lowpass = true;
        "fitted"
    };
    let spec = spec;
    progress("fitting the base law", 0, 1);
    // The base law is `tribo fit`'s answer: the one estimator of a law from a record, on the
    // whole record. The joint envelope + force model the effects are added to starts from it.
    let (tau_all, y_all, ydot_all) = &data.record;
    let mut base_fit =
        match fit_dimensionless(tau_all, y_all, ydot_all, opts.base, &FitOptions::default()) {
            Ok(r) => r,
            Err(FitError::NotAnalysable(n)) => return Err(ExplainError::not_analysable(n)),
            Err(e) => return Err(ExplainError::BaseLaw(e.to_string())),
        };
    base_fit.p_si = data.rig.p_of_mu(&base_fit.mu);
    base_fit.p_si_se = data.rig.p_of_mu(&base_fit.mu_se);
    // The low-pass starts from the rig's charge amplifier and from (nearly) none.
    let tau_rig = data.rig.omega() / (2.0 * std::f64::consts::PI * RIG_FORCE_CUTOFF_HZ);
    let law_start = tribo_physics::identify::start_point(&data.tau, &data.y, &data.ydot, opts.base);
    let fit_base_on = |data: &Prepared, spec: &Spec| {
        let mut starts = vec![
            spec.start_with(&base_fit.params, tau_rig),
            spec.start_with(&law_start, tau_rig),
        ];
        if spec.lowpass {
            starts.push(spec.start_with(&base_fit.params, 0.2 * data.dtau));
        }
        fit_spec(data, spec, &starts, opts.max_iter)
    };
    let fit_base = |spec: &Spec| fit_base_on(&data, spec);
    // A fitted low-pass's order (1 or 2 poles, `shared/docs/real-bench.md`) is chosen from the
    // record: the base law is fitted with each, and the one with the smaller misfit (the same
    // number of parameters) is held in every model of the search (and, for 2 poles, its kind,
    // below). The final model is checked against the other order below.
    let base = if spec.lowpass {
        let one = Spec {
            lowpass_poles: 1,
            ..spec.clone()
        };
        [fit_base(&spec), fit_base(&one)]
            .into_iter()
            .flatten()
            .min_by(|a, b| a.chi2.total_cmp(&b.chi2))
    } else {
        fit_base(&spec)
    };
    let base = base.ok_or_else(|| {
        ExplainError::BaseLaw("the base law could not be fitted to the record".into())
    })?;
    // The force samples at the base model's velocity reversals are not compared (held in every
    // model, like the release instant): see [`without_reversal_samples`].
    let (data, base) = match without_reversal_samples(&data, &base) {
        Some((d, b)) => (d, b),
        None => (data, base),
    };
    // A fitted 2-pole filter's kind, analog (discretised exactly) or digital (bilinear), is chosen
    // on the samples the search compares, from the analog one's fit: the two part only near the
    // sampling rate, where the samples next to the reversals (left out now) would decide it.
    // Only where the analog one found a filter, and a digital one below the bilinear filter's
    // clamp (0.49 of the rate, where it is not the identity: CI-grid #136, no filter, took a
    // digital one at the clamp and a false sensor lag beside it).
    let below_clamp = |m: &FittedModel| {
        m.spec
            .lowpass_tau(&m.p)
            .is_some_and(|t| data.dtau / (2.0 * std::f64::consts::PI * t) < 0.45)
    };
    let base = if base.spec.lowpass
        && base.spec.lowpass_poles == 2
        && !lowpass_at_bound(&data, &base.spec, &base.p)
    {
        let digital = Spec {
            lowpass_digital: true,
            ..base.spec.clone()
        };
        // Its misfit is rough in the cut-off near the sampling rate (the bilinear filter's
        // response to a step between samples): a scan of ±15 % about the analog one's in 1 %
        // steps, the rest held, and the fit from the best three.
        let i = digital.lowpass_index().expect("a fitted low-pass");
        let mut scan: Vec<(f64, Vec<f64>)> = (-15..=15)
            .filter_map(|k| {
                let mut p = base.p.clone();
                p[i] *= 1.0 + 0.01 * f64::from(k);
                evaluate(&data, &digital, &p).map(|m| (m.chi2, p))
            })
            .collect();
        scan.sort_by(|a, b| a.0.total_cmp(&b.0));
        let starts: Vec<Vec<f64>> = scan.into_iter().take(3).map(|(_, p)| p).collect();
        let dd = fit_spec(&data, &digital, &starts, opts.max_iter);
        match dd {
            Some(d) if d.chi2 < base.chi2 && below_clamp(&d) => d,
            _ => base,
        }
    } else {
        base
    };
    // The one likelihood's noise model (each channel's residual variance and correlation) is
    // measured on the base model's residuals, and the base law refitted under it: the search
    // starts from the maximiser of the likelihood its first comparisons are made under.
    let (data, base) = reweigh(&data, &base, opts.max_iter);
    let fit_base = |spec: &Spec| fit_base_on(&data, spec);
    let base = with_standard_errors(&data, base);
    progress("diagnostics", 0, 1);
    let diagnostics = diag::diagnose(&data, &base, opts.base);
    let Searched {
        start: mut base,
        mut cur,
        mut steps,
        mut rounds,
        mut ambiguous,
        mut stripe,
        mut drift_model,
        data: mut used,
    } = search(&data, opts, &diagnostics, &base, progress);
    // The other order against the final model, with its effects: the same constants refitted
    // with the other filter. If it explains the record better by the evidence an effect needs,
    // the search is run again with that order from its base law (once: no going back and forth).
    let mut order_evidence = None;
    if cur.spec.lowpass {
        let other = other_order(&used, &cur, opts.max_iter);
        if let Some(o) = &other {
            let ev = Evidence::of(&used, &cur, o, opts);
            order_evidence = Some(-ev.value);
            if ev.value >= ev.threshold {
                let spec2 = Spec {
                    lowpass_poles: o.spec.lowpass_poles,
                    lowpass_digital: o.spec.lowpass_digital,
                    ..base.spec.clone()
                };
                if let Some(b2) = fit_base(&spec2) {
                    let (d2, b2) = reweigh(&data, &b2, opts.max_iter);
                    let b2 = with_standard_errors(&d2, b2);
                    Searched {
                        start: base,
                        cur,
                        steps,
                        rounds,
                        ambiguous,
                        stripe,
                        drift_model,
                        data: used,
                    } = search(&d2, opts, &diagnostics, &b2, progress);
                    order_evidence = other_order(&used, &cur, opts.max_iter)
                        .map(|o| -Evidence::of(&used, &cur, &o, opts).value);
                }
            }
        }
    }
    let base = base;
    // The final model's residuals are over the force samples its last round compared (the
    // reversal samples are chosen again each round): its ± and diagnostics are over the same.
    let data = {
        let mut d = data.clone();
        d.f_idx = used.f_idx.clone();
        d
    };
    let chain = MeasurementChain::of(&data, &cur, zero_source, opts);
    if ambiguous.is_empty() && chain.as_ref().is_some_and(|c| c.force_zero_significant) {
        ambiguous = vec![
            Effect::DirectionAsymmetry.name().to_string(),
            FORCE_ZERO_OFFSET.to_string(),
        ];
    }
    // The force channel's trend of μ0 over the motion (`tribo fit`'s drift check, on the same
    // samples, against the final model's law): a record whose μ0 drifts is never base-adequate.
    let mu0_trend = mu0_trend_of(&data, &cur);
    let drifting = mu0_trend.as_ref().is_some_and(|t| t.significant);
    // A friction level that differs between the two sides of the track (a worn stripe, a load
    // that varies along it): no effect of the vocabulary makes it, so what the search fitted to
    // it is not named — the record is unexplained, and where says why.
    // (Judged on the model with the running-in a stripe fitted as well, where the search left it
    // unnamed: the profile across the track is judged beside a drift.)
    let position = diag::position_dependence(&data, drift_model.as_ref().unwrap_or(&cur));
    let mut not_named = Vec::new();
    if position.as_ref().is_some_and(|p| p.significant) {
        not_named = steps.iter().map(|s| s.effect.clone()).collect();
        steps.clear();
        ambiguous.clear();
        stripe = None;
        cur = base.clone();
    }
    // What remains of the base law's excess over the floor, of the model kept (the base law when
    // what the search fitted is not named).
    let floor = data.noise_floor();
    let excess = |g: f64| (g * g - floor * floor).max(0.0).sqrt();
    let unexplained_fraction = if excess(base.gap) > 0.0 {
        (excess(cur.gap) / excess(base.gap)).min(1.0)
    } else {
        0.0
    };
    let conclusion = if !ambiguous.is_empty() {
        Conclusion::Ambiguous
    } else if cur.adequate(&data)
        && !(drifting && steps.is_empty())
        && !position.as_ref().is_some_and(|p| p.significant)
    {
        if steps.is_empty() {
            Conclusion::BaseAdequate
        } else {
            Conclusion::Explained
        }
    } else if steps.is_empty() {
        Conclusion::Unexplained
    } else {
        Conclusion::PartlyExplained
    };
    // Every named effect's constants are the final model's, the model the record is explained
    // by, with their ± from its sandwich: a step's were those of the model that step left, before
    // the effects named after it were fitted beside them (a Stribeck rise's speed 4 % off, 8σ,
    // once a quadratic term was named after it). A step's own ± (which the profile at the
    // effect's absence may have widened, and a zero measured over the hold widens for an
    // asymmetry) is kept where it is the wider.
    let final_se = final_constants(&used, &cur, &mut steps);
    progress("done", 1, 1);
    let lowpass = ForceLowpass::of(&data, &cur, source, order_evidence);
    // The release instant of the final model (the motion's measurement plus the offset fitted
    // with it) and its ± from the same sandwich as every constant's (the prior in it), with the
    // resolution of a staircase beside it: the force at a sample jumps when a reversal crosses
    // it, so the misfit is flat in the instant between two such crossings, n reversals making
    // about n of them per sample, and its minimum is known to one of them (uniform: a width over
    // √12). The sandwich alone on grid #6 (`grid(520, 1)`, 18.7 kS/s, ×8 noise): ± 0.11 µs for
    // an error of 0.43.
    let release = cur.spec.release_index().map(|i| {
        let se = final_se.get(i).copied().unwrap_or(f64::NAN);
        let crossings = simulate_spec(&used, &cur.spec, &cur.p)
            .map_or(0, |s| s.reversals.len())
            .max(1) as f64;
        let step = used.dtau / (crossings * 12f64.sqrt());
        let w = data.rig.omega();
        (
            used.release_shift_of(&cur.spec, &cur.p) / w,
            se.hypot(step) / w,
        )
    });
    let ex = Explanation {
        conclusion,
        base: opts.base,
        missing_effects: steps.iter().map(|s| s.effect.clone()).collect(),
        gap_initial: base.gap,
        gap_final: cur.gap,
        noise_floor: floor,
        noise_floor_envelope: data.env_floor(),
        noise_floor_force: data.has_force().then(|| data.force_floor()),
        unexplained_fraction,
        disagreement: if conclusion == Conclusion::BaseAdequate {
            Vec::new()
        } else {
            let mut d = diag::locate(&data, &cur);
            if let Some(t) = mu0_trend.as_ref().filter(|t| t.significant) {
                d.push(format!("the force channel's level: {}", t.text()));
            }
            if let Some(p) = position.as_ref().filter(|p| p.significant) {
                d.push(p.text());
                if !not_named.is_empty() {
                    d.push(format!(
                        "the search fitted {} to it, not named: the misfit is not of their form",
                        not_named.join(" + ")
                    ));
                }
            }
            d
        },
        position_dependence: position,
        drift_or_stripe: stripe,
        mu0_trend,
        steps,
        ambiguous,
        force_cutoff_hz: lowpass.as_ref().and_then(|l| l.cutoff_hz),
        force_cutoff_source: source.into(),
        force_lowpass: lowpass,
        measurement_chain: chain,
        release_offset_s: release.map(|(v, _)| v),
        release_offset_s_se: release.map(|(_, se)| se),
        rounds,
        base_fit,
        base_model: base,
        final_model: cur,
        diagnostics,
    };
    Ok((ex, used))
}

/// The force channel's trend of μ0 over the motion against the model `m`'s law (`tribo fit`'s
/// drift check, on the same samples, through `m`'s low-pass: the fitted one with its order, or
/// the stated one; a fitted one is profiled beside none and the bench's 2-pole cut-offs, as `tribo
/// fit` does for a record that does not state it). A drift already in `m` (thermal drift,
/// running-in: [`model::Mu0Drift`]) is taken out of the force channel first, through the same
/// low-pass, so the trend is the one that remains beside it. `None` without a force channel.
pub(crate) fn mu0_trend_of(
    data: &Prepared,
    m: &FittedModel,
) -> Option<tribo_physics::identify::Mu0Trend> {
    let f = data.f_meas.as_ref()?;
    let mu = m.spec.mu(&m.p);
    let fitted = m.spec.lowpass_tau(&m.p);
    let through = |c: &[f64]| match (fitted, data.force_cutoff_hz) {
        (Some(t), _) => m.spec.filter_force(c, t, data.dtau),
        (None, Some(fc)) => tribo_physics::sensor::butterworth2(c, fc, data.rate_hz),
        (None, None) => c.to_vec(),
    };
    // The model's drift as the force channel reads it (the contact's force is μ sgn y').
    let remaining = model::Mu0Drift::of(data, &m.spec, &m.p).map(|drift| {
        let level: Vec<f64> = drift
            .at_samples(data)
            .iter()
            .zip(&data.ydot)
            .map(|(d, v)| d * v.signum())
            .collect();
        f.iter()
            .zip(through(&level))
            .map(|(f, d)| f - d)
            .collect::<Vec<f64>>()
    });
    let f = remaining.as_ref().unwrap_or(f);
    if data.force_cutoff_known {
        return tribo_physics::identify::mu0_trend_through(
            &data.tau,
            &data.ydot,
            f,
            &mu,
            0..data.tau.len(),
            &through,
            1.0 / data.rig.omega(),
        );
    }
    // A low-pass the record does not state is, for the trend, one candidate beside none and the
    // bench's: the one `tribo fit`'s drift check profiles, so the two read the same trend.
    tribo_physics::identify::mu0_trend_profiled(
        &data.tau,
        &data.ydot,
        f,
        &mu,
        0..data.tau.len(),
        data.rate_hz,
        fitted.is_some().then_some(&through),
        1.0 / data.rig.omega(),
    )
}

/// Whether the effect `e` of the fitted model `m` is more than 2σ (its own standard error) from
/// its absence: zero for every constant, the Coulomb level for Stribeck's static level (and a
/// frictional lag's memory from the shortest one simulated, [`MEMORY_TAU_MIN`]). Stribeck's
/// is one-sided: the effect is a *rise* of friction at low sliding speed, and a static level
/// fitted below the Coulomb level (a dip) is not it (the grid's clean record #5, ×16 noise: μs
/// 7σ below μ0 with evidence 70 on a base model at 0.92 × its noise floor, named Stribeck). An
/// undetermined ± does not decide.
fn distinct_from_absence(m: &FittedModel, se: &[f64], e: Effect) -> bool {
    let (Some(q), Some(qs)) = (m.spec.effect_params(e, &m.p), m.spec.effect_params(e, se)) else {
        return true;
    };
    match e {
        Effect::Stribeck => {
            let z = (q[0] - m.spec.mu(&m.p)[0]) / qs[0];
            !(z.is_finite() && z < 2.0)
        }
        // A memory within 2σ of the shortest one simulated is the fit at the edge of its range,
        // not a memory measured (grid #186, a cubic stiffness of 0.15 % alone: beside it a lag
        // of 65 ± 15 µs, at that edge, had an evidence of 18 against none).
        Effect::FrictionalLag => {
            let z = (q[0] - MEMORY_TAU_MIN) / qs[0];
            !(z.is_finite() && z < 2.0)
        }
        _ => {
            let z = q[0] / qs[0];
            !(z.is_finite() && z.abs() < 2.0)
        }
    }
}

/// The model `m` (the current model `cur` plus the effect `e`) refitted with `e`'s constant held
/// at its absence (zero), from `m`'s other constants and from `cur`'s, the better kept; with the
/// constant's index in `m.p` and the value it is held at. For frictional lag, whose memory of 0
/// is below the simulated range ([`MEMORY_TAU_MIN`]), the model returned is `cur`'s law
/// without the lag (`cur.spec`), refitted from the same starts. `None` for Stribeck (its absence,
/// μs = μ0, is not a value of one constant) or if the fit fails.
fn profile_at_absence(
    data: &Prepared,
    cur: &FittedModel,
    m: &FittedModel,
    e: Effect,
    max_iter: usize,
) -> Option<(usize, f64, FittedModel)> {
    // Running-in is absent at Δ = 0 whatever its shape: held with it.
    if e == Effect::Stribeck || (e.n_params() != 1 && e != Effect::RunningIn) {
        return None;
    }
    let i = m.spec.effects.iter().position(|&x| x == e)?;
    let o = m.spec.offset(i);
    if e == Effect::FrictionalLag {
        // A memory is absent at 0, which the simulated range does not reach: its absence is
        // the law without one (the current model's spec), refitted from the lag fit's other
        // constants and from the current model's. Held at the shortest memory simulated
        // instead, it was no absence (grid #161, a frictional lag of 0.13 ms at 22 Hz: held at
        // 72 µs the rest refitted 78 units of χ² under the current model, while no model without
        // a lag came within them, and the lag's evidence 91 fell to 13).
        if m.spec != cur.spec.with(e) || o + 1 != m.p.len() {
            return None;
        }
        let mut a = m.p.clone();
        a.remove(o);
        return fit_spec(data, &cur.spec, &[a, cur.p.clone()], max_iter).map(|p| (o, 0.0, p));
    }
    let held = 0.0;
    let mut a = m.p.clone();
    a[o] = held;
    let mut starts = vec![a];
    let k = e.n_params();
    if cur.p.len() + k == m.p.len() && o == cur.p.len() {
        let mut b = cur.p.clone();
        b.extend_from_slice(&m.p[o..o + k]);
        b[o] = held;
        starts.push(b);
    }
    let idx: Vec<usize> = (o..o + k).collect();
    fit_spec_held(data, &m.spec, &starts, &idx, max_iter).map(|p| (o, held, p))
}

/// The fit of a named effect, moved to the bottom of its valley. The force channel's misfit is
/// only piecewise smooth in the parameters (a velocity reversal crossing a sample instant changes
/// the sampled force by a step), so Levenberg–Marquardt can stop in a small hollow of it: on a
/// −10 % cubic stiffness it stopped 4.7 σ (its own ±) from the truth, where the misfit with the
/// rest re-fitted was 60 units of χ² below. The fit is restarted with each of the effect's
/// constants moved by ±3 of its standard errors, and the best is kept.
fn settle(data: &Prepared, m: FittedModel, e: Effect, max_iter: usize) -> FittedModel {
    let Some(i) = m.spec.effects.iter().position(|&x| x == e) else {
        return m;
    };
    let o = m.spec.offset(i);
    let se = standard_errors_of(data, &m);
    let mut starts = Vec::new();
    for j in o..o + e.n_params() {
        let s = se.get(j).copied().unwrap_or(f64::NAN);
        if !(s.is_finite() && s > 0.0) {
            continue;
        }
        for d in [-3.0, 3.0] {
            let mut p = m.p.clone();
            p[j] += d * s;
            if m.spec.in_range(&p, data.a0) {
                starts.push(p);
            }
        }
    }
    match fit_spec(data, &m.spec, &starts, max_iter) {
        Some(b) if b.chi2 < m.chi2 => b,
        _ => m,
    }
}

/// The record's noise model ([`model::NoiseModel`]) set from the residuals of `m`, and `m`
/// refitted under it from its own constants (kept if its `−2 ln L` under the new weights is
/// smaller; `m`'s standard errors are kept): one step of iteratively reweighted least squares,
/// so that the model the next comparison is made against maximises the likelihood that
/// comparison uses.
fn reweigh(data: &Prepared, m: &FittedModel, max_iter: usize) -> (Prepared, FittedModel) {
    let mut d = data.clone();
    d.noise = Some(model::NoiseModel::of(data, &m.env_resid, &m.force_resid));
    let old = evaluate(&d, &m.spec, &m.p);
    let refit = fit_spec(&d, &m.spec, std::slice::from_ref(&m.p), max_iter);
    let best = match (old, refit) {
        (Some(o), Some(r)) if r.chi2 < o.chi2 => r,
        (Some(o), _) => o,
        (None, Some(r)) => r,
        (None, None) => {
            // Not evaluable under the new weights (cannot happen for a model that was): its
            // likelihood there is that of its own residuals.
            let mut c = m.clone();
            c.chi2 = d.chi2(&m.env_resid, &m.force_resid) + d.release_chi2(&m.spec, &m.p);
            c
        }
    };
    let best = FittedModel {
        params_se: m.params_se.clone(),
        ..best
    };
    (d, best)
}

/// `m` (a model that has just taken a Stribeck rise) or the same model with the curve's other
/// exponent ([`model::STRIBECK_DELTAS`]), fitted from `m`'s constants, from the rise's own
/// `starts` and from taller, narrower rises than `m`'s, whichever fits better.
fn stribeck_exponent(
    data: &Prepared,
    m: FittedModel,
    starts: &[Vec<f64>],
    max_iter: usize,
) -> FittedModel {
    let mut best = m;
    for d in model::STRIBECK_DELTAS {
        if d == best.spec.stribeck_delta {
            continue;
        }
        let spec = Spec {
            stribeck_delta: d,
            ..best.spec.clone()
        };
        let mut from = vec![best.p.clone()];
        from.extend(starts.iter().cloned());
        // And from a taller, narrower rise: the exponential curve reaches the same force over
        // the sliding speeds with a higher static level and a lower speed than the Gaussian one
        // (grid #337, 93 % with exponent 1: from the exponent-2 fit's own constants the fit stopped
        // at −2 ln L 388 against 371 with 2; from these it takes μs and vs within 0.3σ and 0.5σ).
        if let Some(i) = best
            .spec
            .effects
            .iter()
            .position(|&x| x == Effect::Stribeck)
        {
            let o = best.spec.offset(i);
            let mu0 = best.spec.mu(&best.p)[0];
            for (rise, speed) in [(1.3, 0.7), (1.6, 0.5), (1.3, 0.5), (1.6, 0.7)] {
                let mut q = best.p.clone();
                q[o] = mu0 + rise * (q[o] - mu0);
                q[o + 1] *= speed;
                from.push(q);
            }
        }
        if let Some(o) = fit_spec(data, &spec, &from, 3 * max_iter).filter(|o| o.chi2 < best.chi2) {
            best = o;
        }
    }
    best
}

/// Sets every step's constants to those of the final model `cur` (fitted on `data`), their ± to
/// the wider of the final model's and the step's own; returns the final model's standard errors
/// (every parameter, `NaN` where one cannot be determined).
fn final_constants(data: &Prepared, cur: &FittedModel, steps: &mut [Step]) -> Vec<f64> {
    let (cov, se) = covariance_and_errors(data, cur);
    for st in steps.iter_mut() {
        let Some(e) = Effect::from_name(&st.effect).filter(|&e| cur.spec.has(e)) else {
            continue;
        };
        let mut params = effect_params(data, &cur.spec, &cur.p, e);
        let mut params_se = effect_params_se(data, &cur.spec, &cur.p, &se, cov.as_deref(), e);
        relative_asymmetry(cur, e, &mut params, Some(&mut params_se));
        for (k, v) in params_se.iter_mut() {
            if let Some(&own) = st.params_se.get(k) {
                if own.is_finite() && (v.is_nan() || *v < own) {
                    *v = own;
                }
            }
        }
        st.params = params;
        st.params_se = params_se;
    }
    se
}

/// Half-width of the band of force samples about each of the base model's velocity reversals
/// that is not compared ([`without_reversal_samples`]), in sample intervals.
pub const REVERSAL_BAND_SAMPLES: f64 = 1.5;

/// `data` with the force samples within [`REVERSAL_BAND_SAMPLES`] of each velocity reversal of
/// the reference model `base` left out of the comparison (`f_idx`, chosen from every compared
/// point, `f_idx_all`), and `base` evaluated on the rest; `None` without a force channel or if
/// nothing is left out. A Coulomb force changes sign at a
/// reversal, so the force a model gives at a sample instant jumps by `2 μ0` when a change of its
/// constants moves a reversal across that instant: the misfit is a staircase in the constants at
/// the scale of a sample interval (grid #99: a thermal drift of 7e-6 per K against 5e-6 moved one
/// reversal of 300 across one sample, and that sample alone raised `−2 ln L` by 371, so every fit
/// of the drift stopped at none, with the force channel's trend at 2.9σ). The samples next to the
/// reversals are chosen once, from the base model (fitted to the record), and held in every model
/// the search compares, so that every likelihood is of the same samples; they are a sample or
/// three in each half cycle. They are chosen again from the current model at the start of every
/// round of the search, with its noise model: a model missing a strong effect reverses at other
/// instants than the record (a cubic stiffness of 8 % of k moves the reversals by many samples
/// over 70 cycles), and the samples left out must be at the reversals of the models a round
/// compares.
fn without_reversal_samples(
    data: &Prepared,
    base: &FittedModel,
) -> Option<(Prepared, FittedModel)> {
    if !data.has_force() || data.f_idx_all.is_empty() {
        return None;
    }
    let sim = simulate_spec(data, &base.spec, &base.p).ok()?;
    let n = data.tau.len();
    let mut drop = vec![false; n];
    for &tr in &sim.reversals {
        // Sample i is at τ_i + release shift on the simulator's clock, τ_i = i dτ.
        let x = (tr - data.release_shift_of(&base.spec, &base.p)) / data.dtau;
        if !x.is_finite() {
            continue;
        }
        let lo = (x - REVERSAL_BAND_SAMPLES).ceil().max(0.0) as usize;
        let hi = (x + REVERSAL_BAND_SAMPLES).floor();
        if hi < 0.0 {
            continue;
        }
        for d in drop.iter_mut().take((hi as usize + 1).min(n)).skip(lo) {
            *d = true;
        }
    }
    let kept: Vec<usize> = data
        .f_idx_all
        .iter()
        .copied()
        .filter(|&i| !drop[i])
        .collect();
    if kept == data.f_idx || kept.len() < data.f_idx_all.len() / 2 {
        return None;
    }
    let mut d = data.clone();
    d.f_idx = kept;
    let b = evaluate(&d, &base.spec, &base.p)?;
    Some((d, b))
}

/// What [`search`] found.
struct Searched {
    /// The base model the steps start from (the one given, or a better fit of its law found on
    /// the way).
    start: FittedModel,
    /// The final model.
    cur: FittedModel,
    steps: Vec<Step>,
    /// The rounds' candidates.
    rounds: Vec<Vec<Candidate>>,
    /// The ambiguous pair, if any.
    ambiguous: Vec<String>,
    /// Running-in against a stripe of the track, where running-in was about to be named.
    stripe: Option<diag::DriftOrStripe>,
    /// The model with the running-in a stripe fitted as well, not named: the position check
    /// judges the track on it, as on a model that names a drift.
    drift_model: Option<FittedModel>,
    /// The data with the last round's noise model.
    data: Prepared,
}

/// The stepwise search from the base model: in each round every candidate effect is fitted and
/// scored against the current model, and the best one that passes every test is added. Every
/// comparison of a round is made under one likelihood ([`model::NoiseModel`]), measured on the
/// current model's residuals at the start of the round (for the first round, `data`'s, set from
/// the base model by the caller). Each round's refit under its noise model is the outcome of the
/// step before it (its gap and constants), so that the steps' gaps run from the base's to the
/// final model's without a jump.
fn search(
    data: &Prepared,
    opts: &ExplainOptions,
    diagnostics: &diag::Diagnostics,
    base: &FittedModel,
    progress: Progress,
) -> Searched {
    let mut cur = base.clone();
    let mut steps: Vec<Step> = Vec::new();
    let mut rounds = Vec::new();
    let mut ambiguous = Vec::new();
    let mut stripe = None;
    let mut drift_model = None;
    let mut redo = 0;
    let mut round = 0;
    let mut d = data.clone();
    let mut fresh = true;
    let mut start = base.clone();
    // The data and model before the last step, and the ± its effect was named with.
    let mut before_last: Option<(Prepared, FittedModel, Vec<f64>)> = None;
    let mut to_2pole = false;
    while round < opts.max_steps {
        round += 1;
        if !fresh {
            if let Some((d2, c2)) = without_reversal_samples(&d, &cur) {
                // (The model's ± are its fit's, kept as `reweigh` keeps them.)
                let params_se = std::mem::take(&mut cur.params_se);
                (d, cur) = (d2, FittedModel { params_se, ..c2 });
            }
            (d, cur) = reweigh(&d, &cur, opts.max_iter);
            // A fitted low-pass's order was chosen with the base law, and an effect the base
            // law missed can have chosen it (grid #347, a hardening cubic of 7.4 % with a thermal
            // drift behind a 1-pole filter at 232 Hz: the base law, 11 × its floor, took 2
            // poles, and beside the cubic and the drift a Stribeck rise of evidence 238 made up
            // the 1-pole's shape; after the cubic the 1-pole fits better by evidence 1 826). It
            // is chosen again with the model each step leaves, where the other order fits that
            // model better by the evidence a change needs (a better fit by 5.8 took #448's
            // 1-pole, a Stribeck rise with a frictional lag, to 2 poles and lost the rise). A
            // 2-pole's extra phase is what a pure delay beside a 1-pole mimics: after a change
            // from 1 pole to 2 the sensor lag is tried again at the floor (#400, a lag with a
            // 0.91 ms delay and no filter: after the lag the 2-pole, better by evidence 1 040,
            // took the model to its floor, and the delay went untried). Not after a change from
            // 2 poles to 1, which takes no delay's place (tried there, delays of 40 ± 16 and
            // 85 ± 39 µs were named beside #154's and #274's cubic stiffness alone).
            to_2pole = false;
            if let Some(o) = filter_order_again(&d, &cur, opts) {
                to_2pole = o.spec.lowpass_poles == 2 && cur.spec.lowpass_poles == 1;
                cur = FittedModel {
                    params_se: std::mem::take(&mut cur.params_se),
                    ..o
                };
            }
            // The model the last step left, refitted under the new noise model, is that step's
            // outcome: its gap and its effect's constants (their ± are the step's own).
            if steps.is_empty() {
                // A better fit of the base law than the one the search was given (the profile's
                // "better without" in the first round): the base the steps start from.
                start = cur.clone();
            }
            if let Some(last) = steps.last_mut() {
                last.gap_after = cur.gap;
                if let Some(e) = Effect::from_name(&last.effect) {
                    let mut params = effect_params(&d, &cur.spec, &cur.p, e);
                    relative_asymmetry(&cur, e, &mut params, None);
                    last.params = params;
                    // A constant the refit moved to within 2σ of its absence, or a memory to
                    // the edge of its range, was not what the record showed: the step is
                    // withdrawn and the search ends on the model before it (grid #379, thermal
                    // drift with a 0.73 ms sensor delay: a frictional lag named at 0.046 ± 0.003
                    // rad slid to 0.0100, the shortest memory, and held the wrong filter order
                    // in place). The ± is the one the constant would be reported with, the wider
                    // of the step's own and the refit's ([`final_constants`]), and the check is
                    // made each round until another step is named: the refit from a better model
                    // that a later candidate's profile found (`better_without`) moves it too
                    // (grid #331, a quadratic term with a cubic stiffness: a sensor delay named
                    // beside the cubic at 0.30 ± 0.03 ms went to 34 ± 24 µs there, and stayed).
                    if let Some((d0, c0, se0)) = before_last.as_ref() {
                        let (_, se_now) = covariance_and_errors(&d, &cur);
                        let se: Vec<f64> =
                            se0.iter().zip(&se_now).map(|(a, b)| a.max(*b)).collect();
                        if !distinct_from_absence(&cur, &se, e) {
                            steps.pop();
                            (d, cur) = (d0.clone(), c0.clone());
                            break;
                        }
                    }
                }
            }
        }
        // A Stribeck rise's exponent was chosen beside the effects named before it: with those
        // named after it, the other exponent can fit better, and a velocity term was named to
        // make up the curve's shape (grid #308, a rise of exponent 1 with a frictional lag: the
        // rise took exponent 2 before the lag, and a quadratic term followed). It is chosen again
        // each round with the model it is held in.
        if !fresh
            && cur.spec.has(Effect::Stribeck)
            && steps
                .last()
                .is_some_and(|s| s.effect != Effect::Stribeck.name())
        {
            let m = stribeck_exponent(&d, cur.clone(), &[], opts.max_iter);
            if m.spec.stribeck_delta != cur.spec.stribeck_delta {
                cur = FittedModel {
                    params_se: std::mem::take(&mut cur.params_se),
                    ..m
                };
            }
        }
        fresh = false;
        let data = &d;
        // Once the model is at the noise floor, the envelope and the force have nothing left to
        // point at: an effect is still tried only where another channel points to it (thermal
        // drift when the temperature column moves over the motion), and it must still pass the
        // same tests. (Every candidate, running-in included, is tried in the first round, at
        // the floor or not: a drift of μ0 over the whole motion can hide below the 1.5 × floor
        // rule.) A second velocity term fitted to a misfit below the noise is not a finding.
        //
        // Except where the force channel points on: the base model's misfit can hide the second
        // effect of a pair in the first round (quadratic velocity's evidence was 0.0 beside a
        // cubic stiffness of evidence 3.6e5, grid #415), and the first effect can take the model
        // under 1.5 × its floor with the second still missing. When the force channel's level
        // drifts over the motion against the current model (the drift check, significant), the
        // effects that drift points to are tried again, under the same tests: a drift in time
        // (running-in, thermal drift) or a law that misses how the force follows the speed
        // (quadratic velocity, Stribeck). Not the sensor lag, which that check does not point to
        // (tried on every candidate, a sensor lag of 46 µs was named beside a frictional lag,
        // grid #105, and beside a cubic stiffness and a lag, #349).
        //
        // The sensor lag is tried where the force channel's level differs across the track
        // against the current model (the position check, significant): a delay of the force
        // behind the motion moves the level it reads at each place of the swing, which no
        // effect of the law does and which the position check then takes for a stripe of the
        // track, setting aside every name (grid #320, a cubic stiffness of 4 % with a 2.3 ms
        // delay: the cubic took the model to its floor and the record was called unexplained;
        // #428, a frictional lag of 1.9 ms with a 2.3 ms delay, the same). Under the same tests.
        //
        // And a cubic stiffness and a frictional lag, the two effects that change the motion
        // itself (the frequency with the amplitude, the energy each cycle loses): the 1.5 × floor
        // rule weighs the misfit of a second one poorly once the first is in. On grid #314 (a
        // frictional lag of 0.83 ms with a cubic stiffness of 3.1 %) the lag's evidence was 769
        // at 1.06 × the floor after the cubic; on #342 (a cubic stiffness of 0.8 % with a lag of
        // 4.3 ms) the cubic's was 382 at 1.04 × after the lag, the drift check pointing to the
        // drifts. Both went unnamed. They must pass the same tests.
        //
        // And the quadratic term μ2 (not a higher one), once: a constant nested in the law at
        // 0, whose misfit is a small change of the force's shape over each half cycle that the
        // gap, an RMS over every sample, does not weigh. After the first effect of a pair took
        // the model to its floor it was never tried again: grid #445 (quadratic velocity 9.6 %
        // with a sensor lag, ×16 noise) at 0.97 × its floor after the lag, where the quadratic
        // term beside it has evidence 80 and μ2 10σ from zero (the truth within 1σ); #358
        // (with a frictional lag, ×46) at 1.00 ×, evidence 34, 8σ. It must pass the same tests.
        //
        // And a direction asymmetry, where the force channel's zero is known (stated or measured
        // over the hold; the filter below keeps it out otherwise): it is a constant force offset
        // while sliding, which the gaps hardly see (on grid #439 an offset of 1e-5 N under a
        // force noise of 2e-4 N: the gap at 0.99 × its floor, the asymmetry's evidence against
        // the held zero 167 in round 1, and it was not tried again after the sensor lag). It
        // must still pass the same tests. Where the force channel's level drifts too (a constant
        // offset is a level the current model misses: on #374, frictional lag with an asymmetry of
        // 7.6 %, the drift check read 5.2σ and only the drifts and velocity terms were tried).
        let at_floor = round > 1 && cur.adequate(data);
        let drift_points = at_floor && mu0_trend_of(data, &cur).is_some_and(|t| t.significant);
        let position_points =
            at_floor && diag::position_dependence(data, &cur).is_some_and(|p| p.significant);
        let settled = at_floor && !drift_points && !position_points;
        let todo: Vec<Effect> = opts
            .candidates
            .iter()
            .copied()
            .filter(|&e| cur.spec.can_add(e, data.has_force(), data.has_temp()))
            // A direction asymmetry is a constant force offset with the centre moved: without the
            // force channel's zero it is the zero offsets themselves (fitted in every model).
            .filter(|&e| e != Effect::DirectionAsymmetry || data.force_zero.is_some())
            .filter(|&e| {
                !at_floor
                    || (e == Effect::ThermalDrift && diagnostics.temperature_moves())
                    || e == Effect::DirectionAsymmetry
                    || (e == Effect::QuadraticVelocity && cur.spec.order() < 2)
                    || changes_the_motion(e)
                    || ((position_points || to_2pole) && e == Effect::SensorLag)
                    || (drift_points
                        && matches!(
                            e,
                            Effect::RunningIn
                                | Effect::ThermalDrift
                                | Effect::QuadraticVelocity
                                | Effect::Stribeck
                        ))
            })
            // A Coulomb level that moves while the plate's temperature moves is read as thermal
            // drift first; running-in is what a drift in time leaves beside it.
            .filter(|&e| {
                e != Effect::RunningIn
                    || !diagnostics.temperature_moves()
                    || cur.spec.has(Effect::ThermalDrift)
            })
            .collect();
        if todo.is_empty() {
            break;
        }
        let mut scored: Vec<(Effect, Option<(FittedModel, Evidence)>)> = Vec::new();
        let mut cur_other = None;
        for (i, &e) in todo.iter().enumerate() {
            progress(
                &format!("round {}: trying {}", round, e.name()),
                i,
                todo.len(),
            );
            let s = cur.spec.with(e);
            let starts = starts_for(data, &cur, e, diagnostics);
            // A sensor lag is also fitted with the other order of a fitted filter, the better
            // kept: a pure delay beside a 1-pole filter is what the 2-pole's extra phase mimics,
            // so the order chosen at the base law can have taken the delay in (grid #124, a 1-pole
            // filter at 315 Hz with a delay of 0.36 ms: the base law chose a 2-pole at 268 Hz
            // and the delay's evidence beside it was 3; with the 1-pole, 44, the delay 0.358 ±
            // 0.045 ms and the filter 323 ± 26 Hz). A model of the other order is judged against
            // the better of the current model and the same refitted with that order
            // ([`judged_against`]): the delay is credited with what it adds, not with the order
            // (grid #202, a 2-pole filter the base law took as a 1-pole beside an 8.8 % cubic:
            // the switch to the 2-pole, not the delay of 0.34 ms fitted with it, explained the
            // record, and the delay was named).
            let fitted = fit_spec(data, &s, &starts, opts.max_iter).map(|m| {
                let m = if e == Effect::SensorLag && m.spec.lowpass {
                    match other_order(data, &m, opts.max_iter) {
                        Some(o) if o.chi2 < m.chi2 => o,
                        _ => m,
                    }
                } else {
                    m
                };
                let against = judged_against(data, &cur, &mut cur_other, &m, opts.max_iter);
                let ev = Evidence::of(data, against, &m, opts);
                (m, ev)
            });
            scored.push((e, fitted));
        }
        rounds.push(
            scored
                .iter()
                .map(|(e, m)| Candidate {
                    effect: e.name().into(),
                    gap: m.as_ref().map(|m| m.0.gap),
                    evidence: m.as_ref().map(|m| m.1.value),
                    excess_removed: m.as_ref().map(|m| m.1.excess_removed),
                    significant: m.as_ref().is_some_and(|m| m.1.significant(opts)),
                })
                .collect(),
        );
        let mut fitted: Vec<(Effect, FittedModel, Evidence)> = scored
            .into_iter()
            .filter_map(|(e, m)| m.map(|(m, ev)| (e, m, ev)))
            .collect();
        fitted.sort_by(|a, b| b.2.value.total_cmp(&a.2.value));
        let mut ranked: Vec<(Effect, FittedModel, Evidence)> = fitted
            .iter()
            .filter(|(_, _, ev)| ev.significant(opts))
            .cloned()
            .collect();
        // Two effects at once, each of which alone removes too small a share of the excess (a
        // frictional lag and a sensor delay of 4–5 ms: each took 3–22 % of it, grid #316 and
        // #344, and the record was called unexplained). Where no candidate qualifies, the
        // pairs of the (up to three) candidates whose evidence passes its threshold are fitted;
        // a pair that removes the share an effect needs, with each member needed beside the
        // other (its evidence against the pair without it), lets its stronger member be named
        // in this round under the same tests but the share, which the pair meets. The other
        // must then qualify on its own in the next round.
        let mut paired: Option<(Effect, Evidence)> = None;
        if ranked.is_empty() && !settled {
            let strong: Vec<&(Effect, FittedModel, Evidence)> = fitted
                .iter()
                .filter(|(_, _, ev)| ev.value >= ev.threshold)
                .take(3)
                .collect();
            let mut best_pair: Option<(usize, Effect, Evidence)> = None;
            for (i, a) in strong.iter().enumerate() {
                for b in &strong[i + 1..] {
                    if let Some(ev) = fit_pair(data, &cur, &mut cur_other, a, b, diagnostics, opts)
                    {
                        if best_pair.as_ref().is_none_or(|p| ev.value > p.2.value) {
                            best_pair = Some((i, b.0, ev));
                        }
                    }
                }
            }
            if let Some((i, other, ev)) = best_pair {
                ranked.push(strong[i].clone());
                paired = Some((other, ev));
            }
        }
        let qualifies =
            |ev: &Evidence| ev.significant(opts) || (paired.is_some() && ev.value >= ev.threshold);
        let Some(best) = ranked.first() else {
            break;
        };
        // The runner-up among every candidate, qualified or not: an effect that explains the
        // record about as well (or better) but misses a threshold by a little is no ground for
        // naming the other. The tie is declared once the winner has passed the tests below (its
        // profile at its absence, its own ± from it): a winner that fails them is not named
        // whatever its rival, and its screening evidence is no ground for calling the record
        // ambiguous (grid #177, a frictional lag alone at 0.97 × its floor: a direction
        // asymmetry of screening evidence 27 against the held zero, not significant with the
        // zero's ±, tied with a quadratic term of 23 that its profile finds is a hollow of the
        // current model; the lag was named, then the record was called ambiguous).
        let tie = rounds
            .last()
            .into_iter()
            .flatten()
            .filter(|c: &&Candidate| c.effect != best.0.name())
            .filter_map(|c| Some((c.effect.clone(), c.evidence?)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .filter(|(_, ev)| best.2.value - ev < opts.min_margin)
            .map(|(name, _)| vec![best.0.name().to_string(), name]);
        let (e, m, _) = best.clone();
        // Polish the winner (candidates are screened with a short iteration budget).
        let m = fit_spec(data, &m.spec, std::slice::from_ref(&m.p), 3 * opts.max_iter)
            .filter(|p| p.chi2 <= m.chi2)
            .unwrap_or(m);
        // A Stribeck rise that won is given the other exponent a contact shows, kept where it
        // fits better ([`Spec::stribeck_delta`]).
        let m = if e == Effect::Stribeck {
            stribeck_exponent(
                data,
                m,
                &starts_for(data, &cur, e, diagnostics),
                opts.max_iter,
            )
        } else {
            m
        };
        let m = settle(data, m, e, opts.max_iter);
        let against = judged_against(data, &cur, &mut cur_other, &m, opts.max_iter);
        let mut ev = Evidence::of(data, against, &m, opts);
        let (cov, mut se) = covariance_and_errors(data, &m);
        // The profile of the effect's constant at its absence (the rest refitted there, from the
        // effect's own fit): the force misfit jumps with the parameters (a velocity reversal
        // crossing a sample instant), so the Jacobian's ± can be far too small (the grid's clean
        // #22 and thermal-drift #75 were named cubic with k3 ± 601 and ± 70 N/m³, 10⁴σ from
        // zero) and the current model can sit in a hollow the effect's fit left (the evidence
        // was then the hollow's, not the effect's). The evidence is against the better of the
        // two models without the effect, and the ± is at least what the profile's Δχ² between
        // the constant and its absence gives (|q| / √Δχ²).
        let mut better_without = None;
        if let Some((o, held, prof)) = profile_at_absence(data, &cur, &m, e, opts.max_iter) {
            let evp = Evidence::of(data, &prof, &m, opts);
            let q = m.p[o] - held;
            let s_prof = if evp.value > 0.0 {
                q.abs() / evp.value.sqrt()
            } else {
                f64::INFINITY
            };
            if se[o].is_nan() || se[o] < s_prof {
                se[o] = s_prof;
            }
            if evp.value < ev.value {
                ev = evp;
            }
            // The current model without the effect, refitted from the profile's constants: when
            // the current model sat in a hollow that the effect's fit left (grid #331, a cubic
            // stiffness fitted: frictional lag at its bound, thermal drift and sensor lag then
            // all "significant" by thousands), the search goes on from the better model.
            if prof.chi2 < cur.chi2 {
                better_without = if prof.spec == cur.spec {
                    Some(prof)
                } else {
                    let mut start = prof.p.clone();
                    start.remove(o);
                    fit_spec(data, &cur.spec, &[start], opts.max_iter).filter(|b| b.chi2 < cur.chi2)
                };
            }
        }
        if !qualifies(&ev) {
            match better_without {
                Some(b) if redo < 1 => {
                    redo += 1;
                    round -= 1;
                    cur = with_standard_errors(data, b);
                    continue;
                }
                _ => break,
            }
        }
        // A direction asymmetry is the force channel's offset while sliding against its zero:
        // a zero measured over the magnet's hold brings its own ± (`σ_z`, the asymmetry's
        // `δ = offset / gain`), which the fit with the zero held does not see. It is added to
        // the asymmetry's ± in quadrature, and the evidence, `(δ / σ_δ)²` for one constant,
        // is scaled to the wider ±.
        if e == Effect::DirectionAsymmetry && data.force_zero_se > 0.0 {
            if let Some(i) = m.spec.effects.iter().position(|&x| x == e) {
                let o = m.spec.offset(i);
                let gain = simulate_spec(data, &m.spec, &m.p)
                    .ok()
                    .map(|s| model::chain::fit(data, &s, data.force_zero).gain)
                    .filter(|g| g.is_finite() && *g > 0.0)
                    .unwrap_or(1.0);
                let s_fit = se[o];
                let s_tot = s_fit.hypot(data.force_zero_se / gain);
                if s_fit.is_finite() && s_tot > 0.0 {
                    let shrink = (s_fit / s_tot).powi(2);
                    ev.value *= shrink;
                    for c in &mut ev.channels {
                        c.evidence *= shrink;
                    }
                }
                se[o] = s_tot;
            }
            if !qualifies(&ev) {
                break;
            }
        }
        let mut m = m;
        m.params_se = named_params_se(data, &m.spec, &m.p, &se, cov.as_deref());
        // The effect's own constant must be told from its absence by its own ±: the randomized
        // grid (issue #32) found clean records named "cubic-stiffness" with evidence 70–870 and a
        // κ 0.4–0.8 σ from zero (the misfit the evidence saw was the base model's, not one the
        // effect's constant accounts for). An effect whose constant is within 2σ of its absence
        // is not named.
        if !distinct_from_absence(&m, &se, e) {
            break;
        }
        // A cubic stiffness or a frictional lag tried at the floor (it changes the motion, which
        // the 1.5 × floor rule weighs poorly) must be seen in the motion: the envelope channel's
        // evidence at least 4, a constant at 2σ. The force channel's misfit alone moves in steps
        // with the parameters (a reversal crossing a sample instant), and the floor leaves it
        // little else to fit (grid #248, a Stribeck rise alone: beside it a cubic of 0.01 % of k,
        // envelope 0.2 and force 49; the lag after #314's cubic had 25 and 744, the cubic after
        // #342's lag 17 and 365).
        if at_floor && changes_the_motion(e) && unseen_in_the_motion(&ev) {
            break;
        }
        // A cubic stiffness the motion does not show (the envelope channel's evidence under 4)
        // is a force that depends on where the pin slides, all its evidence in the force
        // channel: a stripe of the track is its rival there. It is named only where its own
        // shape explains the force channel's friction level at least as well as the best
        // stripe, given the stripe's freedom of where it lies ([`diag::drift_or_stripe`], the
        // cubic's shape in place of the drift's); otherwise the record is ambiguous between
        // them (grid #503, a +19 % stripe at −73 µm, ×34 the noise, was named a cubic of
        // evidence 343, the envelope −0.1: the cubic's shape 2.8 on the friction level, the
        // stripe 83; cubic stiffnesses the envelope does not see, from 0.06 % of k, have their
        // shape ahead by 19 or more).
        if e == Effect::CubicStiffness && unseen_in_the_motion(&ev) {
            if let Some(c) = diag::drift_or_stripe(data, &cur, &m) {
                let freedom = (opts.threshold(3) - opts.threshold(ev.k)).max(0.0);
                // Unless that stripe is a drift in time: the round's running-in leaves no stripe
                // beside it (grid #321, a cubic of 1.3 % with a running-in of 23 %: in the
                // search with the filter order it later left, the cubic's shape 0.1, a stripe
                // across the centre 152, which the running-in took).
                let a_drift = || {
                    fitted
                        .iter()
                        .find(|f| f.0 == Effect::RunningIn)
                        .and_then(|r| diag::drift_or_stripe(data, &cur, &r.1))
                        .is_some_and(|r| r.stripe_beside_drift <= stripe_beside_limit(opts))
                };
                if c.stripe - freedom > c.drift && !a_drift() {
                    stripe = Some(diag::DriftOrStripe {
                        freedom,
                        close: true,
                        ..c
                    });
                    ambiguous = vec![e.name().to_string(), POSITION_LEVEL.to_string()];
                    drift_model = Some(m);
                    break;
                }
            }
        }
        // Running-in is a rival of a stripe of the track: a stripe near the centre takes a
        // larger share of each swing as the amplitude decays, which the force and the envelope
        // read as a drift in time, and no effect of the vocabulary is one (grid #499, #507,
        // named running-in). Running-in is named only where it explains the force channel at
        // least as well as the best stripe, given the stripe's freedom of where it lies;
        // otherwise the record is ambiguous between them ([`diag::drift_or_stripe`]). The
        // comparison is kept and shown either way (a stripe within the margin a candidate needs
        // over its runner-up is a caveat of the name). Not thermal drift: it follows the
        // measured temperature, not a shape of its own in time.
        if e == Effect::RunningIn {
            if let Some(c) = diag::drift_or_stripe(data, &cur, &m) {
                let freedom = (opts.threshold(3) - opts.threshold(ev.k)).max(0.0);
                let c = diag::DriftOrStripe {
                    freedom,
                    close: c.stripe - freedom > c.drift - opts.min_margin,
                    ..c
                };
                // Nor where a stripe is there beside it: the stripe's evidence beside the drift
                // passes the false-alarm rate of one round for its 3 constants (where it begins
                // and ends, its level). A stripe that a drift takes most of leaves such a share
                // (grid #483, a −11 % stripe: the drift 102.9 alone, the stripe 102.2, beside
                // the drift 17.3); a drift leaves a stripe little beside it (the grid's records
                // named running-in, alone and in pairs: at most 10.1).
                let stripe_wins = c.stripe - freedom > c.drift
                    || c.stripe_beside_drift > stripe_beside_limit(opts);
                stripe = Some(c);
                if stripe_wins {
                    ambiguous = vec![e.name().to_string(), POSITION_LEVEL.to_string()];
                    drift_model = Some(m);
                    break;
                }
            }
        }
        // Two rivals that are both there: where the pair of the winner and its rival explains the
        // record with each needed beside the other, the record is not ambiguous between them
        // (grid #432, a cubic stiffness of 1.7 % with a sensor delay of 3 ms: evidence 887 and
        // 878). The winner is named and the rival must qualify on its own beside it.
        let tie = tie.filter(|t| {
            let rival = fitted.iter().find(|f| f.0.name() == t[1]);
            rival.is_none_or(|r| {
                fit_pair(data, &cur, &mut cur_other, best, r, diagnostics, opts).is_none()
            })
        });
        if let Some(t) = tie {
            ambiguous = t;
            break;
        }
        let mut params = effect_params(data, &m.spec, &m.p, e);
        let mut params_se = effect_params_se(data, &m.spec, &m.p, &se, cov.as_deref(), e);
        relative_asymmetry(&m, e, &mut params, Some(&mut params_se));
        let by_its_own = ev.significant(opts);
        steps.push(Step {
            effect: e.name().into(),
            gap_before: cur.gap,
            gap_after: m.gap,
            evidence: ev,
            params,
            params_se,
            paired_with: paired
                .as_ref()
                .filter(|_| !by_its_own)
                .map(|(other, pe)| PairedWith {
                    effect: other.name().into(),
                    evidence: pe.value,
                    threshold: pe.threshold,
                    excess_removed: pe.excess_removed,
                }),
        });
        before_last = Some((d.clone(), std::mem::replace(&mut cur, m), se));
    }
    Searched {
        start,
        cur,
        steps,
        rounds,
        ambiguous,
        stripe,
        drift_model,
        data: d,
    }
}

/// The current model with its fitted low-pass's order chosen again, where the better of its
/// fits with each order fits better than `cur` by the evidence a change needs. Each order is
/// fitted from `cur`'s constants with the chain's nuisances started afresh (the release
/// amplitude's correction and the blades' damping at 0: a model fitted under the wrong order can
/// have dragged them along), the filter at the time constant of the same delay; the other order
/// also from `cur`'s constants as they are.
fn filter_order_again(
    data: &Prepared,
    cur: &FittedModel,
    opts: &ExplainOptions,
) -> Option<FittedModel> {
    let max_iter = opts.max_iter;
    let i = cur.spec.lowpass_index()?;
    let fresh = |p: &[f64], tau: f64| {
        let mut p = p.to_vec();
        let n = cur.spec.powers.len();
        p[n] = 0.0;
        if cur.spec.apparatus {
            p[n + 1] = 0.0;
        }
        p[i] = tau;
        p
    };
    let t = cur.p[i].abs();
    let mut best: Option<FittedModel> = None;
    for poles in [1u8, 2] {
        let spec = Spec {
            lowpass_poles: poles,
            lowpass_digital: poles == cur.spec.lowpass_poles && cur.spec.lowpass_digital,
            ..cur.spec.clone()
        };
        let other_t = if poles == cur.spec.lowpass_poles {
            t
        } else {
            same_delay_tau(t, poles)
        };
        let mut starts = vec![fresh(&cur.p, other_t)];
        if poles != cur.spec.lowpass_poles {
            let mut a = cur.p.clone();
            a[i] = other_t;
            starts.push(a);
        }
        if let Some(m) = fit_spec(data, &spec, &starts, max_iter) {
            if m.chi2 < best.as_ref().map_or(cur.chi2, |b| b.chi2) {
                best = Some(m);
            }
        }
    }
    best.filter(|b| {
        let ev = Evidence::of(data, cur, b, opts);
        ev.value >= ev.threshold
    })
}

/// Whether the motion does not show an effect: the envelope channel's evidence under 4, or no
/// envelope channel (an effect that changes the motion, tried at the floor, must be seen there;
/// a cubic stiffness that is not is a force that depends on where the pin slides).
fn unseen_in_the_motion(ev: &Evidence) -> bool {
    ev.channels
        .iter()
        .find(|c| c.channel == "envelope")
        .is_none_or(|c| c.evidence < 4.0)
}

/// The evidence past which a stripe of the track is there beside a drift
/// ([`diag::DriftOrStripe::stripe_beside_drift`]): the false-alarm rate of one round for the
/// stripe's 3 constants (where it begins and ends, its level).
fn stripe_beside_limit(opts: &ExplainOptions) -> f64 {
    chi2_upper_quantile(3, opts.false_alarm)
}

/// The current model with the two effects of `a` and `b` (each fitted alone beside it), from each
/// one's fit with the other's start: its evidence against `cur`, when the pair removes
/// the share of the excess an effect needs and each member is needed beside the other (the pair's
/// evidence against the other's fit alone passes the member's threshold).
fn fit_pair(
    data: &Prepared,
    cur: &FittedModel,
    cur_other: &mut Option<Option<FittedModel>>,
    a: &(Effect, FittedModel, Evidence),
    b: &(Effect, FittedModel, Evidence),
    diagnostics: &diag::Diagnostics,
    opts: &ExplainOptions,
) -> Option<Evidence> {
    let (ea, eb) = (a.0, b.0);
    let mut spec = cur.spec.with(ea).with(eb);
    // A sensor lag's fit may have taken the other order of a fitted filter (`search`): the pair
    // keeps it.
    if let Some(o) = [a, b].iter().find(|x| x.0 == Effect::SensorLag) {
        spec.lowpass_poles = o.1.spec.lowpass_poles;
        spec.lowpass_digital = o.1.spec.lowpass_digital;
    }
    let n = cur.p.len();
    let (na, nb) = (ea.n_params(), eb.n_params());
    let extra = |e: Effect| -> Vec<f64> {
        starts_for(data, cur, e, diagnostics)
            .first()
            .map(|p| p[n..].to_vec())
            .unwrap_or_default()
    };
    let (xa, xb) = (extra(ea), extra(eb));
    if xa.len() != na || xb.len() != nb {
        return None;
    }
    let mut s1 = a.1.p.clone();
    s1.extend_from_slice(&xb);
    let mut s2 = b.1.p[..n].to_vec();
    s2.extend_from_slice(&xa);
    s2.extend_from_slice(&b.1.p[n..]);
    let m = fit_spec(data, &spec, &[s1, s2], opts.max_iter)?;
    let ev = Evidence::of(
        data,
        judged_against(data, cur, cur_other, &m, opts.max_iter),
        &m,
        opts,
    );
    let needed = |without: &FittedModel| {
        let e = Evidence::of(data, without, &m, opts);
        e.value >= e.threshold
    };
    (ev.significant(opts) && needed(&a.1) && needed(&b.1)).then_some(ev)
}

/// The effects that change the motion itself (the frequency with the amplitude, the energy each
/// cycle loses): tried once the model is at its floor, and named there only where the envelope
/// sees them (`search`).
fn changes_the_motion(e: Effect) -> bool {
    matches!(e, Effect::CubicStiffness | Effect::FrictionalLag)
}

/// What a model `m` of the current model's family is judged against: the current model `cur`,
/// or, where `m`'s filter is of the other order (a sensor lag's fit may take it), the better of
/// `cur` and `cur` refitted with that order (computed once, kept in `other`). An effect is then
/// credited with what it adds beside the order, not with the order.
fn judged_against<'a>(
    data: &Prepared,
    cur: &'a FittedModel,
    other: &'a mut Option<Option<FittedModel>>,
    m: &FittedModel,
    max_iter: usize,
) -> &'a FittedModel {
    if !cur.spec.lowpass || m.spec.lowpass_poles == cur.spec.lowpass_poles {
        return cur;
    }
    other
        .get_or_insert_with(|| other_order(data, cur, max_iter).filter(|o| o.chi2 < cur.chi2))
        .as_ref()
        .unwrap_or(cur)
}

/// A direction asymmetry's (μ0f − μ0b) / μ0 beside its constant (and its ±, if given): relative to
/// the mean Coulomb level of `m` (whose own ± is far smaller). Nothing for another effect.
fn relative_asymmetry(
    m: &FittedModel,
    e: Effect,
    params: &mut BTreeMap<String, f64>,
    params_se: Option<&mut BTreeMap<String, f64>>,
) {
    const KEY: &str = "dmu0_forward_minus_backward";
    if e != Effect::DirectionAsymmetry {
        return;
    }
    let mu0 = m.spec.mu(&m.p).first().copied().unwrap_or(f64::NAN);
    let Some(d) = params.get(KEY).copied() else {
        return;
    };
    params.insert("asymmetry_relative".into(), d / mu0);
    if let Some(se) = params_se {
        if let Some(d_se) = se.get(KEY).copied() {
            se.insert("asymmetry_relative".into(), d_se / mu0.abs());
        }
    }
}

/// The time constant of a low-pass of `poles` whose delay is that of the other order's at time
/// constant `t` (a 2-pole Butterworth delays a slow signal by √2 τ_f, a 1-pole by τ_f).
fn same_delay_tau(t: f64, poles: u8) -> f64 {
    let r2 = std::f64::consts::SQRT_2;
    if poles == 1 {
        r2 * t
    } else {
        t / r2
    }
}

/// The final model `m` refitted with the other order of its fitted low-pass (1 ↔ 2 poles), from
/// its own constants with the time constant of the same delay (a 1-pole filter delays a slow
/// signal by `τ_f`, the 2-pole Butterworth by `√2 τ_f`). `None` if `m` fits no low-pass or the
/// fit fails.
fn other_order(data: &Prepared, m: &FittedModel, max_iter: usize) -> Option<FittedModel> {
    let i = m.spec.lowpass_index()?;
    let poles = if m.spec.lowpass_poles == 1 { 2 } else { 1 };
    // The other order is the other exact filter (a digital 2-pole's is the 1-pole).
    let spec = Spec {
        lowpass_poles: poles,
        lowpass_digital: false,
        ..m.spec.clone()
    };
    let t = m.p[i].abs();
    let mut a = m.p.clone();
    a[i] = same_delay_tau(t, poles);
    let mut b = m.p.clone();
    b[i] = t;
    fit_spec(data, &spec, &[a, b], max_iter)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stribeck is a rise of friction at low speed: a static level fitted 10σ below the Coulomb
    /// level is no ground for the name (the grid's clean record #5 was named so), one 10σ above
    /// is; other effects stay two-sided.
    #[test]
    fn stribeck_is_distinct_from_its_absence_only_as_a_rise() {
        let spec = Spec::base(vec![0, 1]).with(Effect::Stribeck);
        let model = |mu_s: f64| FittedModel {
            effects: vec!["stribeck".into()],
            params: BTreeMap::new(),
            params_se: BTreeMap::new(),
            gap: 1.0,
            gap_envelope: 1.0,
            gap_force: None,
            chi2: 1.0,
            spec: spec.clone(),
            // μ0, μ1, start correction, μs, vs
            p: vec![0.02, 0.01, 0.0, mu_s, 0.5],
            env_resid: Vec::new(),
            force_resid: Vec::new(),
        };
        let se = [1e-4, 1e-4, 1e-4, 1e-3, 0.05];
        assert!(!distinct_from_absence(&model(0.01), &se, Effect::Stribeck));
        assert!(!distinct_from_absence(&model(0.021), &se, Effect::Stribeck));
        assert!(distinct_from_absence(&model(0.03), &se, Effect::Stribeck));
        // A cubic term is absent at zero, either sign.
        let cubic = Spec::base(vec![0, 1]).with(Effect::CubicStiffness);
        let m = |k: f64| FittedModel {
            spec: cubic.clone(),
            p: vec![0.02, 0.01, 0.0, k],
            ..model(0.0)
        };
        let se = [1e-4, 1e-4, 1e-4, 1e-3];
        assert!(distinct_from_absence(
            &m(-0.01),
            &se,
            Effect::CubicStiffness
        ));
        assert!(distinct_from_absence(&m(0.01), &se, Effect::CubicStiffness));
        assert!(!distinct_from_absence(
            &m(0.001),
            &se,
            Effect::CubicStiffness
        ));
    }
}
