//! A Stribeck rise beside a quadratic velocity term (issue #32: every pair of the vocabulary). The
//! model's Stribeck curve (`FrictionLaw::Stribeck`) had no quadratic term, so a spec with both
//! could not be built and the pair could only be named half: grid #301 and #385 were named
//! Stribeck alone. The curve now carries the pseudo-polynomial law's `μ2 y'² sgn(y')`, and either
//! effect can be added beside the other. Records from the independent generators of `support`
//! (their own equations and integrators).

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
        assert_within_3_sigma("mu_s", s.params["mu_s"], s.params_se["mu_s"], 0.03);
        assert_within_3_sigma("v_s", s.params["v_s"], s.params_se["v_s"], 0.2);
    }
}

/// Grid #385 (a Stribeck rise of 132 % with exponent 1 and a quadratic term of 18 %, 12.3 kS/s,
/// a stated 991 Hz filter, held 1.4 s, ×3.2 noise) and #301 (28 % and 14 %, no filter, ×44): both
/// effects named (the grid's exponent 1 is not the model's 2, so only the names are scored, as
/// `explain_lhs` scores them). Both were named Stribeck alone before.
#[test]
fn grid_pairs_of_stribeck_and_quadratic_velocity_are_named_both() {
    for index in [385, 301] {
        let (_, e) = explained(index);
        assert_named_both(&format!("#{index}"), &e);
    }
}
