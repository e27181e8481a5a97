//! The on-board result as an independent cross-check of the host fit.
//!
//! There is one estimator of a friction law from a record: the host fit (`tribo_physics::identify`),
//! used by `fit`, `run`, `explain`, the report and the campaign tables. The rig computes its own
//! Coulomb–viscous result on board from the same samples by other means (half-cycle peaks, a
//! linear regression, f32): it is shown beside the host's, never instead of it. When the two
//! differ by more than [`DISAGREE_SIGMAS`] combined standard errors on μ0 or μ1, every command
//! says so, with what to suspect.

use serde::Serialize;
use tribo_physics::identify::{FitResult, FitVerdict};
use tribo_physics::LawSpec;
use tribo_wire::{OnboardResult, Verdict};

/// Host and on-board results disagree beyond this many combined standard errors.
pub const DISAGREE_SIGMAS: f64 = 3.0;

/// Where the on-board result came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnboardSource {
    /// The rig's own result, stored with the run.
    Rig,
    /// The firmware's pipeline run on the host over the record's samples (`tribo onboard`).
    Record,
}

/// The comparison of the host fit with the on-board result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CrossCheck {
    /// Where the on-board result came from.
    pub source: OnboardSource,
    /// On-board μ0, μ1.
    pub onboard_mu: [f64; 2],
    /// Their standard errors.
    pub onboard_mu_se: [f64; 2],
    /// Host μ0, μ1.
    pub host_mu: [f64; 2],
    /// Their standard errors.
    pub host_mu_se: [f64; 2],
    /// (host − on-board) / √(σ_host² + σ_onboard²) for μ0 and μ1 (`null` when a σ is unknown).
    pub z: [f64; 2],
    /// Both within [`DISAGREE_SIGMAS`], and the on-board result usable.
    pub agree: bool,
    /// False when the on-board analysis said its own result is not to be used: its two
    /// estimators disagree (`estimators-disagree`). Its ± then says nothing about the record, and
    /// a distance in σ from it is no comparison: the check reads "the on-board result is not
    /// usable here", never "they agree".
    pub usable: bool,
    /// What to suspect when they do not agree (or when the on-board analysis flagged the record).
    pub suspect: Option<String>,
}

impl CrossCheck {
    /// Compares a host fit with an on-board result. `None` when the host law is not
    /// Coulomb–viscous (the rig fits only that law) or the on-board result has no estimate.
    pub fn of(host: &FitResult, onboard: &OnboardResult, source: OnboardSource) -> Option<Self> {
        if host.law != LawSpec::CoulombViscous || host.mu.len() < 2 {
            return None;
        }
        Self::of_values(
            [host.mu[0], host.mu[1]],
            [host.mu_se[0], host.mu_se[1]],
            Some(host.verdict),
            onboard,
            source,
        )
    }

    /// [`CrossCheck::of`] from the host's μ0, μ1, their standard errors and its verdict.
    pub fn of_values(
        host_mu: [f64; 2],
        host_mu_se: [f64; 2],
        host_verdict: Option<FitVerdict>,
        onboard: &OnboardResult,
        source: OnboardSource,
    ) -> Option<Self> {
        let b = &onboard.best;
        let onboard_mu = [b.mu0 as f64, b.mu1 as f64];
        let onboard_mu_se = [b.mu0_se as f64, b.mu1_se as f64];
        if onboard_mu.iter().any(|v| !v.is_finite()) || host_mu.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let z: [f64; 2] = std::array::from_fn(|j| {
            let s = host_mu_se[j].hypot(onboard_mu_se[j]);
            if s.is_finite() && s > 0.0 {
                (host_mu[j] - onboard_mu[j]) / s
            } else {
                f64::NAN
            }
        });
        let usable = onboard.verdict != Verdict::EstimatorsDisagree;
        let agree = usable
            && z.iter()
                .all(|z| z.is_finite() && z.abs() <= DISAGREE_SIGMAS);
        let suspect = if agree && onboard.verdict == Verdict::Ok {
            None
        } else if !usable {
            Some(
                "the on-board analysis's two estimators (decrement and averaging) disagree: the \
                 Coulomb–viscous law may not describe the record (`tribo explain` names what is \
                 missing)"
                    .into(),
            )
        } else if onboard.verdict != Verdict::Ok {
            Some(format!(
                "the on-board analysis flagged the record ({}): its result is the weaker of the two",
                onboard.verdict.name()
            ))
        } else if host_verdict == Some(FitVerdict::Inadequate) {
            Some(
                "the Coulomb–viscous law does not describe the record (host verdict inadequate): \
                 the two estimators weigh its misfit differently; `tribo explain` names what is \
                 missing"
                    .into(),
            )
        } else if host_verdict == Some(FitVerdict::NotConverged) {
            Some("the host fit did not converge".into())
        } else {
            Some(
                "a disturbed release or a hold before it, drift or spikes in the velocity \
                 channel, or wrong rig constants (the two estimators use them differently): \
                 look at `tribo fit --plot`"
                    .into(),
            )
        };
        Some(CrossCheck {
            source,
            onboard_mu,
            onboard_mu_se,
            host_mu,
            host_mu_se,
            z,
            agree,
            usable,
            suspect,
        })
    }

    /// [`CrossCheck::of_values`] from a stored run's host fit and the rig's own result.
    #[cfg(feature = "store")]
    pub fn of_stored(host: &tribo_store::HostFit, onboard: &OnboardResult) -> Option<Self> {
        if host.law != LawSpec::CoulombViscous {
            return None;
        }
        // Stored by its name (`FitVerdict::name`).
        let verdict = [
            FitVerdict::Adequate,
            FitVerdict::Inadequate,
            FitVerdict::NotConverged,
            FitVerdict::Drifting,
        ]
        .into_iter()
        .find(|v| host.verdict.as_deref() == Some(v.name()));
        Self::of_values(
            [host.mu0, host.mu1],
            [host.mu0_se, host.mu1_se],
            verdict,
            onboard,
            OnboardSource::Rig,
        )
    }

    /// One sentence: the distances in σ and whether they agree (and what to suspect if not).
    pub fn summary(&self) -> String {
        let z = sigmas;
        if !self.usable {
            let mut s = String::from(NOT_USABLE);
            if let Some(w) = &self.suspect {
                s.push_str(&format!("; {w}"));
            }
            return s;
        }
        let mut s = format!(
            "host − on-board: μ0 {}, μ1 {}: {}",
            z(self.z[0]),
            z(self.z[1]),
            if self.agree {
                "they agree"
            } else {
                "they disagree (more than 3 combined σ)"
            }
        );
        if let Some(w) = &self.suspect {
            s.push_str(&format!("; suspect {w}"));
        }
        s
    }

    /// One line for the terminal (and a second with what to suspect when they disagree).
    pub fn text(&self) -> String {
        let z = sigmas;
        let src = match self.source {
            OnboardSource::Rig => "the rig's own result",
            OnboardSource::Record => "the firmware's pipeline on these samples",
        };
        if !self.usable {
            let mut s = format!(
                "on-board   mu0 {:.6}, mu1 {:.6} ({src}, estimators-disagree): {NOT_USABLE}",
                self.onboard_mu[0], self.onboard_mu[1],
            );
            if let Some(why) = &self.suspect {
                s.push_str(&format!("\n           why: {why}"));
            }
            return s;
        }
        let mut s = format!(
            "on-board   mu0 {:.6} ± {:.1e}, mu1 {:.6} ± {:.1e} ({src}): host − on-board = {} and {} — {}",
            self.onboard_mu[0],
            self.onboard_mu_se[0],
            self.onboard_mu[1],
            self.onboard_mu_se[1],
            z(self.z[0]),
            z(self.z[1]),
            if self.agree {
                "they agree"
            } else {
                "THEY DISAGREE (more than 3 combined σ)"
            }
        );
        if let Some(why) = &self.suspect {
            s.push_str(&format!("\n           suspect: {why}"));
        }
        s
    }
}

/// What the cross-check says of an on-board result whose estimators disagree.
pub const NOT_USABLE: &str = "the on-board result is not usable here";

/// A distance in combined σ, signed (`?σ` when unknown).
fn sigmas(v: f64) -> String {
    if v.is_finite() {
        format!("{v:+.1}σ")
    } else {
        "?σ".into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_wire::{EnvelopeShape, Estimate};

    fn onboard(mu0: f32, mu1: f32, se: f32) -> OnboardResult {
        let e = Estimate {
            mu0,
            mu0_se: se,
            mu1,
            mu1_se: se,
        };
        OnboardResult {
            run_id: 1,
            verdict: Verdict::Ok,
            cycles: 20,
            frequency_hz: 27.0,
            initial_amplitude_m: 6.67e-4,
            duration_s: 1.0,
            best: e,
            averaging: e,
            decrement: e,
            shape: EnvelopeShape::Convex,
            curvature: 0.0,
        }
    }

    #[test]
    fn agreement_and_disagreement_are_told_apart_by_the_combined_sigma() {
        let ob = onboard(0.02, 0.01, 1e-5);
        let ok = CrossCheck::of_values(
            [0.02002, 0.00998],
            [1e-5, 1e-5],
            Some(FitVerdict::Adequate),
            &ob,
            OnboardSource::Rig,
        )
        .unwrap();
        assert!(ok.agree, "{ok:?}");
        assert!((ok.z[0] - 2.0f64.sqrt()).abs() < 0.01, "{:?}", ok.z);
        assert!(ok.suspect.is_none());
        let bad = CrossCheck::of_values(
            [0.0102, 0.0198],
            [9e-4, 2e-3],
            Some(FitVerdict::Inadequate),
            &ob,
            OnboardSource::Record,
        )
        .unwrap();
        assert!(!bad.agree);
        assert!(bad.text().contains("DISAGREE"), "{}", bad.text());
        assert!(bad.suspect.as_deref().unwrap().contains("explain"));
    }

    /// The case: the on-board estimators disagree, the "best" result's ± is inflated by
    /// their difference (0.32 on μ0 = 0.029), and a host fit at −0.0σ from it read "they agree".
    #[test]
    fn estimators_that_disagree_are_not_usable_never_agreement() {
        let mut ob = onboard(0.029, 0.004, 0.32);
        ob.verdict = Verdict::EstimatorsDisagree;
        let c = CrossCheck::of_values(
            [0.0291, 0.0041],
            [1e-5, 1e-5],
            Some(FitVerdict::Adequate),
            &ob,
            OnboardSource::Record,
        )
        .unwrap();
        assert!(!c.usable && !c.agree, "{c:?}");
        for s in [c.text(), c.summary()] {
            assert!(s.contains("not usable here"), "{s}");
            assert!(!s.contains("agree —") && !s.contains("they agree"), "{s}");
            assert!(!s.contains('σ'), "no distance in σ from it: {s}");
        }
        // an on-board result that is Ok stays usable
        let ok = CrossCheck::of_values(
            [0.029, 0.004],
            [1e-5, 1e-5],
            None,
            &onboard(0.029, 0.004, 1e-5),
            OnboardSource::Rig,
        )
        .unwrap();
        assert!(ok.usable && ok.agree, "{ok:?}");
    }

    #[test]
    fn an_unknown_sigma_is_not_agreement() {
        let ob = onboard(0.02, 0.01, f32::NAN);
        let c = CrossCheck::of_values(
            [0.02, 0.01],
            [f64::NAN, f64::NAN],
            None,
            &ob,
            OnboardSource::Rig,
        )
        .unwrap();
        assert!(!c.agree);
    }
}
