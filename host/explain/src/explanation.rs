//! The answer: the steps tried, the candidates, the models fitted and the conclusion, in words and
//! JSON.

use super::*;

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
    /// Set when this effect alone removed too small a share of the excess misfit and was named
    /// as the stronger member of a pair that removes enough of it, each member needed beside the
    /// other (the other must then qualify on its own in the next round).
    pub paired_with: Option<PairedWith>,
}

/// The pair an effect was named with ([`Step::paired_with`]).
#[derive(Debug, Clone, Serialize)]
pub struct PairedWith {
    /// The other member.
    pub effect: String,
    /// The pair's evidence against the model before the step.
    pub evidence: f64,
    /// What that evidence must exceed (the threshold for both members' constants).
    pub threshold: f64,
    /// The share of the excess misfit the pair removes.
    pub excess_removed: f64,
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
    /// `−2 ln L` of its residuals under the noise model it was fitted with ([`Prepared::chi2`]);
    /// comparable only between models evaluated under the same [`Prepared::noise`].
    #[serde(skip)]
    pub chi2: f64,
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
    /// True if every channel's misfit is within [`ADEQUATE_RATIO`] × its noise floor. A test of
    /// each channel against its own noise, so no weighting between the channels enters it: in the
    /// likelihood's terms ([`crate::model::NoiseModel`]) it asks that no channel's `RSS_c / n_c`
    /// exceed `ADEQUATE_RATIO² floor_c²`, whatever `w_c` the comparisons use.
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
    /// The base law (serialised as its name).
    pub base: tribo_physics::LawSpec,
    /// The base law's constants: `tribo fit`'s result on the same record (the one estimator of a
    /// law from a record), with its standard errors, noise floor, verdict and compared span.
    pub base_fit: tribo_physics::FitResult,
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
    /// Envelope part of the noise floor.
    pub noise_floor_envelope: f64,
    /// Force part of the noise floor (none without a force channel).
    pub noise_floor_force: Option<f64>,
    /// Share of the base model's excess misfit (gap² − floor², as a gap) the final model leaves.
    pub unexplained_fraction: f64,
    /// Candidates that explained the remainder about equally well (no clear winner), if the
    /// search stopped for that reason.
    pub ambiguous: Vec<String>,
    /// Where the final model still disagrees with the record, in words (each channel above its
    /// floor: the time third and amplitude band where it misses most, and a force misfit that
    /// differs between the sliding directions); empty when it is at the floor.
    pub disagreement: Vec<String>,
    /// The force channel's low-pass of the final model (Hz; `null` = none, or no force channel).
    pub force_cutoff_hz: Option<f64>,
    /// Where it comes from: `record`, `option`, `fitted` (the record does not state it: a
    /// parameter of every model of the search), or `none` (no force channel).
    pub force_cutoff_source: String,
    /// The force channel's low-pass in full, with its ± when fitted (`null` without a force
    /// channel).
    pub force_lowpass: Option<ForceLowpass>,
    /// The other nuisances of the measurement chain (displacement centre, force gain and zero),
    /// fitted with the final model, with their ± and what each can and cannot be told from.
    pub measurement_chain: Option<MeasurementChain>,
    /// The force channel's friction level on the two sides of the track
    /// ([`crate::diag::PositionDependence`]); when significant the record is *unexplained*.
    pub position_dependence: Option<crate::diag::PositionDependence>,
    /// Running-in against a stripe of the track, where running-in passed every other test
    /// ([`crate::diag::drift_or_stripe`]): both evidences, each beside the other, where the
    /// stripe lies and what its freedom of where it lies is charged. Running-in is named where
    /// it is the better fit and no stripe is there beside it (a stripe within
    /// [`ExplainOptions::min_margin`] of it is printed as a caveat); otherwise the conclusion is
    /// `ambiguous`, running-in and [`POSITION_LEVEL`]. The same for a cubic stiffness the
    /// motion does not show (its shape in the drift's place), ambiguous where the stripe is the
    /// better fit.
    pub drift_or_stripe: Option<crate::diag::DriftOrStripe>,
    /// On a record held before its release: where the release falls before the first compared
    /// sample (s; negative: after it), measured from the displacement and velocity about it
    /// ([`crate::release::release_from_motion`]) and held in every model. `null`
    /// for a record that starts in motion.
    pub release_offset_s: Option<f64>,
    /// Its standard error (s).
    pub release_offset_s_se: Option<f64>,
    /// The force channel's trend of μ0 over the motion against the final model's law
    /// ([`tribo_physics::identify::mu0_trend_of`], `tribo fit`'s drift check); a significant one
    /// is never called base-adequate (`null` without a force channel or a Coulomb level).
    pub mu0_trend: Option<tribo_physics::identify::Mu0Trend>,
    /// Candidate scores per round.
    pub rounds: Vec<Vec<Candidate>>,
    /// The base model.
    pub base_model: FittedModel,
    /// The final model.
    pub final_model: FittedModel,
    /// Disagreement measures of the base model.
    pub diagnostics: diag::Diagnostics,
}

/// The force channel's low-pass: stated (by the record or the caller) or fitted.
#[derive(Debug, Clone, Serialize)]
pub struct ForceLowpass {
    /// `record`, `option` or `fitted`.
    pub source: String,
    /// Cut-off (Hz); `null` for no filter (stated none, or a fitted time constant at its bound:
    /// below a quarter of the sample interval, a filter the samples cannot show).
    pub cutoff_hz: Option<f64>,
    /// Its standard error when fitted (delta method on the time constant; `null` otherwise).
    pub cutoff_hz_se: Option<f64>,
    /// Time constant `1/(2π f_c)` of the filter (s; 0 = no filter).
    pub time_constant_s: f64,
    /// Its standard error when fitted (`null` at the bound, where it is held for the others' ±).
    pub time_constant_s_se: Option<f64>,
    /// When fitted: the lowest cut-off the record allows at 2σ (Hz): `1/(2π (T + 2σ))` for a
    /// filter found; at the bound, from the force misfit's profile ([`lowpass_bound`]). `null`
    /// when stated, or when the record rules out no filter up to the largest explored.
    pub cutoff_at_least_hz: Option<f64>,
    /// The filter's order: 1 (1-pole) or 2 (2-pole Butterworth). Fitted: the order chosen from
    /// the record (held in every model of the search; at the bound, the order the bound is
    /// for). Stated: 2 (a stated cut-off is the charge amplifier's 2-pole filter); `null` when
    /// none is stated.
    pub poles: Option<u8>,
    /// Whether the 2-pole filter is the digital one, the bilinear Butterworth a DAQ (and the rig's
    /// own records) apply to the sampled force, rather than the analog filter discretised exactly:
    /// fitted, chosen from the record with the order; stated, a stated cut-off is that filter.
    pub digital: bool,
    /// When fitted: the evidence for the chosen order over the other one, the final model
    /// refitted with the other filter (the same χ² measure as an effect's evidence; negative
    /// would mean the other order fits better). `null` when stated or when the refit failed.
    pub order_evidence: Option<f64>,
}

impl ForceLowpass {
    /// The low-pass of the final model `m` (`None` without a force channel).
    pub fn of(
        data: &Prepared,
        m: &FittedModel,
        source: &str,
        order_evidence: Option<f64>,
    ) -> Option<ForceLowpass> {
        if !data.has_force() {
            return None;
        }
        let two_pi = 2.0 * std::f64::consts::PI;
        match m.params.get("force_lowpass_s") {
            Some(&tc) => {
                let se = m
                    .params_se
                    .get("force_lowpass_s")
                    .copied()
                    .filter(|v| v.is_finite());
                let at_bound = lowpass_at_bound(data, &m.spec, &m.p);
                let cutoff = (tc > 0.0 && !at_bound).then(|| 1.0 / (two_pi * tc));
                let at_least = if at_bound {
                    lowpass_bound(data, m).map(|t| 1.0 / (two_pi * t))
                } else {
                    se.map(|se| 1.0 / (two_pi * (tc + 2.0 * se)))
                };
                Some(ForceLowpass {
                    source: source.into(),
                    cutoff_hz: cutoff,
                    cutoff_hz_se: match (cutoff, se) {
                        (Some(fc), Some(se)) => Some(fc * se / tc),
                        _ => None,
                    },
                    time_constant_s: tc,
                    time_constant_s_se: se,
                    cutoff_at_least_hz: at_least,
                    poles: Some(m.spec.lowpass_poles),
                    digital: m.spec.lowpass_digital && m.spec.lowpass_poles == 2,
                    order_evidence,
                })
            }
            None => Some(ForceLowpass {
                source: source.into(),
                cutoff_hz: data.force_cutoff_hz,
                cutoff_hz_se: None,
                time_constant_s: data.force_cutoff_hz.map_or(0.0, |f| 1.0 / (two_pi * f)),
                time_constant_s_se: None,
                cutoff_at_least_hz: None,
                poles: data.force_cutoff_hz.map(|_| 2),
                digital: data.force_cutoff_hz.is_some(),
                order_evidence: None,
            }),
        }
    }

    /// The evidence for the fitted order, in words.
    fn order_text(&self) -> String {
        let p = self.poles.unwrap_or(2);
        let q = if p == 1 { 2 } else { 1 };
        let kind = self.kind();
        match self.order_evidence {
            Some(ev) if ev >= 0.0 => {
                format!("{kind} over {q}-pole by evidence {ev:.1}")
            }
            Some(ev) => format!(
                "{kind} held from the search; the {q}-pole refit is better by evidence {:.1}, \
                 below what a change needs",
                -ev
            ),
            None => "the other order could not be refitted".into(),
        }
    }

    /// The filter's order and kind in words: `1-pole`, `2-pole`, `2-pole digital (bilinear)`.
    fn kind(&self) -> String {
        match (self.poles.unwrap_or(2), self.digital) {
            (1, _) => "1-pole".into(),
            (p, true) => format!("{p}-pole digital (bilinear)"),
            (p, false) => format!("{p}-pole"),
        }
    }

    /// One line of text.
    pub fn text(&self) -> String {
        match (self.source.as_str(), self.cutoff_hz) {
            ("fitted", Some(fc)) => format!(
                "{fc:.0} ± {:.0} Hz, {} (fitted: the record does not state it; time constant \
                 {:.3} ± {:.3} ms; {})",
                self.cutoff_hz_se.unwrap_or(f64::NAN),
                self.kind(),
                1e3 * self.time_constant_s,
                1e3 * self.time_constant_s_se.unwrap_or(f64::NAN),
                self.order_text()
            ),
            ("fitted", None) => format!(
                "none found (fitted: the record does not state it; time constant {:.4} ms, below a \
                 quarter of a sample; {})",
                1e3 * self.time_constant_s,
                self.cutoff_at_least_hz.map_or(
                    "no cut-off within the explored range is ruled out".into(),
                    |f| format!(
                        "a {}-pole cut-off below {f:.0} Hz is ruled out at 2σ",
                        self.poles.unwrap_or(2)
                    )
                )
            ),
            (src, Some(fc)) => format!(
                "{fc} Hz (stated by the {}), 2-pole (a stated cut-off is the charge amplifier's filter)",
                if src == "option" {
                    "--force-cutoff-hz option"
                } else {
                    "record"
                }
            ),
            (src, None) => format!(
                "none (stated by the {})",
                if src == "option" {
                    "--force-cutoff-hz option"
                } else {
                    "record"
                }
            ),
        }
    }
}

/// The name, in [`Explanation::ambiguous`], of a friction level that depends on where the pin
/// slides (a worn or contaminated stripe), which a drift of μ0 in time is not told apart from
/// ([`crate::diag::drift_or_stripe`]).
pub const POSITION_LEVEL: &str = "position-dependent-friction";

/// The name, in [`Explanation::ambiguous`], of a constant offset of the force channel that the
/// record cannot tell from a direction asymmetry (its zero is not stated).
pub const FORCE_ZERO_OFFSET: &str = "force-zero-offset";

/// The measurement chain's nuisances of the final model ([`model::chain`]).
#[derive(Debug, Clone, Serialize)]
pub struct MeasurementChain {
    /// Centre of the motion relative to the vibrometer's zero (m; y for a dimensionless record):
    /// the vibrometer's zero offset minus the shift a direction asymmetry gives the equilibrium.
    pub displacement_center_m: f64,
    /// Its standard error.
    pub displacement_center_m_se: f64,
    /// Force channel gain (measured / true), `null` without a force channel.
    pub force_gain: Option<f64>,
    /// Its standard error (`null` when held).
    pub force_gain_se: Option<f64>,
    /// `fitted`, or `held` (a law without a Coulomb level: the gain cannot be told from the
    /// apparatus' share of the damping).
    pub force_gain_source: Option<String>,
    /// What the force channel reads at zero force (N): stated, or fitted (then it is the zero
    /// offset plus any direction asymmetry `δ N`, which cannot be told apart).
    pub force_zero_n: Option<f64>,
    /// Its standard error when fitted or measured over the hold.
    pub force_zero_n_se: Option<f64>,
    /// `record`, `option`, `hold` (measured over the magnet's hold before the release: no
    /// tangential force acts on the contact then, [`Prepared::hold_zero`]) or `fitted`.
    pub force_zero_source: Option<String>,
    /// The number of held samples the zero was measured from (`hold` only).
    pub force_zero_hold_samples: Option<usize>,
    /// When fitted: the evidence for a non-zero offset (χ²₁ units, as the effects').
    pub force_zero_evidence: Option<f64>,
    /// When fitted: whether that evidence passes an effect's threshold. The record then has a
    /// direction asymmetry or a zero offset, and says nothing of which (the conclusion is
    /// `ambiguous`).
    pub force_zero_significant: bool,
    /// The same offset as a direction asymmetry would be: (μ0 forward − μ0 backward) / μ0.
    pub force_zero_as_asymmetry: Option<f64>,
}

impl MeasurementChain {
    /// The nuisances of the final model `m`.
    pub fn of(
        data: &Prepared,
        m: &FittedModel,
        zero_source: &str,
        opts: &ExplainOptions,
    ) -> Option<MeasurementChain> {
        let sim = simulate_spec(data, &m.spec, &m.p).ok()?;
        let cf = model::chain::fit(data, &sim, data.force_zero);
        let held = lowpass_at_bound(data, &m.spec, &m.p)
            .then(|| m.spec.lowpass_index())
            .flatten();
        let [c_se, g_se, z_se] = model::chain::nuisance_standard_errors(data, &m.spec, &m.p, held);
        let to_m = data.rig.load_n / data.rig.stiffness_n_per_m;
        let load = data.rig.load_n;
        let has_force = data.has_force();
        let zero_fitted = has_force && data.force_zero.is_none();
        let (mut ev, mut significant) = (None, false);
        if zero_fitted {
            // The offset held at 0 (the gain refitted), against the fitted one, in the units of
            // an effect's evidence.
            let c0 = model::chain::fit(data, &sim, Some(0.0));
            let ss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
            let n = cf.force.len();
            if n > 0 {
                let n_eff = effective_count(&cf.force).max(1.0);
                let var = (ss(&cf.force) / n as f64).max(data.force_floor().powi(2));
                let e = (ss(&c0.force) - ss(&cf.force)) / (var * n as f64 / n_eff);
                significant = e >= opts.threshold(1);
                ev = Some(e);
            }
        }
        let mu0 = m.spec.mu(&m.p).first().copied().unwrap_or(f64::NAN);
        let finite = |v: f64| v.is_finite().then_some(v);
        Some(MeasurementChain {
            displacement_center_m: cf.center * to_m,
            displacement_center_m_se: c_se * to_m,
            force_gain: has_force.then_some(cf.gain),
            force_gain_se: if has_force { finite(g_se) } else { None },
            force_gain_source: has_force
                .then(|| if sim.gain_free { "fitted" } else { "held" }.to_string()),
            force_zero_n: has_force.then_some(cf.zero * load),
            force_zero_n_se: if zero_fitted {
                finite(z_se * load)
            } else if zero_source == "hold" {
                finite(data.force_zero_se * load)
            } else {
                None
            },
            force_zero_hold_samples: (zero_source == "hold")
                .then(|| data.hold_zero.map(|h| h.2))
                .flatten(),
            force_zero_source: has_force.then(|| zero_source.to_string()),
            force_zero_evidence: ev,
            force_zero_significant: significant,
            force_zero_as_asymmetry: (zero_fitted && mu0 != 0.0)
                .then(|| 2.0 * cf.zero / (cf.gain * mu0)),
        })
    }

    /// Lines of text (indented by the caller).
    pub fn lines(&self) -> Vec<String> {
        let mut out = vec![format!(
            "displacement centre = {} µm (the vibrometer's zero offset, less the equilibrium \
             shift of any direction asymmetry; fitted)",
            pm_fixed(
                1e6 * self.displacement_center_m,
                1e6 * self.displacement_center_m_se
            )
        )];
        if let (Some(g), Some(src)) = (self.force_gain, &self.force_gain_source) {
            out.push(if src == "fitted" {
                format!(
                    "force channel gain = {} (measured / true, against the envelope's Coulomb \
                     level; fitted)",
                    pm_fixed(g, self.force_gain_se.unwrap_or(f64::NAN))
                )
            } else {
                format!(
                    "force channel gain held at {g} (a law without a Coulomb level cannot tell \
                     it from the apparatus' share of the damping)"
                )
            });
        }
        if let (Some(z), Some(src)) = (self.force_zero_n, &self.force_zero_source) {
            out.push(match src.as_str() {
                "fitted" => format!(
                    "force channel zero = {} N (fitted: the record does not state it, so it \
                     includes any direction asymmetry of μ0, which cannot be told from it; as an \
                     asymmetry it would be {:+.1} % of μ0; evidence {:.1}{})",
                    pm_fixed(z, self.force_zero_n_se.unwrap_or(f64::NAN)),
                    100.0 * self.force_zero_as_asymmetry.unwrap_or(f64::NAN),
                    self.force_zero_evidence.unwrap_or(f64::NAN),
                    if self.force_zero_significant {
                        ", significant"
                    } else {
                        ", not significant"
                    }
                ),
                "hold" => format!(
                    "force channel zero = {} N (measured over the magnet's hold before the \
                     release, {} samples: no tangential force acts on the contact then; held in \
                     every model, its ± carried into a direction asymmetry's)",
                    pm_fixed(z, self.force_zero_n_se.unwrap_or(f64::NAN)),
                    self.force_zero_hold_samples.unwrap_or(0)
                ),
                src => format!(
                    "force channel zero = {z} N (stated by the {})",
                    if src == "option" {
                        "--force-zero-n option"
                    } else {
                        "record"
                    }
                ),
            });
        }
        out
    }
}

/// `v ± se` in fixed notation with the standard error's second significant digit.
fn pm_fixed(v: f64, se: f64) -> String {
    if se.is_finite() && se > 0.0 {
        let d = (1 - se.log10().floor() as i32).clamp(0, 12) as usize;
        format!("{v:.d$} ± {se:.d$}")
    } else {
        format!("{v:.4e} ± ?")
    }
}

pub(super) fn pm(v: f64, se: f64) -> String {
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
            Conclusion::Ambiguous if self.ambiguous.iter().any(|a| a == FORCE_ZERO_OFFSET) => {
                let named = if self.missing_effects.is_empty() {
                    String::new()
                } else {
                    format!("missing: {}; ", self.missing_effects.join(" + "))
                };
                let c = self.measurement_chain.as_ref();
                format!(
                    "{named}unresolved: the force channel stands {:.2e} N off in both sliding \
                     directions: a direction asymmetry of μ0 ((forward − backward) / μ0 = \
                     {:+.1} %) or a zero offset of the force channel; the record does not state \
                     the channel's zero (`# force_zero_n=…`) and has no hold to measure it over \
                     (the rest after the stop does not tell them apart), so neither is named: \
                     state the zero, or record a hold before the release",
                    c.and_then(|c| c.force_zero_n).unwrap_or(f64::NAN),
                    100.0
                        * c.and_then(|c| c.force_zero_as_asymmetry)
                            .unwrap_or(f64::NAN)
                )
            }
            Conclusion::Ambiguous if self.ambiguous.iter().any(|a| a == POSITION_LEVEL) => {
                let named = if self.missing_effects.is_empty() {
                    String::new()
                } else {
                    format!("missing: {}; ", self.missing_effects.join(" + "))
                };
                let drift = self.ambiguous.first().map_or("a drift", |s| s.as_str());
                match self.drift_or_stripe.as_ref() {
                    Some(c) if drift == "cubic-stiffness" => format!(
                        "{named}unresolved: the force channel's friction level depends on where \
                         the pin slides, as a cubic stiffness would make it (its shape, evidence \
                         {:.1}), but a stripe of the track from {:.0} to {:.0} µm with a \
                         friction level of its own explains it better (evidence {:.1}, {:.1} of \
                         which its freedom of where it lies accounts for), and the motion does \
                         not show the stiffness (the envelope channel's evidence under 4). \
                         Neither is named: a release from a larger amplitude tells them apart (a \
                         cubic stiffness moves the frequency with the amplitude, a stripe does \
                         not)",
                        c.drift,
                        1e6 * c.stripe_from_to_m.0,
                        1e6 * c.stripe_from_to_m.1,
                        c.stripe,
                        c.freedom
                    ),
                    Some(c) if c.stripe - c.freedom <= c.drift => format!(
                        "{named}unresolved: the force channel's friction level changes over the \
                         motion as {drift} would make it (evidence {:.1}), and a stripe of the \
                         track from {:.0} to {:.0} µm with a friction level of its own is there \
                         beside it (evidence {:.1} beside the drift, {:.1} alone): a stripe \
                         takes a larger share of each swing as the amplitude decays, which a \
                         drift takes most of. Neither is named: a release from another \
                         amplitude tells them apart (a stripe stays where it is on the track, a \
                         drift follows the time)",
                        c.drift,
                        1e6 * c.stripe_from_to_m.0,
                        1e6 * c.stripe_from_to_m.1,
                        c.stripe_beside_drift,
                        c.stripe
                    ),
                    Some(c) => format!(
                        "{named}unresolved: the force channel's friction level changes over the \
                         motion as {drift} would make it (evidence {:.1}), but a stripe of the \
                         track from {:.0} to {:.0} µm with a friction level of its own explains \
                         it better (evidence {:.1}, {:.1} of which its freedom of where it \
                         lies accounts for): a stripe takes a larger share of each \
                         swing as the amplitude decays. Neither is named: a release from \
                         another amplitude tells them apart (a stripe stays where it is on the \
                         track, a drift follows the time)",
                        c.drift,
                        1e6 * c.stripe_from_to_m.0,
                        1e6 * c.stripe_from_to_m.1,
                        c.stripe,
                        c.freedom
                    ),
                    None => format!(
                        "{named}unresolved: {drift} or a friction level that depends on where \
                         the pin slides; neither is named"
                    ),
                }
            }
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
        let f = &self.base_fit;
        for (j, m) in f.mu.iter().enumerate() {
            if f.law.powers().contains(&j) {
                let _ = writeln!(s, "    mu{j} = {}", pm(*m, f.mu_se[j]));
            }
        }
        let _ = writeln!(
            s,
            "    (`tribo fit`'s result: {}, gap {:.2} × its noise floor)",
            f.verdict.name(),
            f.gap_ratio()
        );
        // The nuisances of the measurement chain, as the final model has them.
        let fm = &self.final_model;
        let nse = |k: &str| fm.params_se.get(k).copied().unwrap_or(f64::NAN);
        let _ = writeln!(s, "measurement chain (fitted with the final model):");
        if let Some(a) = fm.params.get("start_scale") {
            let _ = writeln!(
                s,
                "    start_scale = {} (correction of the release amplitude read from the first sample)",
                pm(*a, nse("start_scale"))
            );
        }
        if let Some(a) = fm.params.get("apparatus_mu1") {
            let _ = writeln!(
                s,
                "    apparatus_mu1 = {} (damping of the blades, which the force channel does not see)",
                pm(*a, nse("apparatus_mu1"))
            );
        }
        if let Some(r) = self.release_offset_s {
            let _ = writeln!(
                s,
                "    release instant = {} µs before the first compared sample (measured from the displacement and velocity about it, held in every model)",
                pm(r * 1e6, self.release_offset_s_se.unwrap_or(f64::NAN) * 1e6)
            );
        }
        if let Some(l) = &self.force_lowpass {
            let _ = writeln!(s, "    force channel low-pass: {}", l.text());
        }
        if let Some(c) = &self.measurement_chain {
            for l in c.lines() {
                let _ = writeln!(s, "    {l}");
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
            if let Some(p) = &st.paired_with {
                let _ = writeln!(
                    s,
                    "    named as one of a pair with {}: alone each removes too little of the excess; \
                     the two remove {:.0} % of it (evidence {:.0} > {:.1}), each needed beside the other",
                    p.effect,
                    100.0 * p.excess_removed.min(1.0),
                    p.evidence,
                    p.threshold
                );
            }
            for (k, v) in &st.params {
                if st.effect == "stribeck" && k == "delta" {
                    // Chosen, not fitted (`Spec::stribeck_delta`): no ±.
                    let _ = writeln!(
                        s,
                        "    {k} = {v} (the curve's exponent: the better fit of 1 and 2)"
                    );
                    continue;
                }
                let se = st.params_se.get(k).copied().unwrap_or(f64::NAN);
                let _ = writeln!(s, "    {k} = {}", pm(*v, se));
            }
        }
        let _ = writeln!(s, "final gap {:.3e}", self.gap_final);
        let _ = writeln!(s, "{}", self.answer());
        if let Some(c) = self
            .drift_or_stripe
            .as_ref()
            .filter(|_| self.missing_effects.iter().any(|m| m == "running-in"))
        {
            let _ = writeln!(
                s,
                "running-in against a stripe of the track: evidence {:.1} on the force channel, \
                 the best stripe ({:.0} to {:.0} µm) {:.1}, less {:.1} for where it lies; \
                 beside each other, a stripe {:.1} and the drift {:.1}{}",
                c.drift,
                1e6 * c.stripe_from_to_m.0,
                1e6 * c.stripe_from_to_m.1,
                c.stripe,
                c.freedom,
                c.stripe_beside_drift,
                c.drift_beside_stripe,
                if c.close {
                    " — too close to rule the stripe out: a release from another amplitude \
                     tells them apart (a stripe stays where it is on the track, a drift follows \
                     the time)"
                } else {
                    ""
                }
            );
        }
        if !self.disagreement.is_empty() {
            let _ = writeln!(s, "where the model still disagrees:");
            for d in &self.disagreement {
                let _ = writeln!(s, "    - {d}");
            }
        }
        if matches!(
            self.conclusion,
            Conclusion::Unexplained | Conclusion::PartlyExplained
        ) {
            let _ = writeln!(
                s,
                "(known effects: {}; more diagnostics in --json or --report)",
                Effect::ALL.map(|e| e.name()).join(", ")
            );
        }
        s
    }
}
