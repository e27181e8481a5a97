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
        if let Some(a) = self.base_model.params.get("apparatus_mu1") {
            let se = self
                .base_model
                .params_se
                .get("apparatus_mu1")
                .copied()
                .unwrap_or(f64::NAN);
            let _ = writeln!(
                s,
                "    apparatus_mu1 = {} (damping of the blades, which the force channel does not see)",
                pm(*a, se)
            );
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
