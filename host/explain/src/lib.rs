//! The discrepancy workflow of the oscillating tribometer (issue 7; thesis ch. 3.7 and 4).
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
//! - the evidence is `Σ_channels (RSS_before − RSS_after) / (s² · n / n_eff)`, a χ² with as many
//!   degrees of freedom as the effect adds parameters when the effect is absent; it must exceed the
//!   χ² quantile of a 10⁻³ false-alarm rate per round, shared among the candidates (Bonferroni);
//! - the effect must also remove a material part (by default 30 %) of the misfit in excess of the
//!   noise floor, so that a systematic misfit from outside the vocabulary is not partly soaked up
//!   by a wrong name; and beat the runner-up by a likelihood ratio of e⁵ (evidence margin 10).
//!
//! The best candidate is added and the search repeats. When nothing more qualifies and the misfit
//! is still above 1.5 × the noise floor in some channel, the answer is "unexplained: N % of the gap
//! remains; not one of the known effects" — never a name the evidence does not support.
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

pub mod diag;
pub mod model;
pub mod report;

pub use model::{Effect, ExplainError, Prepared, Spec};
/// Re-exported so that users can read [`Explanation::to_json`] output with the same version.
pub use serde_json;

use model::{gap_of, residuals, rms, simulate_spec, weighted, RIG_FORCE_CUTOFF_HZ};
use serde::Serialize;
use std::collections::BTreeMap;
use tribo_physics::identify::{
    estimate_averaging, fit_dimensionless, levenberg_marquardt_with, FitError, FitOptions, LawSpec,
    LmOptions, ADEQUATE_RATIO,
};
use tribo_physics::integrate::Method;
use tribo_physics::uncertainty::{
    chi2_upper_quantile, effective_count, hac_covariance_blocks, jacobian, standard_errors,
};
use tribo_physics::Record;

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
    /// Smallest fraction of the excess misfit (gap² − floor²) an effect must remove to be named.
    pub min_excess_reduction: f64,
    /// Evidence margin the best candidate needs over the runner-up to be named.
    pub min_margin: f64,
    /// Compared envelope points.
    pub max_env_points: usize,
    /// Compared force points.
    pub max_force_points: usize,
    /// Levenberg–Marquardt iterations per fit.
    pub max_iter: usize,
    /// Low-pass of the force channel (Hz) applied to simulated force, overriding the record's
    /// (`None`: the record's `# force_cutoff_hz`, or, if it says nothing, the better of no filter
    /// and the rig's 300 Hz charge amplifier — and the result says which it took).
    pub force_cutoff_hz: Option<f64>,
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
            max_force_points: 3000,
            max_iter: 15,
            force_cutoff_hz: None,
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

/// One channel's part of the evidence for an effect.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelEvidence {
    /// `envelope` or `force`.
    pub channel: String,
    /// Residual sum of squares before and after adding the effect.
    pub rss_before: f64,
    pub rss_after: f64,
    /// Compared points.
    pub n: usize,
    /// Effectively independent residuals after adding the effect.
    pub n_eff: f64,
    /// Residual variance used as the noise level (never below the channel's noise floor²).
    pub noise_var: f64,
    /// This channel's evidence.
    pub evidence: f64,
}

/// How strongly adding an effect is supported.
#[derive(Debug, Clone, Serialize)]
pub struct Evidence {
    /// Sum over the channels: χ² with `k` degrees of freedom if the effect is absent.
    pub value: f64,
    /// What it must exceed ([`ExplainOptions::threshold`]).
    pub threshold: f64,
    /// Parameters the effect adds.
    pub k: usize,
    /// Fraction of the excess misfit (gap² − floor²) the effect removes (1 if there was none).
    pub excess_removed: f64,
    /// Per channel.
    pub channels: Vec<ChannelEvidence>,
}

impl Evidence {
    /// Evidence of `after` (the current model plus one effect) against `before`.
    pub fn of(
        data: &Prepared,
        before: &FittedModel,
        after: &FittedModel,
        opts: &ExplainOptions,
    ) -> Evidence {
        let k = after.p.len().saturating_sub(before.p.len()).max(1);
        let mut channels = Vec::new();
        for (name, rb, ra, floor) in [
            (
                "envelope",
                &before.env_resid,
                &after.env_resid,
                data.env_floor(),
            ),
            (
                "force",
                &before.force_resid,
                &after.force_resid,
                data.force_floor(),
            ),
        ] {
            if ra.is_empty() {
                continue;
            }
            let n = ra.len();
            let ss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
            let (rss_b, rss_a) = (ss(rb), ss(ra));
            let n_eff = effective_count(ra);
            let noise_var = (rss_a / n as f64).max(floor * floor);
            let evidence = (rss_b - rss_a) / (noise_var * n as f64 / n_eff);
            channels.push(ChannelEvidence {
                channel: name.into(),
                rss_before: rss_b,
                rss_after: rss_a,
                n,
                n_eff,
                noise_var,
                evidence,
            });
        }
        let floor2 = data.noise_floor().powi(2);
        let excess = before.gap.powi(2) - floor2;
        let excess_removed = if excess > 0.0 {
            (before.gap.powi(2) - after.gap.powi(2)) / excess
        } else {
            1.0
        };
        Evidence {
            value: channels.iter().map(|c| c.evidence).sum(),
            threshold: opts.threshold(k),
            k,
            excess_removed,
            channels,
        }
    }

    /// Whether the effect qualifies: enough evidence and a material share of the excess misfit.
    pub fn significant(&self, opts: &ExplainOptions) -> bool {
        self.value >= self.threshold && self.excess_removed >= opts.min_excess_reduction
    }
}

/// One accepted effect.
#[derive(Debug, Clone, Serialize)]
pub struct Step {
    /// Effect name.
    pub effect: String,
    /// Gap of the model before adding it.
    pub gap_before: f64,
    /// Gap after adding it and refitting.
    pub gap_after: f64,
    /// The evidence that named it.
    pub evidence: Evidence,
    /// The effect's recovered parameters (dimensionless and SI).
    pub params: BTreeMap<String, f64>,
    /// Their standard errors (`NaN`/null if the fit cannot determine them).
    pub params_se: BTreeMap<String, f64>,
}

/// How a candidate scored in a round.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// Effect name.
    pub effect: String,
    /// Gap with the effect added (`null` if the fit failed).
    pub gap: Option<f64>,
    /// Its evidence (`null` if the fit failed).
    pub evidence: Option<f64>,
    /// Fraction of the excess misfit it removes.
    pub excess_removed: Option<f64>,
    /// Whether it qualified.
    pub significant: bool,
}

/// A fitted model.
#[derive(Debug, Clone, Serialize)]
pub struct FittedModel {
    /// Effects added to the base law.
    pub effects: Vec<String>,
    /// All parameters (dimensionless and SI).
    pub params: BTreeMap<String, f64>,
    /// Their standard errors (filled for the base and final models).
    pub params_se: BTreeMap<String, f64>,
    /// The gap.
    pub gap: f64,
    /// Envelope part of the gap.
    pub gap_envelope: f64,
    /// Force part of the gap (`null` without a force channel).
    pub gap_force: Option<f64>,
    /// Structure.
    #[serde(skip)]
    pub spec: Spec,
    /// Parameter vector.
    #[serde(skip)]
    pub p: Vec<f64>,
    /// Envelope residuals.
    #[serde(skip)]
    pub env_resid: Vec<f64>,
    /// Force residuals.
    #[serde(skip)]
    pub force_resid: Vec<f64>,
}

impl FittedModel {
    /// True if every channel's misfit is within [`ADEQUATE_RATIO`] × its noise floor.
    pub fn adequate(&self, data: &Prepared) -> bool {
        self.gap_envelope <= ADEQUATE_RATIO * data.env_floor()
            && self
                .gap_force
                .is_none_or(|g| g <= ADEQUATE_RATIO * data.force_floor())
    }
}

/// What the workflow concluded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Conclusion {
    /// The base law describes the record: its misfit is at the noise floor, nothing is missing.
    BaseAdequate,
    /// The named effects were missing; with them the model describes the record.
    Explained,
    /// Effects were named, but a material misfit remains that no known effect explains.
    PartlyExplained,
    /// A material misfit that no known effect explains: nothing is named.
    Unexplained,
    /// Two effects explain the remainder about equally well: neither is named.
    Ambiguous,
}

impl Conclusion {
    /// kebab-case name.
    pub fn name(&self) -> &'static str {
        match self {
            Conclusion::BaseAdequate => "base-adequate",
            Conclusion::Explained => "explained",
            Conclusion::PartlyExplained => "partly-explained",
            Conclusion::Unexplained => "unexplained",
            Conclusion::Ambiguous => "ambiguous",
        }
    }
}

/// Outcome of the workflow.
#[derive(Debug, Clone, Serialize)]
pub struct Explanation {
    /// What the workflow concluded.
    pub conclusion: Conclusion,
    /// Base law name.
    pub base: String,
    /// Effects found missing, in the order they were added.
    pub missing_effects: Vec<String>,
    /// One entry per added effect.
    pub steps: Vec<Step>,
    /// Gap of the base model.
    pub gap_initial: f64,
    /// Gap of the final model.
    pub gap_final: f64,
    /// The gap a model that describes the record leaves (the channels' measurement noise).
    pub noise_floor: f64,
    /// Envelope and force parts of the noise floor.
    pub noise_floor_envelope: f64,
    pub noise_floor_force: Option<f64>,
    /// Share of the base model's excess misfit (gap² − floor², as a gap) the final model leaves.
    pub unexplained_fraction: f64,
    /// Candidates that explained the remainder about equally well (no clear winner), if the
    /// search stopped for that reason.
    pub ambiguous: Vec<String>,
    /// The force channel's low-pass used for the simulated force (Hz; `null` = none).
    pub force_cutoff_hz: Option<f64>,
    /// How it was chosen: `record`, `option`, `assumed` (the record did not say: the better of
    /// none and the rig's 300 Hz), or `none` (no force channel).
    pub force_cutoff_source: String,
    /// Candidate scores per round.
    pub rounds: Vec<Vec<Candidate>>,
    /// The base model.
    pub base_model: FittedModel,
    /// The final model.
    pub final_model: FittedModel,
    /// Disagreement measures of the base model.
    pub diagnostics: diag::Diagnostics,
}

fn pm(v: f64, se: f64) -> String {
    if se.is_finite() && se > 0.0 {
        format!("{v:.4e} ± {se:.1e}")
    } else {
        format!("{v:.4e} ± ?")
    }
}

impl Explanation {
    /// One JSON object.
    pub fn to_json(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string_pretty(self)
    }

    /// The one-sentence answer.
    pub fn answer(&self) -> String {
        let remains = format!(
            "unexplained: {:.0} % of the gap remains; not one of the known effects",
            100.0 * self.unexplained_fraction
        );
        match self.conclusion {
            Conclusion::BaseAdequate => format!(
                "no missing effect: the {} law leaves only the noise (gap {:.2} × the noise floor)",
                self.base,
                self.gap_final / self.noise_floor
            ),
            Conclusion::Explained => format!(
                "missing: {} (gap {:.2} × the noise floor with {})",
                self.missing_effects.join(" + "),
                self.gap_final / self.noise_floor,
                if self.missing_effects.len() == 1 {
                    "it"
                } else {
                    "them"
                }
            ),
            Conclusion::PartlyExplained => {
                format!("missing: {}; {remains}", self.missing_effects.join(" + "))
            }
            Conclusion::Unexplained => remains,
            Conclusion::Ambiguous => format!(
                "unresolved: {} explain the remainder about equally well; neither is named",
                self.ambiguous.join(" and ")
            ),
        }
    }

    /// Plain-text summary.
    pub fn to_text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "base law: {}   gap {:.3e} ({:.2} × the noise floor {:.3e})",
            self.base,
            self.gap_initial,
            self.gap_initial / self.noise_floor,
            self.noise_floor
        );
        for (k, v) in &self.base_model.params {
            if k.starts_with("mu") || k == "apparatus_mu1" {
                let se = self
                    .base_model
                    .params_se
                    .get(k)
                    .copied()
                    .unwrap_or(f64::NAN);
                let _ = writeln!(s, "    {k} = {}", pm(*v, se));
            }
        }
        for st in &self.steps {
            let _ = writeln!(
                s,
                "+ {:<20} gap {:.3e} -> {:.3e}  (evidence {:.0} > {:.1}, {:.0} % of the excess misfit)",
                st.effect,
                st.gap_before,
                st.gap_after,
                st.evidence.value,
                st.evidence.threshold,
                100.0 * st.evidence.excess_removed.min(1.0)
            );
            for (k, v) in &st.params {
                let se = st.params_se.get(k).copied().unwrap_or(f64::NAN);
                let _ = writeln!(s, "    {k} = {}", pm(*v, se));
            }
        }
        if self.force_cutoff_source == "assumed" {
            let _ = writeln!(
                s,
                "force channel low-pass: {} (assumed: the record does not say; the better fit of \
                 none and the rig's {RIG_FORCE_CUTOFF_HZ} Hz)",
                self.force_cutoff_hz
                    .map_or("none".into(), |f| format!("{f} Hz"))
            );
        }
        let _ = writeln!(s, "final gap {:.3e}", self.gap_final);
        let _ = writeln!(s, "{}", self.answer());
        if matches!(
            self.conclusion,
            Conclusion::Unexplained | Conclusion::PartlyExplained
        ) {
            let _ = writeln!(
                s,
                "(known effects: {}; see the diagnostics in --json or --report for where the model \
                 disagrees)",
                Effect::ALL.map(|e| e.name()).join(", ")
            );
        }
        s
    }
}

/// Fits `spec` from each starting point, keeping the best.
pub fn fit_spec(
    data: &Prepared,
    spec: &Spec,
    starts: &[Vec<f64>],
    max_iter: usize,
) -> Option<FittedModel> {
    let mut best: Option<FittedModel> = None;
    for p0 in starts {
        let scales = spec.scales();
        // A difference step of 1e-3 of each parameter's scale: the default 1e-7 is below the
        // resolution of the adaptive integrator and of the stick events on long records with
        // Coulomb friction (a 1e-9 change of μ0 may move the final stop by a half cycle).
        let lm = levenberg_marquardt_with(
            |p| {
                let s = simulate_spec(data, spec, p).ok()?;
                let (e, f) = residuals(data, &s);
                Some(weighted(&e, &f))
            },
            p0,
            &LmOptions {
                max_iter,
                tol: 1e-5,
                rel_step: 1e-3,
                scales,
            },
        );
        let Some(lm) = lm else { continue };
        let Some(m) = evaluate(data, spec, &lm.p) else {
            continue;
        };
        if best.as_ref().is_none_or(|b| m.gap < b.gap) {
            best = Some(m);
        }
    }
    best
}

/// Simulates and scores a model with given parameters.
pub fn evaluate(data: &Prepared, spec: &Spec, p: &[f64]) -> Option<FittedModel> {
    let s = simulate_spec(data, spec, p).ok()?;
    let (e, f) = residuals(data, &s);
    let gap = gap_of(&e, &f);
    if !gap.is_finite() {
        return None;
    }
    Some(FittedModel {
        effects: spec.effects.iter().map(|e| e.name().to_string()).collect(),
        params: named_params(data, spec, p),
        params_se: BTreeMap::new(),
        gap,
        gap_envelope: rms(&e),
        gap_force: data.has_force().then(|| rms(&f)),
        spec: spec.clone(),
        p: p.to_vec(),
        env_resid: e,
        force_resid: f,
    })
}

/// Standard errors of a fitted model's parameter vector: the Jacobian of the weighted residuals at
/// the optimum and the HAC sandwich with the envelope and force channels as independent blocks
/// (each channel's own correlation accounted for). `NaN` where they cannot be determined.
pub fn standard_errors_of(data: &Prepared, m: &FittedModel) -> Vec<f64> {
    let r = weighted(&m.env_resid, &m.force_resid);
    let ne = m.env_resid.len();
    let blocks = [0..ne, ne..r.len()];
    let scales = m.spec.scales();
    jacobian(
        |p| {
            let s = simulate_spec(data, &m.spec, p).ok()?;
            let (e, f) = residuals(data, &s);
            Some(weighted(&e, &f))
        },
        &m.p,
        &r,
        1e-3,
        &scales,
    )
    .and_then(|j| hac_covariance_blocks(&j, &r, &blocks))
    .map(|c| standard_errors(&c))
    .unwrap_or_else(|| vec![f64::NAN; m.p.len()])
}

/// Fills `params_se` of a fitted model.
pub fn with_standard_errors(data: &Prepared, mut m: FittedModel) -> FittedModel {
    let se = standard_errors_of(data, &m);
    m.params_se = named_params(data, &m.spec, &se);
    m
}

/// Parameters by name, with SI equivalents. (Every conversion is linear, so the same map of a
/// vector of standard errors gives the standard errors of the named parameters.)
pub fn named_params(data: &Prepared, spec: &Spec, p: &[f64]) -> BTreeMap<String, f64> {
    let rig = data.rig;
    let mut m = BTreeMap::new();
    let mu = spec.mu(p);
    let p_si = rig.p_of_mu(&mu);
    for (j, (&a, &b)) in mu.iter().zip(&p_si).enumerate() {
        m.insert(format!("mu{j}"), a);
        m.insert(format!("p{j}_si"), b);
    }
    if spec.apparatus {
        m.insert("apparatus_mu1".into(), spec.apparatus_mu1(p));
    }
    for e in &spec.effects {
        m.extend(effect_params(data, spec, p, *e));
    }
    m
}

/// The named parameters of one effect of a fitted model (dimensionless and SI; linear in `p`).
pub fn effect_params(data: &Prepared, spec: &Spec, p: &[f64], e: Effect) -> BTreeMap<String, f64> {
    let rig = data.rig;
    let mut m = BTreeMap::new();
    let mu = spec.mu(p);
    let Some(q) = spec.effect_params(e, p) else {
        return m;
    };
    match e {
        Effect::QuadraticVelocity => {
            let j = spec.order();
            let p_si = rig.p_of_mu(&mu);
            m.insert(format!("mu{j}"), mu[j]);
            m.insert(format!("p{j}_si"), p_si[j]);
        }
        Effect::Stribeck => {
            m.insert("mu_s".into(), q[0]);
            m.insert("v_s".into(), q[1]);
            m.insert("v_s_m_s".into(), rig.v_of_ydot(q[1]));
        }
        Effect::FrictionalLag => {
            m.insert("memory_tau".into(), q[0]);
            m.insert("memory_s".into(), rig.t_of_tau(q[0]));
        }
        Effect::CubicStiffness => {
            m.insert("kappa".into(), q[0]);
            m.insert(
                "k3_n_per_m3".into(),
                q[0] * rig.stiffness_n_per_m.powi(3) / rig.load_n.powi(2),
            );
        }
        Effect::ThermalDrift => {
            m.insert("dmu0_dT_per_c".into(), q[0]);
        }
        Effect::SensorLag => {
            m.insert("delay_tau".into(), q[0]);
            m.insert("delay_s".into(), rig.t_of_tau(q[0]));
        }
    }
    m
}

/// Starting points for `spec + e` from the current fit and the diagnostics.
fn starts_for(
    data: &Prepared,
    cur: &FittedModel,
    e: Effect,
    d: &diag::Diagnostics,
) -> Vec<Vec<f64>> {
    let mu = cur.spec.mu(&cur.p);
    let mu0 = mu.first().copied().unwrap_or(0.01).abs().max(1e-4);
    let with = |extra: &[f64]| {
        let mut p = cur.p.clone();
        p.extend_from_slice(extra);
        p
    };
    match e {
        Effect::QuadraticVelocity => {
            let next = cur.spec.order() + 1;
            let mut pw = cur.spec.powers.clone();
            pw.extend(cur.spec.powers.iter().max().map_or(1, |m| m + 1)..=next);
            let est = estimate_averaging(&data.tau, &data.y, &data.ydot, &pw)
                .and_then(|v| v.last().copied())
                .filter(|v| v.is_finite())
                .unwrap_or(0.0);
            vec![with(&[est]), with(&[0.0])]
        }
        Effect::Stribeck => vec![with(&[1.05 * mu0, 0.3]), with(&[1.5 * mu0, 0.15])],
        Effect::FrictionalLag => {
            let from_lag = d
                .force_lag_s
                .filter(|&l| l > 0.0)
                .map(|l| data.rig.tau_of_t(l).clamp(0.02, 2.0))
                .unwrap_or(0.3);
            vec![with(&[from_lag]), with(&[0.1])]
        }
        Effect::CubicStiffness => {
            let k = d.kappa_estimate.filter(|k| k.is_finite()).unwrap_or(0.0);
            vec![with(&[k])]
        }
        Effect::ThermalDrift => vec![with(&[0.0])],
        Effect::SensorLag => {
            let l = d.force_lag_s.unwrap_or(0.0).max(0.0);
            vec![with(&[data.rig.tau_of_t(l).max(0.2 * data.dtau)])]
        }
    }
}

/// Base law powers of a [`LawSpec`] (polynomial laws only).
pub fn base_powers(base: LawSpec) -> Result<Vec<usize>, ExplainError> {
    match base {
        LawSpec::LuGre => Err(ExplainError::BaseLaw(
            "the base law must be polynomial (coulomb, viscous, coulomb-viscous, quadratic, poly:N)"
                .into(),
        )),
        b => Ok(b.powers()),
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
    let mut spec = Spec::base(powers.clone());
    spec.apparatus = data.has_force();
    let spec = spec;
    progress("fitting the base law", 0, 1);
    // Envelope-only fit of tribo-physics first (robust from its own estimators, and it screens
    // the record), then the joint envelope + force fit from there.
    let fopts = FitOptions {
        method: Method::dopri(1e-9),
        max_points: opts.max_env_points,
        max_iter: opts.max_iter,
        fit_initial_amplitude: false,
        ..FitOptions::default()
    };
    let mut starts = Vec::new();
    match fit_dimensionless(&data.tau, &data.y, &data.ydot, opts.base, &fopts) {
        Ok(r) => starts.push(spec.start(&r.params)),
        Err(FitError::NotAnalysable(n)) => return Err(ExplainError::not_analysable(n)),
        Err(_) => {}
    }
    starts.push(spec.start(&tribo_physics::identify::start_point(
        &data.tau, &data.y, &data.ydot, opts.base,
    )));
    // The force channel's low-pass, if the record does not say: the better of none and the rig's.
    let mut data = data.clone();
    let source = if !data.has_force() {
        "none"
    } else if opts.force_cutoff_hz.is_some() {
        "option"
    } else if data.force_cutoff_known {
        "record"
    } else {
        let mut best: Option<(f64, Option<f64>)> = None;
        for fc in [None, Some(RIG_FORCE_CUTOFF_HZ)] {
            data.force_cutoff_hz = fc;
            if let Some(m) = starts.first().and_then(|p| evaluate(&data, &spec, p)) {
                let g = m.gap_force.unwrap_or(f64::INFINITY);
                if best.is_none_or(|b| g < b.0) {
                    best = Some((g, fc));
                }
            }
        }
        data.force_cutoff_hz = best.and_then(|b| b.1);
        "assumed"
    };
    let data = data;
    let base = fit_spec(&data, &spec, &starts, opts.max_iter).ok_or_else(|| {
        ExplainError::BaseLaw("the base law could not be fitted to the record".into())
    })?;
    let base = with_standard_errors(&data, base);
    progress("diagnostics", 0, 1);
    let diagnostics = diag::diagnose(&data, &base, opts.base);
    let mut cur = base.clone();
    let mut steps = Vec::new();
    let mut rounds = Vec::new();
    let mut ambiguous = Vec::new();
    for round in 0..opts.max_steps {
        if cur.adequate(&data) && round > 0 {
            break;
        }
        let todo: Vec<Effect> = opts
            .candidates
            .iter()
            .copied()
            .filter(|&e| cur.spec.can_add(e, data.has_force(), data.has_temp()))
            .collect();
        let mut scored: Vec<(Effect, Option<(FittedModel, Evidence)>)> = Vec::new();
        for (i, &e) in todo.iter().enumerate() {
            progress(
                &format!("round {}: trying {}", round + 1, e.name()),
                i,
                todo.len(),
            );
            let s = cur.spec.with(e);
            let starts = starts_for(&data, &cur, e, &diagnostics);
            let fitted = fit_spec(&data, &s, &starts, opts.max_iter).map(|m| {
                let ev = Evidence::of(&data, &cur, &m, opts);
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
        let mut ranked: Vec<(Effect, FittedModel, Evidence)> = scored
            .into_iter()
            .filter_map(|(e, m)| m.map(|(m, ev)| (e, m, ev)))
            .filter(|(_, _, ev)| ev.significant(opts))
            .collect();
        ranked.sort_by(|a, b| b.2.value.total_cmp(&a.2.value));
        let Some(best) = ranked.first() else {
            break;
        };
        if let Some(second) = ranked.get(1) {
            if best.2.value - second.2.value < opts.min_margin {
                ambiguous = vec![best.0.name().to_string(), second.0.name().to_string()];
                break;
            }
        }
        let (e, m, _) = best.clone();
        // Polish the winner (candidates are screened with a short iteration budget).
        let m = fit_spec(
            &data,
            &m.spec,
            std::slice::from_ref(&m.p),
            3 * opts.max_iter,
        )
        .filter(|p| p.gap <= m.gap)
        .unwrap_or(m);
        let ev = Evidence::of(&data, &cur, &m, opts);
        let m = with_standard_errors(&data, m);
        steps.push(Step {
            effect: e.name().into(),
            gap_before: cur.gap,
            gap_after: m.gap,
            evidence: ev,
            params: effect_params(&data, &m.spec, &m.p, e),
            params_se: {
                let se = standard_errors_of(&data, &m);
                effect_params(&data, &m.spec, &se, e)
            },
        });
        cur = m;
    }
    let floor = data.noise_floor();
    let excess = |g: f64| (g * g - floor * floor).max(0.0).sqrt();
    let unexplained_fraction = if excess(base.gap) > 0.0 {
        (excess(cur.gap) / excess(base.gap)).min(1.0)
    } else {
        0.0
    };
    let conclusion = if !ambiguous.is_empty() {
        Conclusion::Ambiguous
    } else if cur.adequate(&data) {
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
    progress("done", 1, 1);
    let ex = Explanation {
        conclusion,
        base: opts.base.name(),
        missing_effects: steps.iter().map(|s| s.effect.clone()).collect(),
        gap_initial: base.gap,
        gap_final: cur.gap,
        noise_floor: floor,
        noise_floor_envelope: data.env_floor(),
        noise_floor_force: data.has_force().then(|| data.force_floor()),
        unexplained_fraction,
        steps,
        ambiguous,
        force_cutoff_hz: data.force_cutoff_hz,
        force_cutoff_source: source.into(),
        rounds,
        base_model: base,
        final_model: cur,
        diagnostics,
    };
    Ok((ex, data))
}
