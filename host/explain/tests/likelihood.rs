//! The fits, the evidence and the excess-misfit rule are one likelihood (issue #32): every channel
//! weighted by its own noise variance with its residuals' correlation (`n_eff / (n s²)`, held in
//! a comparison), over every force sample of the compared motion. Before, the fits minimised each
//! channel's RMS misfit over its floor while the evidence was the likelihood, and the force
//! channel was compared at one sample in `n / 3000`: a linear running-in that the force channel's
//! own μ0 trend shows at 6σ (grid #213) was fitted from the envelope, got evidence −39.4 and was
//! *ambiguous* with quadratic velocity and Stribeck. The record is a grid point of `explain_lhs
//! --records 520 --seed 1`, from the independent generator (`support/bench.rs`: its own equations
//! and integrator).

mod support;

use support::lhs::{assert_within_3_sigma, explained};
use tribo_explain::Conclusion;

/// Grid #213: linear running-in, μ0 rising +2.55e-4/s (7 % of μ0 over the 2.2 s of motion), a
/// 31.6 Hz rig at 0.14 N, 14.7 kS/s, no force filter, held 3.4 s, noise ×4.2. Running-in is
/// named, alone, and its rate is within 3σ of the truth with a ± that is a measurement's.
#[test]
fn a_running_in_the_force_channel_shows_is_named_with_its_rate() {
    let (c, e) = explained(213);
    let truth = c.truth("dmu0_dt_per_s");
    assert_eq!(
        e.missing_effects,
        vec!["running-in".to_string()],
        "conclusion {:?}, ambiguous {:?}",
        e.conclusion,
        e.ambiguous
    );
    assert_eq!(e.conclusion, Conclusion::Explained);
    let step = &e.steps[0];
    let (r, se) = (
        step.params["dmu0_dt_per_s"],
        step.params_se["dmu0_dt_per_s"],
    );
    println!(
        "dμ0/dt = {r:.4e} ± {se:.1e} /s (truth {truth:.4e}), evidence {:.1}",
        step.evidence.value
    );
    assert_within_3_sigma("dμ0/dt", r, se, truth);
    assert!(se < 0.5 * truth.abs(), "± {se:.1e} against {truth:.4e}");
    // The excess-misfit share is in the evidence's units: an effect with positive evidence
    // removes a positive share (before, the per-channel RMS rule could call a likelihood gain a
    // loss of −36 %).
    assert!(step.evidence.excess_removed > 0.0);
}
