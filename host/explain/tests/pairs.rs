//! Two effects at once, each of which alone removes too small a share of the excess misfit
//! (issue #32: every pair of the vocabulary named both). The search named the best single effect
//! that removed at least 30 % of the excess; on these records no single one did (a frictional
//! lag and a sensor lag: each took 10–27 % of it, the fitted force filter bending to the rest),
//! and the records were called unexplained. Where no candidate qualifies, the pairs of the
//! strongest are fitted: a pair that removes the share, each member needed beside the other,
//! names its stronger member, and the other must then qualify on its own. Likewise two rivals
//! that explain the record about equally well are not called ambiguous when the pair of them
//! explains it with each needed beside the other: both are there. Records are grid points
//! of `explain_lhs --records 520 --seed 1`, from the independent generator (`support/bench.rs`:
//! its own equations and integrator).

mod support;

use support::lhs::{assert_within_3_sigma, explained, step_constant as constant};
use tribo_explain::{Conclusion, Explanation};

fn assert_named_both(e: &Explanation, a: &str, b: &str) {
    let mut named = e.missing_effects.clone();
    named.sort();
    let mut want = vec![a.to_string(), b.to_string()];
    want.sort();
    assert_eq!(
        named, want,
        "{:?} (ambiguous {:?})",
        e.conclusion, e.ambiguous
    );
    assert_eq!(e.conclusion, Conclusion::Explained);
    // The first was named as one of the pair (it alone removed too little), and says so.
    let first = &e.steps[0];
    let p = first
        .paired_with
        .as_ref()
        .unwrap_or_else(|| panic!("{} is not marked as named with a pair", first.effect));
    assert_eq!(p.effect, e.steps[1].effect);
    assert!(first.evidence.excess_removed < 0.3);
    assert!(p.excess_removed >= 0.3 && p.evidence >= p.threshold);
    assert!(e.steps[1].paired_with.is_none());
    assert!(e.to_text().contains("named as one of a pair with"));
}

/// Grid #316 (24.6 Hz, ×3.6 noise, a 1-pole 319 Hz filter the record does not state): a frictional
/// lag of 0.81 ms and a sensor delay of 4.8 ms. Both are named with their constants within 3σ,
/// and the fitted filter too: the base model had taken the delay as a 44 Hz filter.
#[test]
fn a_frictional_lag_and_a_sensor_delay_are_named_both() {
    let (c, e) = explained(316);
    assert_named_both(&e, "frictional-lag", "sensor-lag");
    for (effect, key) in [("frictional-lag", "memory_s"), ("sensor-lag", "delay_s")] {
        let (v, se) = constant(&e, effect, key);
        assert_within_3_sigma(key, v, se, c.truth(key));
    }
    let l = e.force_lowpass.as_ref().expect("a fitted filter");
    let (f, se) = (
        l.cutoff_hz.expect("a filter found"),
        l.cutoff_hz_se.expect("fitted"),
    );
    assert_within_3_sigma("cutoff_hz", f, se, 319.0);
    assert_eq!(l.poles, Some(1));
}

/// Grid #369 (19.5 Hz, ×7.6, no filter, a 4.5 s hold): a Stribeck rise of +170 % with a direction
/// asymmetry of 37 %: each alone took 3–23 % of the excess. Both are named, vs and the asymmetry
/// within 3σ.
#[test]
fn a_stribeck_rise_and_a_direction_asymmetry_are_named_both() {
    let (c, e) = explained(369);
    assert_named_both(&e, "stribeck", "direction-asymmetry");
    for (effect, key) in [
        ("stribeck", "v_s_m_s"),
        ("direction-asymmetry", "dmu0_forward_minus_backward"),
    ] {
        let (v, se) = constant(&e, effect, key);
        assert_within_3_sigma(key, v, se, c.truth(key));
    }
}

/// Grid #308 (22.0 Hz, ×20 noise, 2.3 kS/s, a stated 2-pole 376 Hz filter): a Stribeck rise of
/// +195 % with exponent 1 and a frictional lag of 0.76 ms. The rise was named first, as one of the
/// pair, and took exponent 2, the better fit before the lag; with the lag in, exponent 1 fits
/// better, and a quadratic velocity term was named to make up the curve's shape. The exponent is
/// chosen again with the model it is held in: the rise and the lag are named, nothing else, the
/// exponent 1, μs, vs and the memory within 3σ.
#[test]
fn a_stribeck_rise_takes_its_exponent_again_beside_a_later_effect() {
    let (c, e) = explained(308);
    assert_named_both(&e, "stribeck", "frictional-lag");
    let s = e.steps.iter().find(|s| s.effect == "stribeck").unwrap();
    assert_eq!(s.params.get("delta"), Some(&1.0));
    for (effect, key) in [
        ("stribeck", "mu_s"),
        ("stribeck", "v_s_m_s"),
        ("frictional-lag", "memory_s"),
    ] {
        let (v, se) = constant(&e, effect, key);
        assert_within_3_sigma(key, v, se, c.truth(key));
    }
}

/// Grid #432 (26.1 Hz, ×38 noise, 3.6 kS/s, a 1-pole 131 Hz filter not stated): a softening cubic
/// stiffness of 1.7 % with a sensor delay of 3.0 ms. Each alone explained the record about as well
/// as the other (evidence 887 and 878) and the record was called ambiguous between them; the pair,
/// each needed beside the other, names both, k3, the delay and the filter within 3σ.
#[test]
fn two_rivals_that_are_both_there_are_named_both() {
    let (c, e) = explained(432);
    let mut named = e.missing_effects.clone();
    named.sort();
    assert_eq!(
        named,
        ["cubic-stiffness", "sensor-lag"],
        "{:?} (ambiguous {:?})",
        e.conclusion,
        e.ambiguous
    );
    assert_eq!(e.conclusion, Conclusion::Explained);
    assert!(e.ambiguous.is_empty());
    for (effect, key) in [
        ("cubic-stiffness", "k3_n_per_m3"),
        ("sensor-lag", "delay_s"),
    ] {
        let (v, se) = constant(&e, effect, key);
        assert_within_3_sigma(key, v, se, c.truth(key));
    }
    let l = e.force_lowpass.as_ref().expect("a fitted filter");
    assert_within_3_sigma(
        "cutoff_hz",
        l.cutoff_hz.expect("a filter found"),
        l.cutoff_hz_se.expect("fitted"),
        131.0,
    );
}
