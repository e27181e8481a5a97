//! Friction laws checked against their own physics: closed forms, steady states, limits,
//! hysteresis, energy balance and the Duffing frequency shift.
#![allow(clippy::needless_range_loop)]

use std::f64::consts::PI;
use tribo_physics::integrate::{grid, simulate, Method, Trajectory};
use tribo_physics::law::{LuGre, ModifiedLuGre};
use tribo_physics::{FrictionLaw, Model};

/// Integrates the law's internal state `dz/dτ` along a prescribed velocity `v(τ)` by RK4 and
/// returns `(τ, x, v, z, f)` samples, `x = ∫ v`.
#[allow(clippy::type_complexity)]
fn drive(
    law: &FrictionLaw,
    v: impl Fn(f64) -> f64,
    x: impl Fn(f64) -> f64,
    t_end: f64,
    h: f64,
) -> Vec<(f64, f64, f64, f64, f64)> {
    let n = (t_end / h).round() as usize;
    let mut z = 0.0;
    let mut out = Vec::with_capacity(n + 1);
    for i in 0..=n {
        let t = i as f64 * h;
        out.push((t, x(t), v(t), z, law.force(v(t), z, 0.0)));
        let k1 = law.dz(v(t), z);
        let k2 = law.dz(v(t + h / 2.0), z + h / 2.0 * k1);
        let k3 = law.dz(v(t + h / 2.0), z + h / 2.0 * k2);
        let k4 = law.dz(v(t + h), z + h * k3);
        z += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    out
}

/// The LuGre contact of these tests: the fixed bristle constants of `LawSpec::LuGre` fits
/// (σ0 = 200, σ1 = 2, v_s = 1, a = 2) with μc = 0.1, μs = 0.15, σ2 = 0.02.
const LUGRE: LuGre = LuGre {
    sigma0: 200.0,
    sigma1: 2.0,
    sigma2: 0.02,
    mu_c: 0.1,
    mu_s: 0.15,
    v_s: 1.0,
    a: 2.0,
};

#[test]
fn dahl_follows_its_stress_strain_closed_form_and_saturates_at_mu_c() {
    let (sigma, mu_c) = (50.0, 0.2);
    for alpha in [1.0, 2.0] {
        let law = FrictionLaw::Dahl { sigma, mu_c, alpha };
        // dF/dx = σ (1 − F/μc)^α from F = 0 (eq. 11): α = 1: F = μc (1 − e^{−σx/μc});
        // α = 2: F = μc (1 − 1/(1 + σx/μc)). Rate independent: any constant speed gives it.
        for speed in [0.1, 3.0] {
            let tr = drive(&law, |_| speed, |t| speed * t, 0.2 / speed, 1e-4 / speed);
            for &(_, x, _, _, f) in tr.iter().step_by(50) {
                let u = sigma * x / mu_c;
                let exact = if alpha == 1.0 {
                    mu_c * (1.0 - (-u).exp())
                } else {
                    mu_c * (1.0 - 1.0 / (1.0 + u))
                };
                assert!(
                    (f - exact).abs() < 1e-9,
                    "α {alpha} speed {speed} x {x}: {f} vs {exact}"
                );
            }
        }
        // Steady state: μc sgn(v), both ways.
        for speed in [0.5, -0.5] {
            let tr = drive(&law, |_| speed, |t| speed * t, 60.0, 1e-3);
            let f = tr.last().unwrap().4;
            assert!((f - mu_c * speed.signum()).abs() < 2e-3, "α {alpha}: {f}");
            assert_eq!(law.steady_force(speed), mu_c * speed.signum());
        }
    }
}

#[test]
fn dahl_hysteresis_loop_area_is_the_closed_form_whatever_the_frequency() {
    // x = X sin(ωτ): on the periodic loop F0 = μc tanh(σX/μc) at the turning points and the
    // dissipated energy per cycle is ∮F dx = 4 μc X − 4 (μc²/σ) tanh(σX/μc) (> 0, < 4 μc X,
    // → 4 μc X for stiff bristles, ≈ (4/3) σ² X³/μc in presliding).
    let (sigma, mu_c) = (50.0, 0.2);
    let law = FrictionLaw::Dahl {
        sigma,
        mu_c,
        alpha: 1.0,
    };
    for amp in [0.001, 0.005, 0.05] {
        let exact = 4.0 * mu_c * amp - 4.0 * mu_c * mu_c / sigma * (sigma * amp / mu_c).tanh();
        assert!(exact > 0.0 && exact < 4.0 * mu_c * amp);
        for om in [0.5, 4.0] {
            let period = 2.0 * PI / om;
            let h = period / 20000.0;
            let tr = drive(
                &law,
                |t| amp * om * (om * t).cos(),
                |t| amp * (om * t).sin(),
                20.0 * period,
                h,
            );
            // Work of the friction over the last cycle (trapezoid on F v).
            let last = &tr[tr.len() - 20001..];
            let area: f64 = last
                .windows(2)
                .map(|w| 0.5 * (w[0].4 * w[0].2 + w[1].4 * w[1].2) * h)
                .sum();
            assert!(
                (area - exact).abs() < 1e-6 * exact.max(1e-6) + 1e-12,
                "X {amp} ω {om}: area {area:e} vs {exact:e}"
            );
        }
    }
}

/// LuGre `g(v)` written out independently of the crate.
fn g_lugre(p: &LuGre, v: f64) -> f64 {
    p.mu_c + (p.mu_s - p.mu_c) * (-(v.abs() / p.v_s).powf(p.a)).exp()
}

/// Force after holding the velocity constant for a long time (z settled).
fn settled_force(law: &FrictionLaw, v: f64, rate: f64) -> f64 {
    // z relaxes at rate σ0|v|/g: integrate over ~50 time constants with 1000 steps.
    let t_end = 50.0 / rate;
    drive(law, |_| v, |t| v * t, t_end, t_end / 2000.0)
        .last()
        .unwrap()
        .4
}

#[test]
fn lugre_steady_state_force_is_the_stribeck_curve_g_plus_viscous() {
    let p = LUGRE;
    let law = FrictionLaw::LuGre(p);
    for v in [-5.0, -1.0, -0.01, 0.01, 0.3, 1.0, 2.0, 5.0] {
        let want = g_lugre(&p, v) * v.signum() + p.sigma2 * v;
        let got = settled_force(&law, v, p.sigma0 * v.abs() / p.mu_s);
        assert!((got - want).abs() < 1e-9, "v {v}: {got} vs {want}");
        assert!(
            (law.steady_force(v) - want).abs() < 1e-12,
            "steady_force({v})"
        );
    }
    // Limits: μs at v → 0+, μc + σ2 v well above v_s.
    assert!((law.steady_force(1e-6) - p.mu_s).abs() < 1e-6);
    assert!((law.steady_force(10.0) - (p.mu_c + p.sigma2 * 10.0)).abs() < 1e-12);
}

#[test]
fn modified_lugre_steady_state_and_lugre_equivalence_at_low_speed() {
    let p = ModifiedLuGre {
        sigma0: 100.0,
        sigma1: 1.0,
        sigma2: 0.01,
        mu_c: 0.08,
        alpha0: 0.1,
        alpha1: 0.05,
        v_s: 0.5,
        l1: 1.0,
        l2: 2.0,
    };
    let law = FrictionLaw::ModifiedLuGre(p);
    let g = |v: f64| p.alpha0 + p.alpha1 * (-(v / p.v_s).powi(2)).exp();
    let s = |v: f64| {
        let a = v.abs();
        if a <= p.l1 {
            1.0
        } else if a >= p.l2 {
            0.0
        } else {
            let u = (a - p.l1) / (p.l2 - p.l1);
            1.0 - u * u * (3.0 - 2.0 * u)
        }
    };
    // Steady state (eq. 20–23): z → g sgn/σ0 where s > 0, so f = (s g + μc (1 − s)) sgn + σ2 v;
    // above l2 the bristles freeze and f = μc sgn + σ2 v (Coulomb–viscous, eq. 19).
    for v in [0.05, 0.5, 1.0, 1.3, 1.7, 2.0, 3.0, -0.5, -1.5, -3.0] {
        let sv = s(v);
        let want = (sv * g(v) + p.mu_c * (1.0 - sv)) * v.signum() + p.sigma2 * v;
        let rate = (p.sigma0 * v.abs() / p.alpha0 * sv).max(1.0);
        let got = settled_force(&law, v, rate);
        assert!((got - want).abs() < 1e-8, "v {v}: {got} vs {want}");
        assert!(
            (law.steady_force(v) - want).abs() < 1e-12,
            "steady_force({v})"
        );
    }
    // With the cut-offs out of reach (s ≡ 1) it is LuGre with μc = α0, μs = α0 + α1, a = 2: the
    // two oscillators move identically.
    let wide = ModifiedLuGre {
        l1: 1e6,
        l2: 2e6,
        ..p
    };
    let lg = LuGre {
        sigma0: p.sigma0,
        sigma1: p.sigma1,
        sigma2: p.sigma2,
        mu_c: p.alpha0,
        mu_s: p.alpha0 + p.alpha1,
        v_s: p.v_s,
        a: 2.0,
    };
    let taus = grid(1501, 0.02);
    let a = simulate(
        &Model::new(FrictionLaw::ModifiedLuGre(wide)),
        5.0,
        0.0,
        &taus,
        Method::default(),
    )
    .unwrap();
    let b = simulate(
        &Model::new(FrictionLaw::LuGre(lg)),
        5.0,
        0.0,
        &taus,
        Method::default(),
    )
    .unwrap();
    for i in 0..taus.len() {
        assert!((a.y[i] - b.y[i]).abs() < 1e-7, "τ {}", taus[i]);
    }
    // And it damps: the amplitude after 30 rad is well below the start.
    let end = a.y[1500].hypot(a.ydot[1500]);
    assert!(end < 4.0, "A(30) = {end}");
}

#[test]
fn hess_soom_limits_and_coulomb_viscous_special_case() {
    let (mu_b, c1, c2) = (0.15, 4.0, 0.1);
    let law = FrictionLaw::HessSoom { mu_b, c1, c2 };
    // Boundary friction at v → 0+, half of it at v = 1/√c1, hydrodynamic slope c2 at high speed.
    assert!((law.force(1e-9, 0.0, 0.0) - mu_b).abs() < 1e-9);
    assert!((law.force(-1e-9, 0.0, 0.0) + mu_b).abs() < 1e-9);
    assert_eq!(law.static_level(), Some(mu_b));
    let vh = 1.0 / c1.sqrt();
    assert!((law.force(vh, 0.0, 0.0) - (mu_b / 2.0 + c2 * vh)).abs() < 1e-12);
    let (f1, f2) = (law.force(1e3, 0.0, 0.0), law.force(2e3, 0.0, 0.0));
    assert!(((f2 - f1) / 1e3 - c2).abs() < 1e-9);
    assert!((f1 - c2 * 1e3).abs() < mu_b / (c1 * 1e6) * 1.0001);
    // The mixed regime makes friction fall with speed first (a Stribeck dip) when c2 is small.
    assert!(law.force(0.5, 0.0, 0.0) < mu_b);
    // c1 = 0: exactly Coulomb–viscous (μb, c2), same trajectory and stop.
    let taus = grid(6001, 0.02);
    let hs = simulate(
        &Model::new(FrictionLaw::HessSoom { mu_b, c1: 0.0, c2 }),
        10.0,
        0.0,
        &taus,
        Method::default(),
    )
    .unwrap();
    let cv = simulate(
        &Model::new(FrictionLaw::coulomb_viscous(mu_b, c2)),
        10.0,
        0.0,
        &taus,
        Method::default(),
    )
    .unwrap();
    assert_eq!(hs.y, cv.y);
    assert_eq!(hs.stop_tau, cv.stop_tau);
    // With c1 > 0 the pin still sticks by the boundary level: rest within |y| ≤ μb, and the
    // last reversal before it was outside the band.
    let tr = simulate(&Model::new(law), 10.0, 0.0, &taus, Method::default()).unwrap();
    assert!(tr.stop_tau.is_some());
    let rest = *tr.y.last().unwrap();
    assert!(rest.abs() <= mu_b, "rest {rest}");
    let n = tr.reversals.len();
    assert!(tr.reversals[n - 2].1.abs() > mu_b);
}

#[test]
fn stribeck_limits_exponential_and_thesis_eq9() {
    let (mu_c, mu_s, v_s, mu_v) = (0.1, 0.15, 0.5, 0.01);
    let ex = FrictionLaw::Stribeck {
        mu_c,
        mu_s,
        v_s,
        delta: 2.0,
        mu_v,
        mu2: 0.0,
    };
    assert!((ex.force(1e-9, 0.0, 0.0) - mu_s).abs() < 1e-10);
    assert_eq!(ex.static_level(), Some(mu_s));
    assert!((ex.force(20.0, 0.0, 0.0) - (mu_c + mu_v * 20.0)).abs() < 1e-12);
    assert!((ex.force(-20.0, 0.0, 0.0) + (mu_c + mu_v * 20.0)).abs() < 1e-12);
    // At v = v_s the Stribeck excess has decayed by 1/e.
    assert!(
        (ex.force(v_s, 0.0, 0.0) - (mu_c + (mu_s - mu_c) / 1f64.exp() + mu_v * v_s)).abs() < 1e-12
    );
    // The quadratic term adds μ2 y'² in the direction of sliding, on either side.
    let mu2 = -2e-4;
    let q = FrictionLaw::Stribeck {
        mu_c,
        mu_s,
        v_s,
        delta: 2.0,
        mu_v,
        mu2,
    };
    for v in [-20.0, -0.3, 0.3, 20.0] {
        let want = ex.force(v, 0.0, 0.0) + mu2 * v * f64::abs(v);
        assert!((q.force(v, 0.0, 0.0) - want).abs() < 1e-12, "{v}");
    }

    // Eq. 7–9: μ_EHL = K v^n, μ_BL = h v^p, blend weight 1/(1 + (v/B)^M).
    let (k, n, h, b, m) = (0.01, 0.6, 0.12, 0.8, 3.0);
    let eq9 = |n_ehl: f64, p_bl: f64, b: f64, m: f64| FrictionLaw::StribeckPower {
        k_ehl: k,
        n_ehl,
        h_bl: h,
        p_bl,
        b,
        m,
    };
    let law = eq9(n, 0.0, b, m);
    law.validate().unwrap();
    // Static limit: boundary friction h; the contact sticks there.
    assert!((law.force(1e-12, 0.0, 0.0) - h).abs() < 1e-6);
    assert_eq!(law.static_level(), Some(h));
    assert!(law.is_discontinuous());
    // At v = B: the mean of the two regimes.
    let at_b = law.force(b, 0.0, 0.0);
    assert!((at_b - 0.5 * (k * b.powf(n) + h)).abs() < 1e-12, "{at_b}");
    // High speed: the EHL power law (relative excess |h/(K v^n) − 1| / (1 + (v/B)^M) → 0).
    for v in [50.0, 500.0] {
        let ehl = k * f64::powf(v, n);
        let rel = law.force(v, 0.0, 0.0) / ehl - 1.0;
        let bound = (h / ehl - 1.0).abs() * (b / v).powf(m);
        assert!(
            rel.abs() <= bound * 1.0001 && rel.abs() < 1e-3,
            "v {v}: {rel}"
        );
    }
    assert_eq!(law.force(-2.0, 0.0, 0.0), -law.force(2.0, 0.0, 0.0));
    // Constant EHL level (n = 0): below B friction is the boundary level (not h + 2K, as the
    // printed "+" would give), above B the EHL level.
    let flat = FrictionLaw::StribeckPower {
        k_ehl: 0.02,
        n_ehl: 0.0,
        h_bl: 0.1,
        p_bl: 0.0,
        b: 1.0,
        m: 4.0,
    };
    assert!((flat.force(1e-3, 0.0, 0.0) - 0.1).abs() < 1e-9);
    assert!((flat.force(1e3, 0.0, 0.0) - 0.02).abs() < 1e-9);
    // Boundary power law p > 0: no static friction, continuous at 0.
    let soft = eq9(n, 0.5, b, m);
    assert_eq!(soft.static_level(), Some(0.0));
    assert!(!soft.is_discontinuous());
    assert!(soft.force(1e-8, 0.0, 0.0).abs() < 1e-4);
    // Bad constants are rejected.
    for bad in [
        eq9(n, 0.0, 0.0, m),
        eq9(-1.0, 0.0, b, m),
        eq9(n, -0.5, b, m),
        eq9(n, 0.0, b, f64::NAN),
    ] {
        assert!(bad.validate().is_err());
    }
}

/// `ΔE − W` over a record: `E(0) − E(τ)` against the work of friction and apparatus damping,
/// `∫ (f + μa y') y' dτ` (Simpson on an even number of intervals). Returns the largest
/// |residual| / E(0) seen at the checkpoints. (Simpson's rule is only second order across the
/// kink of the power `μ0 |y'|` at each velocity reversal, so the quadrature, not the
/// integrator, sets the floor: ~1e-7 of E(0) at dτ = 0.002.)
fn energy_residual(model: &Model, tr: &Trajectory, dtau: f64) -> f64 {
    let p: Vec<f64> = (0..tr.tau.len())
        .map(|i| (tr.f[i] + model.apparatus_mu1 * tr.ydot[i]) * tr.ydot[i])
        .collect();
    let e0 = model.energy(tr.y[0], tr.ydot[0]);
    let mut work = 0.0;
    let mut worst: f64 = 0.0;
    let mut i = 0;
    while i + 2 < p.len() {
        work += dtau / 3.0 * (p[i] + 4.0 * p[i + 1] + p[i + 2]);
        i += 2;
        let de = e0 - model.energy(tr.y[i], tr.ydot[i]);
        worst = worst.max((de - work).abs() / e0);
    }
    // Friction dissipates: the energy went down by a good fraction.
    let e_end = model.energy(*tr.y.last().unwrap(), *tr.ydot.last().unwrap());
    assert!(e_end < 0.9 * e0, "{}: barely damped", model.law.name());
    worst
}

#[test]
fn energy_lost_equals_friction_work_for_every_law() {
    let lugre = LUGRE;
    let cases: Vec<(Model, Method, f64)> = vec![
        (
            Model::new(FrictionLaw::coulomb_viscous(0.1, 0.03)),
            Method::default(),
            5e-7,
        ),
        (
            Model::new(FrictionLaw::coulomb_viscous(0.1, 0.03)),
            Method::Rk4 { h: 0.01 },
            5e-7,
        ),
        (
            Model::new(FrictionLaw::quadratic(0.05, 0.02, 0.003)),
            Method::Rk4 { h: 0.01 },
            5e-7,
        ),
        (
            Model::new(FrictionLaw::LuGre(lugre)).with_apparatus_damping(0.0011),
            Method::default(),
            5e-7,
        ),
        (
            Model::new(FrictionLaw::Dahl {
                sigma: 50.0,
                mu_c: 0.1,
                alpha: 1.0,
            }),
            Method::default(),
            5e-7,
        ),
        (
            Model::new(FrictionLaw::Stribeck {
                mu_c: 0.1,
                mu_s: 0.15,
                v_s: 0.5,
                delta: 2.0,
                mu_v: 0.01,
                mu2: 0.0,
            })
            .with_cubic(2e-3),
            Method::Rk4 { h: 0.01 },
            5e-7,
        ),
        (
            Model::new(FrictionLaw::HessSoom {
                mu_b: 0.15,
                c1: 4.0,
                c2: 0.02,
            }),
            Method::default(),
            5e-7,
        ),
        (
            Model::new(FrictionLaw::StribeckPower {
                k_ehl: 0.01,
                n_ehl: 0.6,
                h_bl: 0.12,
                p_bl: 0.0,
                b: 0.8,
                m: 3.0,
            }),
            Method::Rk4 { h: 0.01 },
            5e-7,
        ),
    ];
    let dtau = 0.002;
    let taus = grid(20001, dtau);
    for (model, method, tol) in &cases {
        let tr = simulate(model, 8.0, 0.0, &taus, *method).unwrap();
        let r = energy_residual(model, &tr, dtau);
        eprintln!("{} {method:?}: energy residual {r:e}", model.law.name());
        assert!(r < *tol, "{} {method:?}: residual {r:e}", model.law.name());
    }
}

#[test]
fn stribeck_rk4_stops_where_dormand_prince_does_inside_the_static_band() {
    let model = Model::new(FrictionLaw::Stribeck {
        mu_c: 0.1,
        mu_s: 0.15,
        v_s: 0.5,
        delta: 2.0,
        mu_v: 0.01,
        mu2: 0.0,
    })
    .with_cubic(2e-3);
    let taus = grid(10001, 0.02);
    let a = simulate(&model, 8.0, 0.0, &taus, Method::Rk4 { h: 0.01 }).unwrap();
    let b = simulate(&model, 8.0, 0.0, &taus, Method::default()).unwrap();
    let (sa, sb) = (
        a.stop_tau.expect("RK4 stops"),
        b.stop_tau.expect("DP stops"),
    );
    assert!((sa - sb).abs() < 1e-6, "stop τ {sa} vs {sb}");
    assert_eq!(a.reversals.len(), b.reversals.len());
    for (ra, rb) in a.reversals.iter().zip(&b.reversals) {
        assert!((ra.0 - rb.0).abs() < 1e-6 && (ra.1 - rb.1).abs() < 1e-7);
    }
    // Stick rule (eq. 14) with the cubic spring: rest where |y + κy³| ≤ μs, and the reversal
    // before it was outside the band.
    let rest = *a.y.last().unwrap();
    assert!(model.spring(rest).abs() <= 0.15, "rest {rest}");
    let n = a.reversals.len();
    assert!(model.spring(a.reversals[n - 2].1).abs() > 0.15);
    assert_eq!(a.reversals[n - 1].1, rest);
}

#[test]
fn duffing_frequency_shifts_with_amplitude_as_averaging_predicts() {
    // y'' + y + κy³ = 0: exact period T = 4 ∫_0^{π/2} dθ / √(1 + ε(1 + sin²θ)/2), ε = κA²;
    // averaging (Lindstedt) gives ω = 1 + 3ε/8 − 21ε²/256 + O(ε³).
    let exact_period = |eps: f64| {
        let n = 2000;
        let h = PI / 2.0 / n as f64;
        let f = |t: f64| 1.0 / (1.0 + eps * (1.0 + t.sin().powi(2)) / 2.0).sqrt();
        let mut s = f(0.0) + f(PI / 2.0);
        for i in 1..n {
            s += f(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        4.0 * s * h / 3.0
    };
    for (kappa, amp) in [(1e-3, 10.0), (1e-4, 10.0), (-5e-4, 10.0)] {
        let eps = kappa * amp * amp;
        let model = Model::new(FrictionLaw::viscous(0.0)).with_cubic(kappa);
        let dtau = 0.001;
        let taus = grid(70001, dtau);
        let tr = simulate(&model, amp, 0.0, &taus, Method::Rk4 { h: 0.01 }).unwrap();
        // Upward zero crossings, linearly interpolated (y'' = 0 at y = 0: exact to O(dτ³)).
        let ups: Vec<f64> = (1..taus.len())
            .filter(|&i| tr.y[i - 1] < 0.0 && tr.y[i] >= 0.0)
            .map(|i| taus[i - 1] + dtau * tr.y[i - 1] / (tr.y[i - 1] - tr.y[i]))
            .collect();
        let k = ups.len() - 1;
        assert!(k >= 9);
        let period = (ups[k] - ups[0]) / k as f64;
        let te = exact_period(eps);
        assert!(
            (period - te).abs() < 1e-8 * te,
            "κ {kappa}: period {period} vs exact {te}"
        );
        let om = 2.0 * PI / period;
        let first = 1.0 + 3.0 * eps / 8.0;
        let second = first - 21.0 * eps * eps / 256.0;
        eprintln!("ε {eps}: ω {om} vs 1 + 3ε/8 = {first} (2nd order {second})");
        assert!(
            (om - second).abs() < 0.2 * eps.abs().powi(3) + 1e-10,
            "ε {eps}: ω {om} vs {second}"
        );
        assert!(
            (om - first).abs() < 0.1 * eps * eps,
            "ε {eps}: ω {om} vs {first}"
        );
        // Energy is conserved without friction (RK4 h = 0.01: ~1e-10 drift over 11 cycles).
        let e0 = model.energy(amp, 0.0);
        let e1 = model.energy(*tr.y.last().unwrap(), *tr.ydot.last().unwrap());
        assert!(
            (e1 - e0).abs() < 1e-8 * e0,
            "energy drift {}",
            (e1 - e0) / e0
        );
    }
}

/// Friction with a memory time T (first-order lag): after each velocity reversal the force, which
/// was `−μ0` (opposing the old direction), relaxes as `μ0 (1 − 2 e^{−t/T})` and so crosses zero
/// `T ln 2` after the velocity does; with T → 0 the law is the memoryless one.
#[test]
fn lagged_friction_reverses_t_ln2_after_the_velocity_and_tends_to_its_steady_law() {
    let (mu0, mu1, memory) = (0.02, 0.002, 0.3);
    let lagged = |m: f64| FrictionLaw::Lagged {
        steady: Box::new(FrictionLaw::coulomb_viscous(mu0, mu1)),
        memory: m,
    };
    let taus = grid(40_001, 0.001);
    let tr = simulate(
        &Model::new(lagged(memory)),
        2.5,
        0.0,
        &taus,
        Method::dopri(1e-10),
    )
    .unwrap();
    let crossings = |v: &[f64]| -> Vec<f64> {
        (1..v.len())
            .filter(|&i| v[i - 1] * v[i] < 0.0)
            .map(|i| taus[i - 1] + 0.001 * v[i - 1].abs() / (v[i - 1] - v[i]).abs())
            .collect()
    };
    let (vz, fz) = (crossings(&tr.ydot), crossings(&tr.f));
    assert!(vz.len() >= 10, "{} reversals", vz.len());
    // Pair each velocity reversal (after the first) with the next force reversal.
    let lags: Vec<f64> = vz
        .iter()
        .skip(1)
        .filter_map(|&t| fz.iter().find(|&&f| f > t).map(|f| f - t))
        .collect();
    let mean = lags.iter().sum::<f64>() / lags.len() as f64;
    // The viscous part shifts the zero slightly; within 10 % of T ln 2.
    let want = memory * std::f64::consts::LN_2;
    assert!((mean - want).abs() < 0.1 * want, "lag {mean} vs {want}");
    // A vanishing memory: the envelope of the memoryless law (until 20 % of the amplitude).
    let a = |tr: &Trajectory| -> Vec<f64> {
        tr.y.iter()
            .zip(&tr.ydot)
            .map(|(y, v)| y.hypot(*v))
            .collect()
    };
    let short = simulate(
        &Model::new(lagged(1e-4)),
        2.5,
        0.0,
        &taus,
        Method::dopri(1e-10),
    )
    .unwrap();
    let plain = simulate(
        &Model::new(FrictionLaw::coulomb_viscous(mu0, mu1)),
        2.5,
        0.0,
        &taus,
        Method::dopri(1e-10),
    )
    .unwrap();
    let (as_, ap) = (a(&short), a(&plain));
    let n = ap.iter().position(|&x| x < 0.5).unwrap_or(ap.len());
    let worst = (0..n).map(|i| (as_[i] - ap[i]).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-3, "memory 1e-4 differs by {worst}");
    // With memory the friction does less work near each reversal: the envelope decays slower.
    let al = a(&tr);
    assert!(al[n - 1] > ap[n - 1], "{} vs {}", al[n - 1], ap[n - 1]);
}
