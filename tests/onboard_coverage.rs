//! Does the on-board result's ± (the decrement regression's standard error, combined with the
//! averaging estimator's in `best`) mean what it says? Over many seeded noisy repeats of the rig's
//! acquisition chain (vibrometer noise, 16-bit counts) fed through the very pipeline the MCU runs,
//! the true μ0 and μ1 must lie within two standard errors of the estimate in at least 90 % of the
//! runs, and the standard errors must not be padded beyond reason (their mean within a factor 10 of
//! the actual RMS error: they are conservative — the decrement regression's residuals are
//! negatively correlated, each peak entering two rows, which the textbook ± ignores, and the
//! combined `best` carries a term for the two estimators' disagreement).

use tribo::cmd::onboard::analyse;
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
    for &(load, mu0, mu1) in &[(0.3, 0.02, 0.01), (0.1, 0.005, 0.003)] {
        let (mut best, mut dec) = (Vec::new(), Vec::new());
        for _ in 0..25 {
            seed += 1;
            let r = analyse(&record(load, mu0, mu1, seed)).unwrap();
            assert_eq!(r.verdict, Verdict::Ok, "{r:?}");
            best.push((r.best, [mu0, mu1]));
            dec.push((r.decrement, [mu0, mu1]));
        }
        for (which, runs) in [("best", &best), ("decrement", &dec)] {
            let which = format!("N = {load} N, μ = ({mu0}, {mu1}), {which}");
            let t = tally(&which, runs);
            for j in 0..2 {
                let rms = (t.sq[j] / t.n as f64).sqrt();
                let se = t.se[j] / t.n as f64;
                assert!(
                    t.inside[j] as f64 >= 0.9 * t.n as f64,
                    "{which}: mu{j}: only {}/{} within 2 SE (RMS error {rms:.2e}, mean SE {se:.2e})",
                    t.inside[j],
                    t.n
                );
                // Conservative, but not by orders of magnitude (the decrement regression's
                // residuals are negatively correlated, so its textbook ± errs on the safe side).
                assert!(
                    se <= 10.0 * rms,
                    "{which}: mu{j}: mean SE {se:.2e} vs RMS error {rms:.2e}"
                );
            }
        }
    }
}
