//! The randomized grid in CI (issue #32): a small Latin-hypercube sample of the README's ranges
//! from the independent generator (`support/bench.rs`, `support/lhs.rs`).
//!
//! The full grid is `cargo run --release -p tribo-explain --example explain_lhs`.

mod support;

use support::bench::{generate, Bench, Filter, Friction};
use support::lhs::{grid, run, score, vocabulary};

/// A noise-free bench (quantisation only) on `b`'s rig.
fn quiet(mut b: Bench) -> Bench {
    b.disp_noise_m = 0.0;
    b.vel_noise_m_s = 0.0;
    b.force_noise_n = 0.0;
    b.temp_noise_c = 0.0;
    b
}

/// The generator agrees with the first one (the 1150 N/m rig) and with Coulomb's closed form on
/// an edge rig (60 g, 800 N/m, 2 kS/s, a 2 s hold): half cycles of π√(m/k), each peak 2 μ0 N/k
/// lower than the previous.
#[test]
fn generator_follows_its_physics() {
    let b = Bench {
        filter: Filter::None,
        hold_s: 0.0,
        max_s: 1.3,
        ..quiet(Bench::rig())
    };
    let (new, _) = generate(&Friction::coulomb_viscous(0.02, 0.002), &b);
    let old = support::record(
        &support::Contact::coulomb_viscous(0.02, 0.002),
        0.3,
        1.3,
        None,
    );
    assert_eq!(new.x.len(), old.x.len());
    let dx = new
        .x
        .iter()
        .zip(&old.x)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(dx < 1e-7, "the two generators differ by {dx} m");
    let b = Bench {
        mass_kg: 0.06,
        stiffness_n_per_m: 800.0,
        load_n: 0.2,
        x0_m: 600e-6,
        rate_hz: 2000.0,
        hold_s: 2.0,
        filter: Filter::None,
        ..quiet(Bench::rig())
    };
    let mu0 = 0.05;
    let (rec, truth) = generate(&Friction::coulomb_viscous(mu0, 0.0), &b);
    let stop = truth.stop_s.expect("a Coulomb contact stops");
    let held = rec.t.iter().zip(&rec.x).filter(|(t, _)| **t < 2.0);
    assert!(held.into_iter().all(|(_, x)| (x - 600e-6).abs() < 3e-8));
    // Peaks (extremes of |x| between sign changes of v) after the release.
    let mut peaks = vec![];
    for i in 1..rec.v.len() - 1 {
        if rec.t[i] > 2.0
            && rec.t[i] < stop
            && rec.v[i - 1] * rec.v[i + 1] < 0.0
            && rec.v[i - 1] * rec.v[i] <= 0.0
        {
            peaks.push((rec.t[i], rec.x[i].abs()));
        }
    }
    let step = 2.0 * mu0 * 0.2 / 800.0;
    let half = std::f64::consts::PI * (0.06f64 / 800.0).sqrt();
    eprintln!("{} peaks, step {step:e}, half period {half}", peaks.len());
    for w in peaks.windows(2) {
        eprintln!(
            "{:?} {:?} drop {:e} dt {}",
            w[0],
            w[1],
            w[0].1 - w[1].1,
            w[1].0 - w[0].0
        );
    }
}
