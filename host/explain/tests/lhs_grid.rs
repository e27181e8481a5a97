//! The randomized grid in CI (issue #32): a small Latin-hypercube sample of the README's ranges
//! from the independent generator (`support/bench.rs`, `support/lhs.rs`).
//!
//! The full grid is `cargo run --release -p tribo-explain --example explain_lhs`.

mod support;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use support::bench::{generate, Bench, Filter, Friction};
use support::lhs::{grid_with, run, score, vocabulary, Case, Group, Outcome};

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
    assert!(peaks.len() >= 20, "{} peaks", peaks.len());
    for w in peaks.windows(2) {
        // A peak is sampled within half a sample of its instant (≤ 0.1 % of the amplitude at
        // 2 kS/s) and quantised to 3e-8 m: each drop within 5 % of the step, each interval within
        // a sample of the half period.
        let drop = w[0].1 - w[1].1;
        assert!(
            (drop - step).abs() < 0.05 * step,
            "drop {drop:e} for {step:e}"
        );
        let dt = w[1].0 - w[0].0;
        assert!(
            (dt - half).abs() <= 1.0 / 2000.0 + 1e-9,
            "half period {dt} for {half}"
        );
    }
}

/// Runs explain on `cases` on two threads; returns the outcomes in order.
fn run_all(cases: &[&Case]) -> Vec<Outcome> {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<Outcome>>> = Mutex::new(vec![None; cases.len()]);
    std::thread::scope(|s| {
        for _ in 0..2 {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                if i >= cases.len() {
                    break;
                }
                let o = run(cases[i]);
                out.lock().unwrap()[i] = Some(o);
            });
        }
    });
    out.into_inner()
        .unwrap()
        .into_iter()
        .map(|o| o.expect("ran"))
        .collect()
}

/// The CI grid: the full grid's Latin hypercube (`grid_with`) at 240 points, records of at most
/// 6 s; of it, the records the properties are asserted on are run (about twenty).
fn ci_grid() -> Vec<Case> {
    grid_with(240, 3, 6.0)
}

/// Strengths (in `strength_unit`) at and above which the full grid (`explain_lhs --records 520
/// --seed 1`) names an effect alone rightly in ≥ 90 % of its records, for the effects that have
/// such a limit within their range (README, "What `tribo explain` can name").
const LIMITS: &[(&str, f64)] = &[
    ("frictional-lag", 0.5),
    ("sensor-lag", 0.5),
    ("cubic-stiffness", 0.01),
];

/// The properties on the CI grid, where the full grid shows they hold (README, "What `tribo
/// explain` can name"): no name on a clean record, held before the release or not, whatever its
/// force filter (none, 1-pole or 2-pole, stated or not); a load that varies along the track and a
/// worn stripe never named as an effect of the vocabulary, held before the release or not; the
/// lags and the cubic
/// stiffness named alone, rightly, above their limits on records without a 1-pole filter, held or
/// not, with constants within 2σ. What does not hold today (the cubic term behind a 1-pole filter;
/// the other effects' limits) is stated in the README, not asserted.
#[test]
fn randomized_grid_properties() {
    let vocab = vocabulary();
    let cases = ci_grid();
    let clean: Vec<&Case> = cases.iter().filter(|c| c.group == Group::Clean).collect();
    // Load-varying records that start at the release are few in one hypercube: two more are
    // taken from another; and three held ones.
    let more = grid_with(240, 4, 6.0);
    let load_varies =
        |c: &&Case| c.group == Group::Outside && c.present[0].effect == "load-varies-with-position";
    let outside: Vec<&Case> = cases
        .iter()
        .chain(more.iter())
        .filter(load_varies)
        .filter(|c| c.bench.hold_s == 0.0)
        .take(6)
        .chain(
            cases
                .iter()
                .filter(load_varies)
                .filter(|c| c.bench.hold_s > 0.0)
                .take(3),
        )
        // And four worn stripes (one of them, #215, a stripe the force channel reads as
        // running-in: *ambiguous*).
        .chain(
            cases
                .iter()
                .filter(|c| c.group == Group::Outside && c.present[0].effect == "worn-stripe")
                .take(4),
        )
        .collect();
    let strong: Vec<&Case> = cases
        .iter()
        .filter(|c| {
            c.group == Group::Alone
                // Behind a 1-pole filter (fitted with its order) the cubic term above its limit
                // is not yet named rightly: on this grid #80 (1.7 %, 185 Hz, ×30) is
                // *unexplained* and #128 (3.8 %, 566 Hz, ×12) gets a sensor lag beside it.
                && !matches!(c.bench.filter, Filter::OnePole(_))
                && LIMITS
                    .iter()
                    .any(|(e, l)| c.present[0].effect == *e && c.present[0].strength >= *l)
        })
        .collect();
    assert!(
        clean.len() >= 3 && outside.len() >= 3 && strong.len() >= 3,
        "the CI grid has {} clean, {} outside, {} strong records",
        clean.len(),
        outside.len(),
        strong.len()
    );
    let mut all: Vec<&Case> = Vec::new();
    all.extend(&clean);
    all.extend(&outside);
    all.extend(&strong);
    let t0 = std::time::Instant::now();
    let outs = run_all(&all);
    eprintln!(
        "{} records in {:.0} s",
        all.len(),
        t0.elapsed().as_secs_f64()
    );
    let mut failures = Vec::new();
    let (mut cov_ok, mut cov_n) = (0, 0);
    for (c, o) in all.iter().zip(&outs) {
        let s = score(c, o, &vocab);
        let line = format!(
            "{} → {} [{}] ({:.1} s)",
            c.describe(),
            o.named.join("+"),
            o.conclusion,
            o.seconds
        );
        eprintln!("{line}");
        if s.error {
            failures.push(format!("refused: {line}"));
        }
        match c.group {
            Group::Clean if !s.false_names.is_empty() => {
                failures.push(format!("false name on a clean record: {line}"))
            }
            Group::Outside if s.outside_named => {
                failures.push(format!("outside effect named as a vocabulary one: {line}"))
            }
            Group::Alone if !s.right => {
                failures.push(format!("effect above its limit not named rightly: {line}"))
            }
            _ => {}
        }
        for (tc, got) in &o.estimates {
            let matches = c
                .present
                .iter()
                .any(|p| p.effect == tc.effect && p.form_matches);
            if let (true, Some((v, se))) = (matches, got) {
                cov_n += 1;
                cov_ok += usize::from(((v - tc.value) / se).abs() <= 2.0);
            }
        }
    }
    eprintln!("constants within 2σ: {cov_ok}/{cov_n}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(
        cov_n >= 3 && cov_ok as f64 >= COVERAGE * cov_n as f64,
        "constants within 2σ: {cov_ok}/{cov_n}"
    );
}

/// Share of these three effects' constants the test asks to be within 2σ: the full grid has 66 of
/// 108 (61 %: memory time 80 %, sensor delay 55 %, cubic 46 %; README).
const COVERAGE: f64 = 0.5;
