//! Effects the search used to leave unnamed though their evidence was tens to hundreds of times
//! its threshold (issue #32: every effect from its detection limit, every pair named both):
//!
//! - a frictional lag, whose absence was taken as the shortest memory the model simulates
//!   (72 µs at 22 Hz) rather than no memory at all, so a lag of 0.13 ms was compared with one of
//!   72 µs and lost its evidence;
//! - the second of a cubic stiffness and a frictional lag, the two effects that change the motion
//!   itself, once the first had taken the model under 1.5 × its noise floor: it was not tried
//!   again there;
//! - a sensor delay that the fitted force filter's order had taken in: a 2-pole filter's extra
//!   phase mimics a 1-pole filter with a delay, so the order chosen at the base law left the
//!   delay nothing to explain;
//! - two effects hidden behind a step whose constant the later refits slid to the edge of its
//!   range, which is now withdrawn;
//! - and a sensor delay left beside another effect once that effect had taken the model under
//!   1.5 × its noise floor, where the force channel's level still differed across the track:
//!   the delay was not tried there, and the position check then took the whole record for a
//!   stripe of the track.
//!
//! Records are grid points of `explain_lhs --records 520 --seed 1`, from the independent
//! generator (`support/bench.rs`: its own equations and integrator).

mod support;

use support::lhs::{assert_within_3_sigma, explained, step_constant as constant};
use tribo_explain::{Conclusion, Explanation};

fn named(e: &Explanation) -> Vec<String> {
    let mut n = e.missing_effects.clone();
    n.sort();
    n
}

/// Explains grid record `n`, asserts it names `want` (sorted) and nothing else, and each of
/// `constants` (effect, key) within 3σ of the truth.
fn names_and_constants(n: usize, want: &[&str], constants: &[(&str, &str)]) -> Explanation {
    let (c, e) = explained(n);
    assert_eq!(
        named(&e),
        want,
        "#{n}: {:?} (ambiguous {:?}; {:?})",
        e.conclusion,
        e.ambiguous,
        e.disagreement
    );
    for (effect, key) in constants {
        let (v, se) = constant(&e, effect, key);
        assert_within_3_sigma(key, v, se, c.truth(key));
    }
    e
}

/// The force filter the record does not state is fitted 1-pole, its cut-off within 3σ of `hz`.
fn assert_fitted_1_pole(e: &Explanation, hz: f64) {
    let l = e.force_lowpass.as_ref().expect("a fitted filter");
    assert_eq!(l.poles, Some(1));
    assert_within_3_sigma(
        "cutoff_hz",
        l.cutoff_hz.expect("a filter found"),
        l.cutoff_hz_se.expect("fitted"),
        hz,
    );
}

/// Grid #161 (22.1 Hz, ×5.9 noise, no filter, a 3.2 s hold): a frictional lag of 0.13 ms alone.
/// Its evidence against the Coulomb–viscous law is 91 (threshold 14.7); held at 72 µs, the
/// shortest memory simulated, the rest refitted 78 units of χ² under the law, and the record was
/// called base-adequate. The lag is named, its memory within 3σ.
#[test]
fn a_short_frictional_lag_is_told_from_no_lag_not_from_the_shortest_one() {
    let e = names_and_constants(161, &["frictional-lag"], &[("frictional-lag", "memory_s")]);
    assert_eq!(e.conclusion, Conclusion::Explained);
}

/// Grid #314 (23.3 Hz, ×3.3, a 2-pole 516 Hz filter not stated): a frictional lag of 0.83 ms with
/// a softening cubic stiffness of 3.1 %. The cubic is named first and leaves the model at 1.06 ×
/// its floor, where the lag's evidence is several hundred; it is named too, both constants within
/// 3σ.
#[test]
fn a_frictional_lag_beside_a_cubic_stiffness_is_tried_at_the_floor() {
    let e = names_and_constants(
        314,
        &["cubic-stiffness", "frictional-lag"],
        &[
            ("cubic-stiffness", "k3_n_per_m3"),
            ("frictional-lag", "memory_s"),
        ],
    );
    assert_eq!(e.conclusion, Conclusion::Explained);
    // The lag was named where the model was already under 1.5 × its floor.
    let lag = e
        .steps
        .iter()
        .find(|s| s.effect == "frictional-lag")
        .unwrap();
    assert!(lag.evidence.value >= 10.0 * lag.evidence.threshold);
}

/// Grid #124 (25.5 Hz, ×3.1, 3.5 kS/s): a sensor delay of 0.36 ms behind a 1-pole 315 Hz filter
/// the record does not state. The base law chose a 2-pole filter (at 268 Hz, better than a
/// 1-pole without a delay by 19), beside which the delay's evidence was 3. Fitted with either
/// order, the delay is named and measured, and the filter comes out 1-pole at its cut-off.
#[test]
fn a_sensor_delay_is_fitted_with_either_order_of_the_filter() {
    let e = names_and_constants(124, &["sensor-lag"], &[("sensor-lag", "delay_s")]);
    assert_fitted_1_pole(&e, 315.0);
}

/// Grid #379 (27.5 Hz, ×22 noise, 2.7 kS/s, no filter): a thermal drift of 14 % over a 3 K ramp
/// with a sensor delay of 0.73 ms. Under the 2-pole filter the base law chose, a frictional lag was
/// named first (0.046 ± 0.003 rad); the refits after it slid the memory to the edge of its range,
/// and the lag held the wrong filter order in place. The step is withdrawn once its constant is
/// within 2σ of its absence, the filter's order is checked again, and both effects are named,
/// their constants within 3σ.
#[test]
fn a_step_whose_constant_slides_to_its_edge_is_withdrawn() {
    names_and_constants(
        379,
        &["sensor-lag", "thermal-drift"],
        &[
            ("sensor-lag", "delay_s"),
            ("thermal-drift", "dmu0_dT_per_c"),
        ],
    );
}

/// Grid #320 (21.5 Hz, ×4.5 noise, 16 kS/s, a 1-pole 551 Hz filter not stated): a softening cubic
/// stiffness of 4 % with a sensor delay of 2.3 ms. The cubic takes the model to its floor; the
/// delay was not tried there, and the force channel's level, which the delay leaves differing
/// across the track (χ² 89 over 10 bins), made the position check set the cubic aside and call
/// the record unexplained. Where that check is significant at the floor the delay is tried: both
/// are named, their constants within 3σ.
#[test]
fn a_sensor_delay_is_tried_at_the_floor_where_the_level_differs_across_the_track() {
    let e = names_and_constants(
        320,
        &["cubic-stiffness", "sensor-lag"],
        &[
            ("cubic-stiffness", "k3_n_per_m3"),
            ("sensor-lag", "delay_s"),
        ],
    );
    assert_eq!(e.conclusion, Conclusion::Explained);
}

/// Grid #428 (26.8 Hz, ×11 noise, a 4.6 s hold, a 1-pole 404 Hz filter not stated): a frictional
/// lag of 1.9 ms with a sensor delay of 2.3 ms. The lag took the model to its floor, and the
/// record was called unexplained for the same reason as #320. Both are named, their constants and
/// the filter's cut-off within 3σ, the filter 1-pole.
#[test]
fn a_sensor_delay_beside_a_frictional_lag_is_tried_at_the_floor() {
    let e = names_and_constants(
        428,
        &["frictional-lag", "sensor-lag"],
        &[("frictional-lag", "memory_s"), ("sensor-lag", "delay_s")],
    );
    assert_fitted_1_pole(&e, 404.0);
}
