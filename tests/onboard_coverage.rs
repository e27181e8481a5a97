//! Does the on-board result's ± mean what it says? Over many seeded noisy repeats of the rig's
//! acquisition chain (vibrometer noise, 16-bit counts) fed through the very pipeline the MCU runs,
//! z = (estimate − truth) / σ of the result shown (`best`: the averaging estimator, its residuals'
//! correlation accounted for) must have a standard deviation near 1 and put the truth within 2σ
//! about 95 % of the time. The decrement estimator's ± stands only in the check between the two
//! estimators and is conservative (its textbook ±): it must cover the truth, and not by orders of
//! magnitude.
//!
//! The bench grid (`cargo run --release -p tribo --example onboard_grid`) checks the same over
//! holds, rates, rigs and noise levels; this is the quick check.

use tribo::onboard::analyse;
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Model, Rig};
use tribo_wire::{Estimate, Verdict};

fn record(load_n: f64, mu0: f64, mu1: f64, seed: u64) -> tribo_physics::Record {
    let spec = RecordSpec {
        rig: Rig::new(0.04, 1150.0, load_n).unwrap(),
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 2.0,
        rate_hz: 10_000.0,
    };
    let sensor = SensorModel {
        seed,
        ..SensorModel::default()
    };
    generate(
        &spec,
        &Model::new(FrictionLaw::coulomb_viscous(mu0, mu1)),
        Method::dopri(1e-9),
        Some(&sensor),
    )
    .unwrap()
}

struct Tally {
    inside: [usize; 2],
    n: usize,
    sq: [f64; 2],
    se: [f64; 2],
}

fn tally(which: &str, runs: &[(Estimate, [f64; 2])]) -> Tally {
    let mut t = Tally {
        inside: [0; 2],
        n: runs.len(),
        sq: [0.0; 2],
        se: [0.0; 2],
    };
    for (e, truth) in runs {
        for (j, (v, se)) in [(e.mu0, e.mu0_se), (e.mu1, e.mu1_se)]
            .into_iter()
            .enumerate()
        {
            let err = v as f64 - truth[j];
            t.inside[j] += usize::from(err.abs() <= 2.0 * se as f64);
            t.sq[j] += err * err;
            t.se[j] += se as f64;
        }
    }
    for j in 0..2 {
        let rms = (t.sq[j] / t.n as f64).sqrt();
        let se = t.se[j] / t.n as f64;
        eprintln!(
            "{which}: mu{j}: {}/{} within 2 SE; RMS error {rms:.2e}, mean SE {se:.2e}",
            t.inside[j], t.n
        );
    }
    t
}

#[test]
fn onboard_standard_errors_cover_the_truth() {
    let mut seed = 1000;
    let (mut best, mut dec) = (Vec::new(), Vec::new());
    for &(load, mu0, mu1) in &[(0.3, 0.02, 0.01), (0.1, 0.005, 0.003)] {
        for _ in 0..25 {
            seed += 1;
            let r = analyse(&record(load, mu0, mu1, seed)).unwrap();
            assert_eq!(r.verdict, Verdict::Ok, "{r:?}");
            best.push((r.best, [mu0, mu1]));
            dec.push((r.decrement, [mu0, mu1]));
        }
    }
    // 50 runs: a coverage of 95 % reads 43–50 of 50 (two binomial σ either side)
    let t = tally("best", &best);
    for j in 0..2 {
        let z: Vec<f64> = best
            .iter()
            .map(|(e, truth)| {
                let (v, se) = if j == 0 {
                    (e.mu0, e.mu0_se)
                } else {
                    (e.mu1, e.mu1_se)
                };
                (v as f64 - truth[j]) / se as f64
            })
            .collect();
        let sdz = (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt();
        assert!(
            t.inside[j] >= 43,
            "best: mu{j}: only {}/{} within 2σ",
            t.inside[j],
            t.n
        );
        assert!(
            (0.7..=1.4).contains(&sdz),
            "best: mu{j}: sd(z) {sdz:.2}: the ± is {} by {:.1}×",
            if sdz > 1.0 { "too small" } else { "too large" },
            if sdz > 1.0 { sdz } else { 1.0 / sdz }
        );
    }
    let t = tally("decrement", &dec);
    for j in 0..2 {
        let rms = (t.sq[j] / t.n as f64).sqrt();
        let se = t.se[j] / t.n as f64;
        assert!(
            t.inside[j] as f64 >= 0.9 * t.n as f64,
            "decrement: mu{j}: only {}/{} within 2 SE (RMS error {rms:.2e}, mean SE {se:.2e})",
            t.inside[j],
            t.n
        );
        assert!(
            se <= 10.0 * rms,
            "decrement: mu{j}: mean SE {se:.2e} vs RMS error {rms:.2e}"
        );
    }
}
