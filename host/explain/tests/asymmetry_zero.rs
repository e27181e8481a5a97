//! Direction asymmetry against the force channel's zero (issue #32), on grid points of
//! `explain_lhs --records 520 --seed 1` from the independent generator (`support/bench.rs`: its
//! own equations and integrator).
//!
//! What a record can tell. With μ0 forward/backward `μ0 ± a/2`, the generator's friction force is
//! `N (d μ0 + a/2)` while sliding (`d` the direction): a constant `aN/2` on top of the symmetric
//! law, which moves the equilibrium by `−aN/(2k)`. Its stick rule (`|k x| ≤ N (μ0 + d a/2)` with
//! `d = −sgn x`) is `|k x + aN/2| ≤ N μ0`, the symmetric rule about the moved equilibrium; while
//! stuck its force channel reads the spring, `−k x`. So the record is, sample for sample, the
//! record of a symmetric contact released from `x0 + aN/(2k)` about its own spring rest, read by a
//! vibrometer whose zero is `aN/(2k)` off and a force channel whose zero is `aN/2` off (the rest
//! tail included: `−k x = −k (x_s − aN/2k) + … ` is the symmetric spring force plus the same
//! offset). Three unknowns — the vibrometer's zero `c`, the force channel's zero `z` and `δ = aN/2`
//! — enter the sliding centre as `A = c − δ/k`, the sliding force level as `B = z + δ`, and the
//! rest tail's `F + k y` as `C = z + k c`: `C = k A + B` always, so the tail adds no equation and
//! only a known zero (stated, or measured over the magnet's hold) separates them. Without either
//! the answer must be *ambiguous* between the asymmetry and a zero offset, which the first two
//! tests check. (Only a filter or a memory that starts from the zero-force state before the
//! release — the generator's 1-pole filter and frictional lag, not its 2-pole filter, which starts
//! settled at the first sample, nor its sensor delay, which holds the first value — carries a
//! trace of the true zero in the first samples after the release.)

mod support;

use support::bench::{generate, Filter};
use support::lhs::{assert_within_3_sigma, explained, grid, Case};
use tribo_explain::{explain, Conclusion, ExplainOptions, FORCE_ZERO_OFFSET};
use tribo_physics::record::Record;

/// The symmetric twin of an asymmetric grid record with the two zero offsets that make it the same
/// record: `(asymmetric record, twin record with the offsets added, offsets (m, N))`.
fn with_twin(c: &Case) -> (Record, Record, (f64, f64)) {
    let a = c.friction.asymmetry;
    let (k, n) = (c.bench.stiffness_n_per_m, c.bench.load_n);
    let shift = a * n / (2.0 * k);
    let mut f = c.friction.clone();
    f.asymmetry = 0.0;
    let mut b = c.bench.clone();
    b.x0_m += shift;
    let (mut twin, _) = generate(&f, &b);
    let (zx, zf) = (-shift, a * n / 2.0);
    for x in twin.x.iter_mut() {
        *x += zx;
    }
    for v in twin.ft.as_mut().expect("a force channel").iter_mut() {
        *v += zf;
    }
    (c.record(), twin, (zx, zf))
}

fn case(index: usize) -> Case {
    grid(520, 1)
        .into_iter()
        .find(|c| c.index == index)
        .expect("grid point")
}

/// The no-hold grid points with a direction asymmetry on the checked subsets (alone `--every 3`,
/// pairs `--every 6`) whose force channel carries no trace of the state before the release (no
/// 1-pole filter, no frictional lag): #102 (no filter), #126 and #198 (2-pole), #355 (with a
/// sensor lag), #391 (with a quadratic term), #409 (with a thermal drift). Each is its symmetric
/// twin with a vibrometer zero of `−aN/(2k)` and a force zero of `aN/2`, to within one step of
/// the 16-bit quantisation in every sample of every channel (the same noise draws): no estimator
/// can tell the two apart.
#[test]
fn a_no_hold_asymmetry_is_the_same_record_as_two_zero_offsets() {
    let lsb_x = 2.0 * 1e-3 / 65536.0;
    let lsb_v = 2.0 * 0.25 / 65536.0;
    let lsb_f = 2.0 * 1.0 / 65536.0;
    for i in [102, 126, 198, 355, 391, 409] {
        let c = case(i);
        assert!(c.friction.asymmetry != 0.0 && c.bench.hold_s == 0.0);
        assert!(!matches!(c.bench.filter, Filter::OnePole(_)) && c.friction.memory_s == 0.0);
        let (r, t, (zx, zf)) = with_twin(&c);
        assert_eq!(r.t.len(), t.t.len(), "#{i}: the same stop");
        let max = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(p, q)| (p - q).abs())
                .fold(0.0, f64::max)
        };
        let dx = max(&r.x, &t.x) / lsb_x;
        let dv = max(&r.v, &t.v) / lsb_v;
        let df = max(r.ft.as_deref().unwrap(), t.ft.as_deref().unwrap()) / lsb_f;
        println!(
            "#{i}: zeros {:.3} µm, {zf:.3e} N ({:.0} force steps); largest difference {dx:.2}, \
             {dv:.2}, {df:.2} steps (x, v, F)",
            zx * 1e6,
            zf.abs() / lsb_f
        );
        assert!(
            dx <= 1.0 + 1e-6 && dv <= 1.0 + 1e-6 && df <= 1.0 + 1e-6,
            "#{i}: {dx} {dv} {df}"
        );
    }
}

/// Grid #126 (31.7 Hz, μ0 0.063, forward − backward −6.5e-3 = −10 % of μ0, 2-pole 250 Hz not
/// stated, no hold, noise ×1.2) and its symmetric twin with the two zero offsets: on both, explain
/// names neither a direction asymmetry nor a zero offset, says *ambiguous* between them, and the
/// fitted force zero holds the offset `aN/2` (−1.20e-3 N) within 3σ.
#[test]
fn explain_cannot_tell_a_no_hold_asymmetry_from_two_zero_offsets() {
    let c = case(126);
    let (rec, twin, (_, zf)) = with_twin(&c);
    for (what, r) in [("asymmetric", rec), ("twin", twin)] {
        let e = explain(&r, &ExplainOptions::default()).expect("explain runs");
        let ch = e.measurement_chain.as_ref().expect("a measurement chain");
        let (z, se) = (ch.force_zero_n.unwrap(), ch.force_zero_n_se.unwrap());
        println!(
            "{what}: {:?} {:?} (ambiguous {:?}); force zero {z:.4e} ± {se:.1e} (offset {zf:.4e})",
            e.conclusion, e.missing_effects, e.ambiguous
        );
        assert_eq!(e.conclusion, Conclusion::Ambiguous, "{what}");
        assert!(
            !e.missing_effects.iter().any(|m| m == "direction-asymmetry"),
            "{what}: {:?}",
            e.missing_effects
        );
        assert_eq!(
            e.ambiguous,
            vec![
                "direction-asymmetry".to_string(),
                FORCE_ZERO_OFFSET.to_string()
            ],
            "{what}"
        );
        assert_eq!(ch.force_zero_source.as_deref(), Some("fitted"), "{what}");
        assert!(se.is_finite() && (z - zf).abs() <= 3.0 * se, "{what}");
    }
}

/// Grid #439 (19.7 Hz, 0.071 N, μ0 3.9e-3, forward − backward +2.7e-4 = 6.9 % of μ0, a sensor
/// delay of 0.78 ms, 2-pole 258 Hz stated, held 1.2 s, noise ×8.1): the force zero is measured over
/// the hold (± 2.1e-6 N), the asymmetry is a force offset of 1.0e-5 N under a force noise of 2e-4
/// N. The sensor lag took the model to its noise floor in round 1, and the search stopped there:
/// only the sensor lag was named, although the asymmetry's evidence was 167 in that round. The
/// asymmetry is tried at the floor too, and named beside the lag with its constant within 3σ.
#[test]
fn an_asymmetry_against_a_held_zero_is_named_beside_another_effect_at_the_floor() {
    let e = asymmetry_named_beside(439, "sensor-lag");
    assert_eq!(e.conclusion, Conclusion::Explained);
}

/// Explains grid point `index`, asserts that exactly the direction asymmetry and `other` are
/// named and that the asymmetry's constant holds the truth within 3σ with a ± under half its
/// value; the explanation for further checks.
fn asymmetry_named_beside(index: usize, other: &str) -> tribo_explain::Explanation {
    let (c, e) = explained(index);
    let mut named = e.missing_effects.clone();
    named.sort();
    let mut want = vec!["direction-asymmetry", other];
    want.sort();
    assert_eq!(named, want);
    let key = "dmu0_forward_minus_backward";
    let truth = c.truth(key);
    let step = e
        .steps
        .iter()
        .find(|s| s.effect == "direction-asymmetry")
        .expect("the asymmetry's step");
    let (v, se) = (step.params[key], step.params_se[key]);
    assert_within_3_sigma(key, v, se, truth);
    assert!(se < 0.5 * v.abs(), "± {se} against {v:.4e}");
    e
}

/// Grid #78 (1-pole 858 Hz at 3.6 kS/s, no hold, forward − backward −8.3e-3, noise ×49) and #307
/// (1-pole 973 Hz at 7.3 kS/s, no hold, with a quadratic term, +3.7e-3): the generator's 1-pole
/// filter starts at rest at zero force, so the first samples after the release differ from the
/// twin's. What that difference is worth, `Σ (ΔF / σ_F)²` over five of the filter's time constants
/// (σ_F = 2e-4 N, the grid's force noise), is under 1 unit of `−2 ln L` on both (measured 0.5 and
/// 0.1), far under the 14.7 a constant needs: these records do not carry the zero either.
#[test]
fn a_one_pole_start_carries_little_of_the_zero() {
    for i in [78, 307] {
        let c = case(i);
        assert!(matches!(c.bench.filter, Filter::OnePole(_)) && c.bench.hold_s == 0.0);
        let (r, t, (_, zf)) = with_twin(&c);
        let (a, b) = (r.ft.unwrap(), t.ft.unwrap());
        let d: Vec<f64> = a.iter().zip(&b).map(|(p, q)| (p - q) / 2e-4).collect();
        // Over five of the filter's time constants (the rest differs by the quantisation only).
        let Filter::OnePole(fc) = c.bench.filter else {
            unreachable!()
        };
        let n = (5.0 * c.bench.rate_hz / (2.0 * std::f64::consts::PI * fc)).ceil() as usize + 1;
        let info: f64 = d.iter().take(n).map(|v| v * v).sum();
        assert!(info < 1.0, "#{i}: {info}");
        println!(
            "#{i}: offset {zf:.3e} N; first differences {:?} σ_F; Σ (ΔF/σ_F)² = {info:.2} over {n}",
            d.iter()
                .take(4)
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
        );
    }
}

/// Grid #374 (26.2 Hz, 0.197 N, μ0 4.5e-3, a frictional lag of 0.89 ms, forward − backward
/// +3.5e-4 = 7.6 % of μ0, 2-pole 367 Hz not stated, held 4.7 s, noise ×1.1): after the lag, the
/// model was at its floor with the force channel's level drifting (5.2σ), and only the drifts and
/// the velocity terms were tried: the lag was named alone. The asymmetry is a level the model
/// misses as well, and is named beside the lag with its constant within 3σ.
#[test]
fn an_asymmetry_is_tried_where_the_force_level_drifts_at_the_floor() {
    asymmetry_named_beside(374, "frictional-lag");
}

/// The grid's scoring of an asymmetry the record cannot identify (`support::lhs::unidentifiable`):
/// on a no-hold record (#126) the right answer names nothing for the asymmetry and flags the
/// offset; naming it is a false name, and saying nothing about the offset is wrong. On a held
/// record (#439) the asymmetry stays an expected name.
#[test]
fn the_grid_scores_a_no_hold_asymmetry_as_the_offset_flagged() {
    use support::lhs::{score, unidentifiable, vocabulary, Outcome};
    let vocab = vocabulary();
    let answer = |named: &[&str], flagged: bool| Outcome {
        named: named.iter().map(|s| s.to_string()).collect(),
        conclusion: "ambiguous".into(),
        estimates: vec![],
        force_offset_flagged: flagged,
        seconds: 0.0,
    };
    let c = case(126);
    assert!(c.bench.hold_s <= 0.0 && unidentifiable(&c, "direction-asymmetry"));
    let s = score(&c, &answer(&[], true), &vocab);
    assert!(s.right && s.expected.is_empty(), "{s:?}");
    assert_eq!(s.unidentifiable, vec!["direction-asymmetry".to_string()]);
    assert!(!score(&c, &answer(&[], false), &vocab).right);
    let guessed = score(&c, &answer(&["direction-asymmetry"], true), &vocab);
    assert!(!guessed.right && guessed.false_names == vec!["direction-asymmetry".to_string()]);
    // The real answer on #126 is scored right.
    let real = support::lhs::run(&c);
    assert!(real.force_offset_flagged, "{real:?}");
    assert!(score(&c, &real, &vocab).right, "{real:?}");

    let h = case(439);
    assert!(h.bench.hold_s > 0.0 && !unidentifiable(&h, "direction-asymmetry"));
    let s = score(&h, &answer(&["sensor-lag"], true), &vocab);
    assert!(!s.right && s.expected.contains(&"direction-asymmetry".to_string()));
}
