//! The Levenberg–Marquardt solver on problems with known minima.

use tribo_physics::identify::{levenberg_marquardt, levenberg_marquardt_with, LmOptions};

fn decay_residuals(t: &[f64], y: &[f64], p: &[f64]) -> Vec<f64> {
    t.iter()
        .zip(y)
        .map(|(t, y)| p[0] * (-p[1] * t).exp() - y)
        .collect()
}

#[test]
fn fits_an_exponential_decay_exactly_with_either_difference_step() {
    let t: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
    let y: Vec<f64> = t.iter().map(|t| 2.5 * (-0.7 * t).exp()).collect();
    let fine = levenberg_marquardt(
        |p| Some(decay_residuals(&t, &y, p)),
        &[1.0, 0.2],
        100,
        1e-14,
    )
    .unwrap();
    let coarse = levenberg_marquardt_with(
        |p| Some(decay_residuals(&t, &y, p)),
        &[1.0, 0.2],
        &LmOptions {
            max_iter: 100,
            tol: 1e-14,
            rel_step: 1e-3,
            scales: vec![1.0, 0.1],
        },
    )
    .unwrap();
    for r in [fine, coarse] {
        assert!(
            (r.p[0] - 2.5).abs() < 1e-6 && (r.p[1] - 0.7).abs() < 1e-6,
            "{:?}",
            r.p
        );
        assert!(r.cost < 1e-12, "{r:?}");
        assert!(r.converged);
    }
}

#[test]
fn backward_difference_where_the_forward_point_is_forbidden() {
    // Minimum on the boundary p ≤ 1 of the domain: residuals cannot be evaluated beyond it, so
    // the forward difference at p = 1 fails and the backward one must be used.
    let r = |p: &[f64]| (p[0] <= 1.0).then(|| vec![p[0] - 1.0, 2.0 * (p[0] - 1.0)]);
    let out = levenberg_marquardt_with(
        r,
        &[1.0],
        &LmOptions {
            max_iter: 10,
            tol: 1e-12,
            rel_step: 1e-3,
            scales: vec![1.0],
        },
    )
    .expect("the start is evaluable");
    assert_eq!(out.p, vec![1.0]);
}

#[test]
fn an_unevaluable_start_is_reported_not_a_panic() {
    assert!(levenberg_marquardt(|_| None, &[1.0], 10, 1e-12).is_none());
}
