//! Reproduction of the thesis's Tables 2, 3 and 4 (ch. 3.5): responses simulated from the listed
#![allow(clippy::needless_range_loop)]
//! true constants (Y0 = 10, y'(0) = 0) are identified by the constant, viscous, Coulomb–viscous and
//! quadratic laws by Levenberg–Marquardt on the Mark & Crandall envelope.

use tribo_physics::envelope::Shape;
use tribo_physics::identify::{fit_dimensionless, FitOptions, LawSpec};
use tribo_physics::integrate::{grid, simulate, Method};
use tribo_physics::{FrictionLaw, Model};

struct Case {
    truth: [f64; 3],
    shape: Shape,
}

/// (μ0, μ1, μ2) of Tables 2–4 and the envelope shape the thesis states for each.
const CASES: [Case; 10] = [
    // Table 2
    Case {
        truth: [0.2, 0.0, 0.0],
        shape: Shape::Straight,
    },
    Case {
        truth: [0.0, 0.1, 0.0],
        shape: Shape::Convex,
    },
    Case {
        truth: [0.08, 0.04, 0.0],
        shape: Shape::Convex,
    },
    Case {
        truth: [0.4, -0.04, 0.0],
        shape: Shape::Concave,
    },
    // Table 3
    Case {
        truth: [0.1, 0.04, 0.005],
        shape: Shape::Convex,
    },
    Case {
        truth: [0.904, -0.125, 0.004],
        shape: Shape::Concave,
    },
    Case {
        truth: [0.6, -0.02, -0.003],
        shape: Shape::Concave,
    },
    Case {
        truth: [0.4, -0.05, 0.0012],
        shape: Shape::Concave,
    },
    // Table 4 (mixed envelopes)
    Case {
        truth: [0.6, -0.25, 0.03],
        shape: Shape::Mixed,
    },
    Case {
        truth: [0.12, 0.03, -0.004],
        shape: Shape::Mixed,
    },
];

/// Simulated record of one case: τ up to 120 (until the stop for all stopping cases), dτ = 0.02.
fn record(mu: [f64; 3]) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let law = FrictionLaw::quadratic(mu[0], mu[1], mu[2]);
    let taus = grid(6001, 0.02);
    let tr = simulate(&Model::new(law), 10.0, 0.0, &taus, Method::default()).unwrap();
    (tr.tau, tr.y, tr.ydot)
}

#[test]
fn quadratic_law_recovers_every_true_constant_within_1e_4() {
    let opts = FitOptions::default();
    for case in &CASES {
        let (t, y, v) = record(case.truth);
        let r = fit_dimensionless(&t, &y, &v, LawSpec::Quadratic, &opts).unwrap();
        for j in 0..3 {
            assert!(
                (r.mu[j] - case.truth[j]).abs() < 1e-4,
                "truth {:?}: fitted {:?} (gap {:e})",
                case.truth,
                r.mu,
                r.gap
            );
        }
        assert!(r.gap < 1e-5, "truth {:?}: gap {:e}", case.truth, r.gap);
        assert_eq!(
            r.shape, case.shape,
            "truth {:?}: fitted {:?}",
            case.truth, r.mu
        );
    }
}

#[test]
fn coulomb_viscous_law_recovers_table2_and_fails_on_mixed_envelopes() {
    let opts = FitOptions::default();
    for case in &CASES {
        let (t, y, v) = record(case.truth);
        let cv = fit_dimensionless(&t, &y, &v, LawSpec::CoulombViscous, &opts).unwrap();
        if case.truth[2] == 0.0 {
            assert!(
                (cv.mu[0] - case.truth[0]).abs() < 1e-4,
                "{:?} -> {:?}",
                case.truth,
                cv.mu
            );
            assert!(
                (cv.mu[1] - case.truth[1]).abs() < 1e-4,
                "{:?} -> {:?}",
                case.truth,
                cv.mu
            );
        }
        if case.shape == Shape::Mixed {
            // "the Coulomb-viscous friction law cannot be used": its best envelope stays far off.
            assert!(cv.gap > 5e-3, "{:?}: cv gap {:e}", case.truth, cv.gap);
            assert_ne!(cv.shape, Shape::Mixed);
        }
    }
}

#[test]
fn single_constant_laws_fit_only_their_own_case() {
    let opts = FitOptions::default();
    // Coulomb response: the constant law is exact, the viscous law is not (Table 2, row 1).
    let (t, y, v) = record([0.2, 0.0, 0.0]);
    let c = fit_dimensionless(&t, &y, &v, LawSpec::Coulomb, &opts).unwrap();
    assert!((c.mu[0] - 0.2).abs() < 1e-6, "{:?}", c.mu);
    let vi = fit_dimensionless(&t, &y, &v, LawSpec::Viscous, &opts).unwrap();
    assert!(
        vi.gap > 100.0 * c.gap.max(1e-9),
        "viscous gap {:e} vs coulomb {:e}",
        vi.gap,
        c.gap
    );
    // Viscous response: the viscous law is exact (row 2).
    let (t, y, v) = record([0.0, 0.1, 0.0]);
    let vi = fit_dimensionless(&t, &y, &v, LawSpec::Viscous, &opts).unwrap();
    assert!((vi.mu[1] - 0.1).abs() < 1e-6, "{:?}", vi.mu);
    assert_eq!(vi.mu[0], 0.0);
}
