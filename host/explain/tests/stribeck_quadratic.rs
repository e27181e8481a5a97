//! A Stribeck rise beside a quadratic velocity term (issue #32: every pair of the vocabulary), and
//! the rise's exponent. The model's Stribeck curve (`FrictionLaw::Stribeck`) had no quadratic
//! term, so a spec with both could not be built and the pair could only be named half: grid #301
//! was named Stribeck alone. The curve now carries the pseudo-polynomial law's `μ2 y'² sgn(y')`,
//! and either effect can be added beside the other. The curve's exponent was 2; a contact shows
//! 1 or 2, and a rise that has won is now fitted with both, the better kept. Records from the
//! independent generators of `support` (their own equations and integrators).

mod support;

use support::lhs::{assert_within_3_sigma, explained};
use support::{record, Contact};
use tribo_explain::{explain, Conclusion, ExplainOptions, Explanation};
use tribo_physics::sensor::SensorModel;

fn assert_named_both(what: &str, e: &Explanation) {
    let mut named = e.missing_effects.clone();
    named.sort();
    assert_eq!(
        named,
        ["quadratic-velocity", "stribeck"],
        "{what}: {:?} (ambiguous {:?})",
        e.conclusion,
        e.ambiguous
    );
    assert_eq!(e.conclusion, Conclusion::Explained, "{what}");
}

/// The real rig at 0.3 N, μ0 0.02, μ1 0.002, a Stribeck rise to μs 0.03 (+50 %) below vs 0.2
/// (8.8 mm/s; the model's own exponent, 2) and a quadratic term of either sign (μ2 ±3e-4, ±10 %
/// of μ0 at the release's peak speed), through the default acquisition chain: both are named, and
/// μ2, μs and vs hold the truth within 3σ. The same rise without the quadratic term is named
/// alone (the term is not named for nothing).
///
/// The Stribeck constants are the final model's: those of the step that named the rise, fitted
/// before the quadratic term, had vs 3.5–4 % off (7.8σ) on these records, with the sign of μ2.
#[test]
fn stribeck_and_quadratic_velocity_are_named_both_with_their_constants() {
    for (mu2, seed) in [(3e-4, 5), (-3e-4, 6), (0.0, 7)] {
        let mut c = Contact::coulomb_viscous(0.02, 0.002);
        c.mu2 = mu2;
        c.stribeck = Some((0.03, 0.2));
        let chain = SensorModel {
            seed,
            ..SensorModel::default()
        };
        let rec = record(&c, 0.3, 1.5, Some(&chain));
        let e = explain(&rec, &ExplainOptions::default()).expect("explain runs");
        let what = format!("μ2 {mu2:+e}");
        println!(
            "{what}: {:?} {:?} (ambiguous {:?})",
            e.conclusion, e.missing_effects, e.ambiguous
        );
        let step = |name: &str| e.steps.iter().find(|s| s.effect == name);
        if mu2 == 0.0 {
            assert_eq!(e.missing_effects, ["stribeck"], "{what}");
            assert_eq!(e.conclusion, Conclusion::Explained, "{what}");
        } else {
            assert_named_both(&what, &e);
            let q = step("quadratic-velocity").unwrap();
            assert_within_3_sigma("mu2", q.params["mu2"], q.params_se["mu2"], mu2);
        }
        let s = step("stribeck").unwrap();
        assert_eq!(exponent(&e), 2.0, "{what}");
        assert_within_3_sigma("mu_s", s.params["mu_s"], s.params_se["mu_s"], 0.03);
        assert_within_3_sigma("v_s", s.params["v_s"], s.params_se["v_s"], 0.2);
    }
}

/// The curve's exponent chosen ([`tribo_explain`]'s `Spec::stribeck_delta`), read from a step.
fn exponent(e: &Explanation) -> f64 {
    let s = e.steps.iter().find(|s| s.effect == "stribeck").unwrap();
    assert!(s.params_se["delta"].is_nan(), "a chosen exponent has no ±");
    s.params["delta"]
}

/// Grid #301 (a Stribeck rise of 28 % with exponent 1 and a quadratic term of 14 %, no filter,
/// held 1.5 s, ×44 noise): both named, the exponent 1 chosen, and μ2 and μs within 3σ. It was
/// named Stribeck alone before the pair could be built; with the exponent held at 2 both were
/// named, μ2 6.8e-4 ± 5.5e-5 for 4.5e-4 (4σ), the quadratic term taking the shape's misfit.
/// Grid #96 (Stribeck alone, 11 %, exponent 1, ×11): μs and vs within 3σ with the exponent 1
/// (with 2: μs 6.6σ and vs 5.9σ off).
#[test]
fn a_stribeck_rise_of_exponent_1_is_fitted_with_it() {
    let (c, e) = explained(301);
    assert_named_both("#301", &e);
    assert_eq!(exponent(&e), 1.0);
    let step = |name: &str| e.steps.iter().find(|s| s.effect == name).unwrap();
    let (q, s) = (step("quadratic-velocity"), step("stribeck"));
    assert_within_3_sigma("mu2", q.params["mu2"], q.params_se["mu2"], c.truth("mu2"));
    assert_within_3_sigma(
        "mu_s",
        s.params["mu_s"],
        s.params_se["mu_s"],
        c.truth("mu_s"),
    );

    let (c, e) = explained(96);
    assert_eq!(e.missing_effects, ["stribeck"]);
    assert_eq!(exponent(&e), 1.0);
    let s = &e.steps[0];
    for key in ["mu_s", "v_s_m_s"] {
        assert_within_3_sigma(key, s.params[key], s.params_se[key], c.truth(key));
    }
}
