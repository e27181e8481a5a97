//! Windowed fits (thesis ch. 3.7, Tables 6–7) and the LuGre fit.
//!
//! Fitting on successive amplitude windows tells whether a law holds over amplitudes: the right law
//! gives the same constants in every window, a law that misses a term gives constants that drift
//! with the window's amplitude, as the averaging method (eq. 27–28) predicts.
#![allow(clippy::needless_range_loop)]

use std::f64::consts::PI;
use tribo_physics::identify::{
    fit_dimensionless, fit_windows, windowed_fits, FitOptions, LawSpec, WindowFit, LUGRE_FIXED,
};
use tribo_physics::integrate::{grid, simulate, Method};
use tribo_physics::law::LuGre;
use tribo_physics::sensor::Rng;
use tribo_physics::{FrictionLaw, Model};

fn record(law: FrictionLaw, n: usize, dtau: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let tr = simulate(
        &Model::new(law),
        10.0,
        0.0,
        &grid(n, dtau),
        Method::default(),
    )
    .unwrap();
    (tr.tau, tr.y, tr.ydot)
}

fn mid(w: &WindowFit) -> f64 {
    0.5 * (w.a_start + w.a_end)
}

/// Least-squares slope of `y` on `x`.
fn slope(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx).powi(2)).sum();
    sxy / sxx
}

#[test]
fn coulomb_viscous_constants_are_flat_across_windows_of_a_coulomb_viscous_record() {
    let (mu0, mu1) = (0.05, 0.03);
    let opts = FitOptions::default();
    let (t, y, v) = record(FrictionLaw::coulomb_viscous(mu0, mu1), 6001, 0.02);
    let w = windowed_fits(&t, &y, &v, LawSpec::CoulombViscous, 5, &opts).unwrap();
    assert_eq!(w.len(), 5);
    // The windows tile the motion, from Y0 down to the stop, in equal amplitude drops.
    assert_eq!(w[0].a_start, 10.0);
    for i in 1..w.len() {
        assert_eq!(w[i].tau_start, w[i - 1].tau_end);
        let (d0, d) = (w[0].a_start - w[0].a_end, w[i].a_start - w[i].a_end);
        assert!((d - d0).abs() < 0.05 * d0, "window {i}: drop {d} vs {d0}");
    }
    assert!(w[4].a_end < 0.5, "last window ends at A = {}", w[4].a_end);
    // Noise-free: the same constants in every window, to the fit's precision.
    for x in &w {
        assert!(
            (x.fit.mu[0] - mu0).abs() < 1e-7 && (x.fit.mu[1] - mu1).abs() < 1e-7,
            "window A {}..{}: {:?}",
            x.a_start,
            x.a_end,
            x.fit.mu
        );
    }
    // With sensor noise (σ = 0.01 on y and y', 0.1 % of Y0) a short window pins down the decay
    // rate dA/dτ = −2μ0/π − μ1 A/2 at its amplitude, not μ0 and μ1 separately (they trade off):
    // that rate is flat, i.e. equal to the true one at every window's amplitude.
    let mut rng = Rng::new(7);
    let (mut yn, mut vn) = (y.clone(), v.clone());
    for i in 0..yn.len() {
        yn[i] += 0.01 * rng.normal();
        vn[i] += 0.01 * rng.normal();
    }
    let w = windowed_fits(&t, &yn, &vn, LawSpec::CoulombViscous, 5, &opts).unwrap();
    for x in &w[..4] {
        let a = mid(x);
        let rate = |m0: f64, m1: f64| -2.0 * m0 / PI - m1 * a / 2.0;
        let (got, want) = (rate(x.fit.mu[0], x.fit.mu[1]), rate(mu0, mu1));
        eprintln!(
            "noisy window A {a:.2}: μ {:?}, rate {got:.5} vs {want:.5}",
            x.fit.mu
        );
        assert!(
            (got - want).abs() < 0.03 * want.abs(),
            "A {a}: rate {got} vs {want} ({:?})",
            x.fit.mu
        );
    }
}

/// CV fits on windows of a quadratic record: the equivalent damping of `μ2 y'² sgn(y')` grows
/// with amplitude. Averaging (eq. 27–28) gives `dA/dτ = a0 + a1 A + a2 A²` with `a2 = −4μ2/(3π)`;
/// a Coulomb–viscous law (μ0, μ1 both free) on a narrow window around `Ā` matches the tangent
/// `a2 A² ≈ a2 (2Ā A − Ā²)`, so `μ1' = −2 a1' = μ1 + (16 μ2 / 3π) Ā` and
/// `μ0' = −(π/2) a0' = μ0 − (2/3) μ2 Ā²`. (With μ0 held at its true value the secant
/// `a1_eq = a2 A`, i.e. half that slope, would apply instead.)
fn quadratic_drift(scale: f64, n: usize) -> (f64, f64) {
    let mu = [0.01 * scale, 0.005 * scale, 0.0005 * scale];
    let opts = FitOptions::default();
    let (t, y, v) = record(FrictionLaw::quadratic(mu[0], mu[1], mu[2]), n, 0.02);
    let w = windowed_fits(&t, &y, &v, LawSpec::CoulombViscous, 5, &opts).unwrap();
    assert_eq!(w.len(), 5);
    let a: Vec<f64> = w.iter().map(mid).collect();
    let m1: Vec<f64> = w.iter().map(|x| x.fit.mu[1]).collect();
    // μ1 grows monotonically with the window's amplitude (windows go down in amplitude).
    for i in 1..w.len() {
        assert!(m1[i] < m1[i - 1], "scale {scale}: μ1 not monotonic: {m1:?}");
    }
    // Each window's constants near the tangent prediction.
    for (x, &am) in w.iter().zip(&a) {
        let p1 = mu[1] + 16.0 * mu[2] / (3.0 * PI) * am;
        let p0 = mu[0] - 2.0 / 3.0 * mu[2] * am * am;
        assert!(
            (x.fit.mu[1] - p1).abs() < 0.05 * p1,
            "scale {scale} A {am}: μ1 {} vs {p1}",
            x.fit.mu[1]
        );
        // μ0' drifts by (2/3) μ2 Ā² (up to 0.03 here): within 15 % of that drift.
        assert!(
            (x.fit.mu[0] - p0).abs() < 0.15 * (2.0 / 3.0 * mu[2] * am * am) + 0.02 * mu[0],
            "scale {scale} A {am}: μ0 {} vs {p0}",
            x.fit.mu[0]
        );
    }
    // The right (quadratic) law is flat over the same windows.
    let q = windowed_fits(&t, &y, &v, LawSpec::Quadratic, 5, &opts).unwrap();
    for x in &q {
        for j in 0..3 {
            assert!(
                (x.fit.mu[j] - mu[j]).abs() < 1e-6 * mu[j],
                "quadratic window A {}: {:?} vs {mu:?}",
                x.a_start,
                x.fit.mu
            );
        }
    }
    (slope(&a, &m1), 16.0 * mu[2] / (3.0 * PI))
}

#[test]
fn coulomb_viscous_mu1_drifts_with_amplitude_on_a_quadratic_record_as_averaging_predicts() {
    let (s1, p1) = quadratic_drift(1.0, 10001);
    let (s2, p2) = quadratic_drift(0.5, 20001);
    let (e1, e2) = ((s1 - p1).abs() / p1, (s2 - p2).abs() / p2);
    eprintln!("dμ1/dA: {s1:e} vs {p1:e} ({e1:.3}); halved μ: {s2:e} vs {p2:e} ({e2:.3})");
    // Averaging is first order in μ: the slope is within 15 % at μ2 = 5e-4 and the error shrinks
    // when the friction is halved (it is then within 6 %) — far from the secant's 50 %.
    assert!(e1 < 0.15, "slope {s1} vs {p1}");
    assert!(
        e2 < 0.06 && e2 < 0.7 * e1,
        "slope {s2} vs {p2} (error {e2} vs {e1})"
    );
}

#[test]
fn lugre_fit_recovers_mu_c_mu_s_and_sigma2() {
    let (s0, s1, vs, a) = LUGRE_FIXED;
    let truth = [0.1, 0.15, 0.02];
    let law = FrictionLaw::LuGre(LuGre {
        sigma0: s0,
        sigma1: s1,
        sigma2: truth[2],
        mu_c: truth[0],
        mu_s: truth[1],
        v_s: vs,
        a,
    });
    let (t, y, v) = record(law, 2001, 0.02);
    let r = fit_dimensionless(&t, &y, &v, LawSpec::LuGre, &FitOptions::default()).unwrap();
    eprintln!(
        "LuGre fit: {:?} (truth {truth:?}), gap {:e}",
        r.params, r.gap
    );
    for j in 0..3 {
        assert!(
            (r.params[j] - truth[j]).abs() < 1e-5,
            "{:?} vs {truth:?}",
            r.params
        );
    }
    // `mu` reports the Coulomb–viscous equivalent [μ_c, σ2].
    assert_eq!(r.mu, vec![r.params[0], r.params[2]]);
    assert!(r.gap < 1e-6, "gap {:e}", r.gap);
}

#[test]
fn fit_windows_on_an_si_record_reports_si_coefficients_and_json() {
    use tribo_physics::identify::fit_windows;
    use tribo_physics::sensor::{generate, RecordSpec};
    use tribo_physics::Rig;
    let rig = Rig::REAL;
    let spec = RecordSpec {
        rig,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 1.0,
        rate_hz: 2000.0,
    };
    let (mu0, mu1) = (0.02, 0.01);
    let rec = generate(
        &spec,
        &Model::new(FrictionLaw::coulomb_viscous(mu0, mu1)),
        Method::default(),
        None,
    )
    .unwrap();
    let w = fit_windows(&rec, LawSpec::CoulombViscous, 3, &FitOptions::default()).unwrap();
    assert_eq!(w.len(), 3);
    for x in &w {
        assert!(
            (x.fit.mu[0] - mu0).abs() < 1e-6 && (x.fit.mu[1] - mu1).abs() < 1e-6,
            "{:?}",
            x.fit.mu
        );
        assert_eq!(x.fit.p_si, rig.p_of_mu(&x.fit.mu));
        let j: serde_json::Value = serde_json::from_str(&x.to_json().unwrap()).unwrap();
        // (serde_json reads floats back to within an ulp)
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs();
        assert!(close(j["a_start"].as_f64().unwrap(), x.a_start), "{j}");
        assert!(close(j["a_end"].as_f64().unwrap(), x.a_end), "{j}");
        assert_eq!(j["fit"]["law"], "coulomb-viscous", "{j}");
        let mu: Vec<f64> = serde_json::from_value(j["fit"]["mu"].clone()).unwrap();
        assert_eq!(mu.len(), x.fit.mu.len(), "{j}");
        assert!(mu.iter().zip(&x.fit.mu).all(|(&a, &b)| close(a, b)), "{j}");
    }
    assert!(w[0].a_start > w[1].a_start && w[1].a_start > w[2].a_start);
    assert!(fit_windows(&rec, LawSpec::CoulombViscous, 0, &FitOptions::default()).is_err());
}

/// On noisy records of an exact Coulomb–viscous law (the real acquisition chain, seeds 2–6),
/// every window's constants hold the truth within their ±: at most one constant in ten outside
/// 2σ and none outside 4σ. (Windows that started from their first sample as measured gave μ1 ten
/// times more precise than it was: 0.00458 ± 4e-5 for a truth of 0.0051.)
#[test]
fn window_constants_of_an_exact_law_hold_the_truth_within_their_standard_errors() {
    use tribo_physics::integrate::Method;
    use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
    use tribo_physics::{Model, Rig};
    let truth = [0.02, 0.0051];
    let (mut inside, mut count) = (0, 0);
    for seed in 2..=6 {
        let spec = RecordSpec {
            rig: Rig::new(0.04, 1150.0, 0.3).unwrap(),
            x0_m: 667e-6,
            v0_m_s: 0.0,
            duration_s: 2.0,
            rate_hz: 10_000.0,
        };
        let sensor = SensorModel {
            seed,
            ..SensorModel::default()
        };
        let rec = generate(
            &spec,
            &Model::new(FrictionLaw::coulomb_viscous(truth[0], truth[1])),
            Method::dopri(1e-10),
            Some(&sensor),
        )
        .unwrap();
        let w = fit_windows(&rec, LawSpec::CoulombViscous, 4, &FitOptions::default()).unwrap();
        assert_eq!(w.len(), 4);
        for x in &w {
            for (j, t) in truth.iter().enumerate() {
                let z = (x.fit.mu[j] - t) / x.fit.mu_se[j];
                assert!(
                    z.abs() < 4.0,
                    "seed {seed}: window at A = {}: mu{j} z = {z}: {:?} ± {:?}",
                    x.a_start,
                    x.fit.mu,
                    x.fit.mu_se
                );
                inside += usize::from(z.abs() <= 2.0);
                count += 1;
            }
        }
    }
    assert!(
        inside as f64 >= 0.9 * count as f64,
        "{inside}/{count} within 2σ"
    );
}
