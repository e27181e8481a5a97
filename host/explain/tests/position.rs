//! A friction level that depends on where the pin slides is outside the vocabulary (issue #32):
//! explain must not name it as one of its effects, and says where it is instead. On the randomized
//! grid (`explain_lhs --only worn-stripe`) a worn stripe was named running-in, Stribeck or cubic
//! stiffness in 15 of 32 records. The force channel's friction level on one side of the track
//! against the mirror side ([`tribo_explain::diag::PositionDependence`]) finds an off-centre
//! stripe; no effect of the vocabulary makes the two sides differ. The records come from the
//! independent generator (`support/bench.rs`).

mod support;

use support::bench::{generate, Bench, Filter, Friction};
use tribo_explain::{explain, Conclusion, ExplainOptions};

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

/// A stripe 30 % more slippery or stickier than the rest, centred at +0.35 x0, ±0.15 x0 wide:
/// no effect named, *unexplained*, and the check puts the stripe on its side of the track. The
/// same contact without the stripe: the check does not fire and the record is base-adequate.
#[test]
fn a_worn_stripe_is_not_named_and_is_located() {
    let b = bench(5);
    let mut failures = Vec::new();
    for s in [0.3, -0.3] {
        let c = Friction {
            stripe: Some((0.35 * b.x0_m, 0.15 * b.x0_m, s)),
            ..Friction::coulomb_viscous(0.02, 0.002)
        };
        let (rec, _) = generate(&c, &b);
        let e = explain(&rec, &ExplainOptions::default()).unwrap();
        let p = e.position_dependence.clone().expect("a force channel");
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
