//! A friction level that depends on where the pin slides is outside the vocabulary (issue #32):
//! explain must not name it as one of its effects, and says where it is instead. On the randomized
//! grid (`explain_lhs --only worn-stripe`) a worn stripe was named running-in, Stribeck or cubic
//! stiffness in 15 of 32 records. The force channel's friction level on one side of the track
//! against the mirror side ([`tribo_explain::diag::PositionDependence`]) finds an off-centre
//! stripe; no effect of the vocabulary makes the two sides differ. The records come from the
//! independent generator (`support/bench.rs`).

mod support;

use support::bench::{generate, Bench, Filter, Friction};
use support::lhs::explained;
use tribo_explain::diag::PositionDependence;
use tribo_explain::{explain, Conclusion, ExplainOptions, Explanation};

/// The real rig, 2-pole 300 Hz stated, default noise, 1.6 s.
fn bench(seed: u64) -> Bench {
    Bench {
        filter: Filter::TwoPole(300.0),
        filter_stated: true,
        max_s: 1.6,
        rest_s: 0.2,
        seed,
        ..Bench::rig()
    }
}

/// Explain on the contact μ0 0.02, μ1 0.002 with a stripe centred at `centre` × x0, ±0.15 x0 wide,
/// of relative change `s`: the explanation and its position check.
fn explain_stripe(b: &Bench, centre: f64, s: f64) -> (Explanation, PositionDependence) {
    let c = Friction {
        stripe: Some((centre * b.x0_m, 0.15 * b.x0_m, s)),
        ..Friction::coulomb_viscous(0.02, 0.002)
    };
    let (rec, _) = generate(&c, b);
    let e = explain(&rec, &ExplainOptions::default()).unwrap();
    let p = e.position_dependence.clone().expect("a force channel");
    (e, p)
}

/// A stripe 30 % more slippery or stickier than the rest, centred at +0.35 x0, ±0.15 x0 wide:
/// no effect named, *unexplained*, and the check puts the stripe on its side of the track. The
/// same contact without the stripe: the check does not fire and the record is base-adequate.
#[test]
fn a_worn_stripe_is_not_named_and_is_located() {
    let b = bench(5);
    let mut failures = Vec::new();
    for s in [0.3, -0.3] {
        let (e, p) = explain_stripe(&b, 0.35, s);
        println!(
            "stripe {s:+}: {:?} {:?}; {}",
            e.conclusion,
            e.missing_effects,
            p.text()
        );
        if !e.missing_effects.is_empty() || e.conclusion != Conclusion::Unexplained {
            failures.push(format!(
                "stripe {s:+}: {:?} {:?}",
                e.conclusion, e.missing_effects
            ));
        }
        // The side that stands higher: the stripe's when it is stickier, the mirror's when it
        // is more slippery.
        let expect_side = if s > 0.0 { 1.0 } else { -1.0 };
        if !(p.significant && p.at_m * expect_side > 0.0) {
            failures.push(format!("stripe {s:+}: {p:?}"));
        }
        if !e.to_text().contains("depends on where the pin slides") {
            failures.push(format!("stripe {s:+}: the text does not say where"));
        }
    }
    let (rec, _) = generate(&Friction::coulomb_viscous(0.02, 0.002), &b);
    let e = explain(&rec, &ExplainOptions::default()).unwrap();
    let p = e.position_dependence.clone().expect("a force channel");
    println!("clean: {:?}; {}", e.conclusion, p.text());
    if p.significant || e.conclusion != Conclusion::BaseAdequate {
        failures.push(format!("clean: {:?} {p:?}", e.conclusion));
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// A stripe across the centre of the track is the same on both sides: the mirror pairs cannot see
/// it, and its share of the sliding grows as the amplitude decays, so the search fits a μ0 drift
/// to it. The profile of the level across the track ([`tribo_explain::diag::AcrossTrack`]) tells
/// it from one: grid #463 (a +12 % stripe at −23 µm, ±83 µm wide, on a 640 µm release, ×43 the
/// noise) was named running-in (*explained*); it is *unexplained*, nothing named, and the text
/// says the level depends on the distance from the centre. On the real rig at the default noise,
/// a ±30 % stripe centred on the track is not named either way (the +30 % one leaves the base
/// law's misfit and the search names nothing; the −30 % one had running-in named).
#[test]
fn a_stripe_across_the_centre_is_not_named() {
    let mut failures = Vec::new();
    let (_, e) = explained(463);
    let p = e.position_dependence.clone().expect("a force channel");
    println!("#463: {:?}", p.across);
    if !e.missing_effects.is_empty() || e.conclusion != Conclusion::Unexplained {
        failures.push(format!("#463: {:?} {:?}", e.conclusion, e.missing_effects));
    }
    if !p.across.as_ref().is_some_and(|a| a.significant) {
        failures.push(format!("#463: not seen across the track: {:?}", p.across));
    }
    if !e.to_text().contains("distance from the centre") {
        failures.push("#463: the text does not say where".into());
    }
    let b = bench(7);
    for s in [0.3, -0.3] {
        let (e, p) = explain_stripe(&b, 0.0, s);
        println!(
            "stripe {s:+} across the centre: {:?} {:?}; {:?}; mirror max z {:.1}",
            e.conclusion, e.missing_effects, p.across, p.max_z
        );
        if !e.missing_effects.is_empty() || e.conclusion != Conclusion::Unexplained {
            failures.push(format!(
                "stripe {s:+}: {:?} {:?}",
                e.conclusion, e.missing_effects
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// A stripe near the centre takes a larger share of each swing as the amplitude decays, which
/// raises the mean friction level over the motion as running-in does: grid #499 (a +30 % stripe
/// at 22 µm, ±78 µm wide, on a 329 µm release, ×24 the noise) was named running-in at evidence
/// 134, neither the mirror pairs nor the profile across the track significant. Running-in is
/// named only where it explains the force channel at least as well as the best stripe of the
/// track, given the stripe's freedom of where it lies ([`tribo_explain::diag::drift_or_stripe`]):
/// #499 is *ambiguous*, running-in or a level of the track's own, nothing named, the stripe put
/// where it is. Nor where a stripe is there beside the drift (its evidence beside it past the
/// false-alarm rate of one round for 3 constants, 16.3): #483 (a −11 % stripe, ×4.5 the noise:
/// the drift 103 alone, the stripe 102, and beside the drift 17) was named running-in with a
/// caveat; it is *ambiguous*, and says the stripe is there beside the drift. Records with
/// running-in and no stripe keep the name: #189 (10 % in the compared motion, first-order),
/// #237 (30 %) and #213 (linear, 7 % in the compared motion: the stripe beside the drift 7.4),
/// alone, and #349 beside a cubic stiffness; all but #213 without the caveat.
#[test]
fn a_stripe_is_not_named_running_in() {
    let mut failures = Vec::new();
    let (_, e) = explained(483);
    failures.extend(ambiguous_with_a_stripe(
        483,
        &e,
        "running-in",
        "is there beside it",
    ));
    let (_, e) = explained(499);
    let c = e.drift_or_stripe.clone();
    failures.extend(ambiguous_with_a_stripe(
        499,
        &e,
        "running-in",
        "a stripe of the track from",
    ));
    // The truth: 22 µm ± 78 µm, from −56 to 100 µm; the stripe found must overlap most of it.
    match &c {
        Some(c) if c.stripe_from_to_m.0 < 0.0 && c.stripe_from_to_m.1 > 60e-6 => {}
        _ => failures.push(format!("#499: the stripe is not where it is: {c:?}")),
    }
    for (n, expect) in [
        (189, &["running-in"][..]),
        (237, &["running-in"][..]),
        (213, &["running-in"][..]),
        (349, &["cubic-stiffness", "running-in"][..]),
    ] {
        let (_, e) = explained(n);
        let mut named = e.missing_effects.clone();
        named.sort();
        println!(
            "#{n}: {:?} {named:?}; {:?}",
            e.conclusion, e.drift_or_stripe
        );
        if named != expect {
            failures.push(format!("#{n}: {:?} {named:?}", e.conclusion));
        }
        if e.drift_or_stripe
            .as_ref()
            .is_none_or(|c| (c.close && n != 213) || c.stripe_beside_drift > 10.0)
        {
            failures.push(format!("#{n}: {:?}", e.drift_or_stripe));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// A cubic stiffness the motion does not show is a force that depends on where the pin slides,
/// all its evidence in the force channel, where a stripe of the track is its rival: grid #503 (a
/// +19 % stripe at −73 µm, ±72 µm wide, ×34 the noise, no hold) was named a cubic stiffness of
/// evidence 343, the envelope channel's −0.1. Such a cubic is named only where its own shape
/// explains the force channel's friction level at least as well as the best stripe, given the
/// stripe's freedom of where it lies: #503 is *ambiguous*, a cubic stiffness or a level of the
/// track's own, nothing named, the stripe put on the side where it is. Cubic stiffnesses the
/// envelope does not see keep their name: #170 (0.06 % of k, ×6 noise: its shape 24 against the
/// stripe's 4, the least margin of the grid's), and #321, a cubic of 1.3 % with a running-in of
/// 23 % (in the search with the filter order it later leaves, a stripe across the centre that
/// the running-in takes: no rival).
#[test]
fn a_stripe_is_not_named_cubic_stiffness() {
    let mut failures = Vec::new();
    let (_, e) = explained(503);
    let c = e.drift_or_stripe.clone();
    failures.extend(ambiguous_with_a_stripe(
        503,
        &e,
        "cubic-stiffness",
        "as a cubic stiffness would make it",
    ));
    // The truth: −73 µm ± 72 µm, from −145 to −1 µm; the stripe found must be on that side.
    match &c {
        Some(c) if c.stripe_from_to_m.0 < -60e-6 && c.stripe_from_to_m.1 < 30e-6 => {}
        _ => failures.push(format!("#503: the stripe is not where it is: {c:?}")),
    }
    for (n, expect) in [
        (170, &["cubic-stiffness"][..]),
        (321, &["cubic-stiffness", "running-in"][..]),
    ] {
        let (_, e) = explained(n);
        let mut named = e.missing_effects.clone();
        named.sort();
        println!("#{n}: {:?} {named:?} {:?}", e.conclusion, e.ambiguous);
        if named != expect {
            failures.push(format!("#{n}: {:?} {named:?}", e.conclusion));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The failure, if `e` (grid record `n`) names anything or is not *ambiguous* between `rival` and
/// a friction level of the track's own, or its text does not say `says`.
fn ambiguous_with_a_stripe(n: usize, e: &Explanation, rival: &str, says: &str) -> Option<String> {
    use tribo_explain::POSITION_LEVEL;
    println!(
        "#{n}: {:?} {:?} {:?}; {:?}",
        e.conclusion, e.missing_effects, e.ambiguous, e.drift_or_stripe
    );
    let right = e.missing_effects.is_empty()
        && e.conclusion == Conclusion::Ambiguous
        && e.ambiguous == [rival.to_string(), POSITION_LEVEL.to_string()]
        && e.to_text().contains(says);
    (!right).then(|| {
        format!(
            "#{n}: {:?} {:?} {:?}, the text saying {says:?}: {}",
            e.conclusion,
            e.missing_effects,
            e.ambiguous,
            e.to_text().contains(says)
        )
    })
}
