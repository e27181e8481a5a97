//! The discrepancy workflow of the oscillating tribometer (issue 7; thesis ch. 3.7 and 4).
//!
//! A base friction law (Coulomb–viscous by default) is fitted to a record, simulated and compared
//! with it: envelope residual, windowed fits, frequency against amplitude, force channel lag and
//! dissipated energy, temperature drift ([`diag`]). Then every candidate [`Effect`] the model
//! could be missing is added in turn, the extended model is refitted by Levenberg–Marquardt on the
//! same residual vector (envelope, plus force when the record has it), and scored by the Bayesian
//! information criterion. The best candidate is accepted only when its evidence is clear (a large
//! ΔBIC, a real gap reduction and a margin over the runner-up); it is added and the search
//! repeats until nothing significant is left.
//!
//! The gap is the one of `tribo fit`: RMS(measured − simulated envelope) / initial amplitude,
//! extended to the force channel as `√(gap_env² + gap_force²)`, the force residual being
//! expressed in the same units (force relative to the initial spring force `k x0`).
//!
//! ```no_run
//! use tribo_explain::{explain, ExplainOptions};
//! let rec = tribo_physics::Record::load(std::path::Path::new("run.csv")).unwrap();
//! let e = explain(&rec, &ExplainOptions::default()).unwrap();
//! println!("{}", e.to_json());
//! ```

pub mod diag;
pub mod model;
pub mod report;

pub use model::{Effect, ExplainError, Prepared, Spec};
/// Re-exported so that users can read [`Explanation::to_json`] output with the same version.
pub use serde_json;

use model::{bic, gap_of, residuals, rms, simulate_spec, weighted};
use serde::Serialize;
use std::collections::BTreeMap;
use tribo_physics::identify::{
    estimate_averaging, fit_dimensionless, levenberg_marquardt_with, FitOptions, LawSpec, LmOptions,
};
use tribo_physics::integrate::Method;
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
    /// Smallest ΔBIC for an effect to count.
    pub min_delta_bic: f64,
    /// Smallest relative gap reduction for an effect to count.
    pub min_gap_reduction: f64,
    /// ΔBIC margin the best candidate needs over the runner-up to be named.
    pub min_margin: f64,
    /// Compared envelope points.
    pub max_env_points: usize,
    /// Compared force points.
    pub max_force_points: usize,
    /// Levenberg–Marquardt iterations per fit.
    pub max_iter: usize,
    /// Known low-pass of the force channel (charge amplifier), applied to simulated force.
    pub force_cutoff_hz: Option<f64>,
}

impl Default for ExplainOptions {
    fn default() -> Self {
        ExplainOptions {
            base: LawSpec::CoulombViscous,
            candidates: Effect::ALL.to_vec(),
            max_steps: 3,
            min_delta_bic: 30.0,
            min_gap_reduction: 0.15,
            min_margin: 10.0,
            max_env_points: 400,
            max_force_points: 3000,
            max_iter: 15,
            force_cutoff_hz: Some(300.0),
        }
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
    /// BIC(before) − BIC(after).
    pub delta_bic: f64,
    /// The effect's recovered parameters (dimensionless and SI).
    pub params: BTreeMap<String, f64>,
}

/// How a candidate scored in a round.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    /// Effect name.
    pub effect: String,
    /// Gap with the effect added (`null` if the fit failed).
    pub gap: Option<f64>,
    /// BIC(current) − BIC(with effect).
    pub delta_bic: Option<f64>,
}

/// A fitted model.
#[derive(Debug, Clone, Serialize)]
pub struct FittedModel {
    /// Effects added to the base law.
    pub effects: Vec<String>,
    /// All parameters (dimensionless and SI).
    pub params: BTreeMap<String, f64>,
    /// The gap.
    pub gap: f64,
    /// Envelope part of the gap.
    pub gap_envelope: f64,
    /// Force part of the gap (`null` without a force channel).
    pub gap_force: Option<f64>,
    /// BIC.
    pub bic: f64,
    /// Structure.
    #[serde(skip)]
    pub spec: Spec,
    /// Parameter vector.
    #[serde(skip)]
    pub p: Vec<f64>,
}

/// Outcome of the workflow.
#[derive(Debug, Clone, Serialize)]
pub struct Explanation {
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
    /// Candidates that explained the remainder about equally well (no clear winner), if the
    /// search stopped for that reason.
    pub ambiguous: Vec<String>,
    /// Candidate scores per round.
    pub rounds: Vec<Vec<Candidate>>,
    /// The base model.
    pub base_model: FittedModel,
    /// The final model.
    pub final_model: FittedModel,
    /// Disagreement measures of the base model.
    pub diagnostics: diag::Diagnostics,
}

impl Explanation {
    /// One JSON object.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
    }

    /// Plain-text summary.
    pub fn to_text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::new();
        let _ = writeln!(s, "base law: {}   gap {:.3e}", self.base, self.gap_initial);
        if self.steps.is_empty() {
            let _ = writeln!(s, "no missing effect: the base law explains the record");
        }
        for st in &self.steps {
            let _ = writeln!(
                s,
                "+ {:<20} gap {:.3e} -> {:.3e}  (ΔBIC {:.0})",
                st.effect, st.gap_before, st.gap_after, st.delta_bic
            );
            for (k, v) in &st.params {
                let _ = writeln!(s, "    {k} = {v:.4e}");
            }
        }
        if !self.ambiguous.is_empty() {
            let _ = writeln!(
                s,
                "unresolved: {} explain the remainder about equally well",
                self.ambiguous.join(", ")
            );
        }
        let _ = writeln!(s, "final gap {:.3e}", self.gap_final);
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
        gap,
        gap_envelope: rms(&e),
        gap_force: data.has_force().then(|| rms(&f)),
        bic: bic(&e, &f, spec.n_params()),
        spec: spec.clone(),
        p: p.to_vec(),
    })
}

/// Parameters by name, with SI equivalents.
pub fn named_params(data: &Prepared, spec: &Spec, p: &[f64]) -> BTreeMap<String, f64> {
    let rig = data.rig;
    let mut m = BTreeMap::new();
    let mu = spec.mu(p);
    let p_si = rig.p_of_mu(&mu);
    for (j, (&a, &b)) in mu.iter().zip(&p_si).enumerate() {
        m.insert(format!("mu{j}"), a);
        m.insert(format!("p{j}_si"), b);
    }
    for e in &spec.effects {
        m.extend(effect_params(data, spec, p, *e));
    }
    m
}

/// The named parameters of one effect of a fitted model (dimensionless and SI).
pub fn effect_params(data: &Prepared, spec: &Spec, p: &[f64], e: Effect) -> BTreeMap<String, f64> {
    let rig = data.rig;
    let mut m = BTreeMap::new();
    let mu = spec.mu(p);
    let mu0 = mu.first().copied().unwrap_or(0.0);
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
            m.insert("sigma0".into(), q[0]);
            m.insert("sigma0_n_per_m".into(), q[0] * rig.stiffness_n_per_m);
            m.insert("presliding_m".into(), rig.x_of_y(mu0 / q[0]));
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
            let a_mid = 0.5 * data.a0;
            let from_lag = d
                .force_lag_s
                .filter(|&l| l > 0.0)
                .map(|l| {
                    let dl = data.rig.tau_of_t(l).max(0.05);
                    (4.0 * mu0 / (a_mid * dl * dl)).clamp(0.05, 1.5)
                })
                .unwrap_or(0.3);
            vec![with(&[from_lag]), with(&[1.5])]
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
        LawSpec::LuGre => Err(ExplainError(
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
    explain_prepared(&data, opts)
}

/// [`explain`] on a prepared record.
pub fn explain_prepared(
    data: &Prepared,
    opts: &ExplainOptions,
) -> Result<Explanation, ExplainError> {
    let powers = base_powers(opts.base)?;
    let spec = Spec::base(powers.clone());
    // Envelope-only fit of tribo-physics first (robust from its own estimators), then the joint
    // envelope + force fit from there.
    let fopts = FitOptions {
        method: Method::dopri(1e-9),
        max_points: opts.max_env_points,
        max_iter: opts.max_iter,
        ..FitOptions::default()
    };
    let mut starts = Vec::new();
    if let Ok(r) = fit_dimensionless(&data.tau, &data.y, &data.ydot, opts.base, &fopts) {
        starts.push(r.params);
    }
    starts.push(tribo_physics::identify::start_point(
        &data.tau, &data.y, &data.ydot, opts.base,
    ));
    let base = fit_spec(data, &spec, &starts, opts.max_iter)
        .ok_or_else(|| ExplainError("the base law could not be fitted to the record".into()))?;
    let diagnostics = diag::diagnose(data, &base, opts.base);
    let mut cur = base.clone();
    let mut steps = Vec::new();
    let mut rounds = Vec::new();
    let mut ambiguous = Vec::new();
    for _ in 0..opts.max_steps {
        let mut scored: Vec<(Effect, Option<FittedModel>)> = Vec::new();
        for &e in &opts.candidates {
            if !cur.spec.can_add(e, data.has_force(), data.has_temp()) {
                continue;
            }
            let s = cur.spec.with(e);
            let starts = starts_for(data, &cur, e, &diagnostics);
            scored.push((e, fit_spec(data, &s, &starts, opts.max_iter)));
        }
        let mut ranked: Vec<(Effect, f64, FittedModel)> = scored
            .iter()
            .filter_map(|(e, m)| m.as_ref().map(|m| (*e, cur.bic - m.bic, m.clone())))
            .collect();
        ranked.sort_by(|a, b| b.1.total_cmp(&a.1));
        rounds.push(
            scored
                .iter()
                .map(|(e, m)| Candidate {
                    effect: e.name().into(),
                    gap: m.as_ref().map(|m| m.gap),
                    delta_bic: m.as_ref().map(|m| cur.bic - m.bic),
                })
                .collect(),
        );
        let significant = |(_, dbic, m): &(Effect, f64, FittedModel)| {
            *dbic >= opts.min_delta_bic && m.gap <= (1.0 - opts.min_gap_reduction) * cur.gap
        };
        let Some(best) = ranked.first().filter(|b| significant(b)) else {
            break;
        };
        if let Some(second) = ranked.get(1).filter(|s| significant(s)) {
            if best.1 - second.1 < opts.min_margin {
                ambiguous = vec![best.0.name().to_string(), second.0.name().to_string()];
                break;
            }
        }
        let (e, _, m) = best.clone();
        // Polish the winner (candidates are screened with a short iteration budget).
        let m = fit_spec(data, &m.spec, std::slice::from_ref(&m.p), 3 * opts.max_iter)
            .filter(|p| p.gap <= m.gap)
            .unwrap_or(m);
        let dbic = cur.bic - m.bic;
        steps.push(Step {
            effect: e.name().into(),
            gap_before: cur.gap,
            gap_after: m.gap,
            delta_bic: dbic,
            params: effect_params(data, &m.spec, &m.p, e),
        });
        cur = m;
    }
    Ok(Explanation {
        base: opts.base.name(),
        missing_effects: steps.iter().map(|s| s.effect.clone()).collect(),
        gap_initial: base.gap,
        gap_final: cur.gap,
        steps,
        ambiguous,
        rounds,
        base_model: base,
        final_model: cur,
        diagnostics,
    })
}
