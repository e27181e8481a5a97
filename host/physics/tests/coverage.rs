//! Do the fit's standard errors mean what they say? Over many seeded noisy repeats of the real
//! acquisition chain (vibrometer noise, 16-bit quantisation), the true constant must lie within two
//! standard errors of the fitted one in at least 90 % of the fits (a Gaussian estimate: 95 %), and
//! the standard errors must not be padded either: their mean stays within a factor 1.6 of the actual
//! RMS error. Both halves can fail: standard errors ignoring the first sample's noise or the
//! residuals' correlation come out 2–3 times too small here, and padded ones too large.

use tribo_physics::identify::{fit, FitOptions, FitVerdict, LawSpec};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Model, Rig};

struct Case {
    name: &'static str,
    load_n: f64,
    law: FrictionLaw,
    spec: LawSpec,
    truth: Vec<f64>,
    duration_s: f64,
}

/// Per constant: (inside 2σ, count, RMS error, mean SE).
fn repeats(c: &Case, seeds: std::ops::Range<u64>) -> Vec<(usize, usize, f64, f64)> {
    let mut stats = vec![(0usize, 0usize, 0.0f64, 0.0f64); c.truth.len()];
    let n = seeds.end - seeds.start;
    for seed in seeds {
        let spec = RecordSpec {
            rig: Rig::new(0.04, 1150.0, c.load_n).unwrap(),
            x0_m: 667e-6,
            v0_m_s: 0.0,
            duration_s: c.duration_s,
            rate_hz: 10_000.0,
        };
        let sensor = SensorModel {
            seed,
            ..SensorModel::default()
        };
        let rec = generate(
            &spec,
            &Model::new(c.law.clone()),
            Method::dopri(1e-10),
            Some(&sensor),
        )
        .unwrap();
        let r = fit(&rec, c.spec, &FitOptions::default()).unwrap();
        assert_eq!(
            r.verdict,
            FitVerdict::Adequate,
            "{}: seed {seed}: {r:?}",
            c.name
        );
        for (j, &t) in c.truth.iter().enumerate() {
            let (e, se) = (r.mu[j] - t, r.mu_se[j]);
            assert!(se.is_finite() && se > 0.0, "{}: seed {seed}: {r:?}", c.name);
            let s = &mut stats[j];
            s.0 += usize::from(e.abs() <= 2.0 * se);
            s.1 += 1;
            s.2 += e * e / n as f64;
            s.3 += se / n as f64;
        }
    }
    for s in &mut stats {
        s.2 = s.2.sqrt();
    }
    stats
}

fn check(c: &Case, seeds: std::ops::Range<u64>) {
    for (j, (inside, n, rms, se)) in repeats(c, seeds).into_iter().enumerate() {
        eprintln!(
            "{}: mu{j}: {inside}/{n} within 2 SE; RMS error {rms:.2e}, mean SE {se:.2e}",
            c.name
        );
        assert!(
            inside as f64 >= 0.9 * n as f64,
            "{}: mu{j}: only {inside}/{n} within 2 SE (RMS error {rms:.2e}, mean SE {se:.2e})",
            c.name
        );
        assert!(
            se <= 1.6 * rms && rms <= 1.6 * se,
            "{}: mu{j}: mean SE {se:.2e} vs RMS error {rms:.2e}",
            c.name
        );
    }
}

#[test]
fn coulomb_viscous_standard_errors_cover_the_truth() {
    check(
        &Case {
            name: "coulomb-viscous, N = 0.3 N",
            load_n: 0.3,
            law: FrictionLaw::coulomb_viscous(0.02, 0.01),
            spec: LawSpec::CoulombViscous,
            truth: vec![0.02, 0.01],
            duration_s: 1.0,
        },
        1..31,
    );
    check(
        &Case {
            name: "coulomb-viscous, light contact N = 0.1 N",
            load_n: 0.1,
            law: FrictionLaw::coulomb_viscous(0.005, 0.002),
            spec: LawSpec::CoulombViscous,
            truth: vec![0.005, 0.002],
            duration_s: 1.0,
        },
        101..131,
    );
}

#[test]
fn quadratic_standard_errors_cover_the_truth() {
    check(
        &Case {
            name: "quadratic, N = 0.3 N",
            load_n: 0.3,
            law: FrictionLaw::quadratic(0.02, 0.004, 0.003),
            spec: LawSpec::Quadratic,
            truth: vec![0.02, 0.004, 0.003],
            duration_s: 1.0,
        },
        201..231,
    );
}

#[test]
fn verdicts_follow_convergence_and_the_noise_floor() {
    let spec = RecordSpec {
        rig: Rig::REAL,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 1.0,
        rate_hz: 10_000.0,
    };
    let quad = generate(
        &spec,
        &Model::new(FrictionLaw::quadratic(0.02, 0.004, 0.003)),
        Method::dopri(1e-10),
        Some(&SensorModel::default()),
    )
    .unwrap();
    // The right law: adequate, the gap at the noise floor.
    let r = fit(&quad, LawSpec::Quadratic, &FitOptions::default()).unwrap();
    assert_eq!(r.verdict, FitVerdict::Adequate, "{r:?}");
    assert!((0.8..1.2).contains(&r.gap_ratio()), "{r:?}");
    // A law that misses the quadratic term: converged, inadequate, its residuals correlated.
    let r = fit(&quad, LawSpec::CoulombViscous, &FitOptions::default()).unwrap();
    assert!(r.converged);
    assert_eq!(r.verdict, FitVerdict::Inadequate, "{r:?}");
    assert!(
        r.gap_ratio() > 5.0 && r.n_eff < 0.1 * r.points as f64,
        "{r:?}"
    );
    // Stopped by its iteration limit far from the optimum: not converged.
    let opts = FitOptions {
        max_iter: 1,
        start: Some(vec![0.05, 0.0, 0.0]),
        ..FitOptions::default()
    };
    let r = fit(&quad, LawSpec::Quadratic, &opts).unwrap();
    assert!(!r.converged);
    assert_eq!(r.verdict, FitVerdict::NotConverged, "{r:?}");
}
