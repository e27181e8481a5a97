//! `tribo fit` never calls a record whose μ0 drifts adequate: the library's fit reads the force
//! channel's trend of μ0 over the motion ([`tribo_physics::identify::mu0_trend`]) and its verdict
//! says the drift. The running-in record of `drift.rs` (μ0 0.01 growing or falling by 12 % over a
//! 2 s run, 0.3 N, from the independent generator of `support`) at ×1, ×3 and ×10 the simulator's
//! default noise, and clean records over several seeds (no false alarm).

mod support;

use support::{record, Contact};
use tribo_physics::identify::{fit, FitOptions, FitVerdict, LawSpec, DRIFT_Z};
use tribo_physics::sensor::SensorModel;

const MU0: f64 = 0.01;

fn chain(noise: f64, seed: u64) -> SensorModel {
    SensorModel {
        disp_noise_m: 2e-8 * noise,
        vel_noise_m_s: 2e-5 * noise,
        force_noise_n: 2e-4 * noise,
        seed,
        ..SensorModel::default()
    }
}

#[test]
fn a_drifting_mu0_is_never_adequate_and_its_change_is_measured() {
    let rate = 0.12 * MU0 / 2.0;
    let mut failures = Vec::new();
    for noise in [1.0, 3.0, 10.0] {
        for sign in [1.0, -1.0] {
            let c = Contact {
                running_in_per_s: sign * rate,
                ..Contact::coulomb_viscous(MU0, 0.001)
            };
            let seed = 700 + noise as u64 + (sign > 0.0) as u64;
            let rec = record(&c, 0.3, 2.0, Some(&chain(noise, seed)));
            let r = fit(&rec, LawSpec::CoulombViscous, &FitOptions::default()).unwrap();
            let t = r
                .mu0_trend
                .clone()
                .expect("a force channel and a Coulomb level");
            // The truth: μ0 changes by rate × the motion's duration, relative to its mean level.
            let truth = sign * rate * t.span_s / MU0;
            eprintln!(
                "×{noise} sign {sign}: verdict {} ({}); truth {:+.1} %",
                r.verdict.name(),
                t.text(),
                100.0 * truth
            );
            // ×1 and ×3: called drifting, its change within 3σ. ×10: the record's drift is
            // within the estimator's noise (±4–5 % for 12 %): whatever the verdict, a drift is
            // never called in the wrong direction.
            let measured = (t.relative_change - truth).abs() <= 3.0 * t.relative_change_se;
            let ok = if noise < 10.0 {
                r.verdict == FitVerdict::Drifting && measured
            } else {
                !t.significant || t.relative_change.signum() == sign
            };
            if !ok {
                failures.push(format!(
                    "×{noise} {sign}: {} {}",
                    r.verdict.name(),
                    t.text()
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_steady_mu0_gives_no_false_drift() {
    let mut worst: f64 = 0.0;
    let mut failures = Vec::new();
    for noise in [1.0, 10.0, 30.0] {
        for seed in 0..4u64 {
            let rec = record(
                &Contact::coulomb_viscous(MU0, 0.001),
                0.3,
                2.0,
                Some(&chain(noise, 800 + 10 * seed + noise as u64)),
            );
            let r = fit(&rec, LawSpec::CoulombViscous, &FitOptions::default()).unwrap();
            let t = r.mu0_trend.clone().unwrap();
            worst = worst.max(t.z);
            eprintln!("×{noise} seed {seed}: {} ({})", r.verdict.name(), t.text());
            if r.verdict == FitVerdict::Drifting || t.significant {
                failures.push(format!("×{noise} seed {seed}: {}", t.text()));
            }
        }
    }
    eprintln!("largest |z| on steady records: {worst:.2} (threshold {DRIFT_Z})");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A steady μ0 behind what a force channel adds — its low-pass, a sensor lag of 1 or 3 ms, a
/// frictional lag of 2 ms — gives no drift either (before the lags were profiled, a 3 ms sensor
/// lag read as a 4 % drift at 20σ), and a noiseless record none (its trend is numerical: 0.0 %
/// at several σ, below [`DRIFT_MIN`](tribo_physics::identify::DRIFT_MIN)). (Not yet right: a
/// 1 ms sensor lag *with* a 2 ms frictional lag reads as a +16 % drift.)
#[test]
fn the_force_channel_lags_are_not_a_drift() {
    let mut failures = Vec::new();
    for (i, (name, lag, memory)) in [
        ("sensor lag 1 ms", 1e-3, 0.0),
        ("sensor lag 3 ms", 3e-3, 0.0),
        ("frictional lag 2 ms", 0.0, 2e-3),
    ]
    .into_iter()
    .enumerate()
    {
        let c = Contact {
            memory_s: memory,
            ..Contact::coulomb_viscous(MU0, 0.001)
        };
        let ch = SensorModel {
            force_lag_s: lag,
            ..chain(1.0, 900 + i as u64)
        };
        let rec = record(&c, 0.3, 2.0, Some(&ch));
        let r = fit(&rec, LawSpec::CoulombViscous, &FitOptions::default()).unwrap();
        let t = r.mu0_trend.clone().unwrap();
        eprintln!("{name}: {} ({})", r.verdict.name(), t.text());
        if t.significant || r.verdict == FitVerdict::Drifting {
            failures.push(format!("{name}: {}", t.text()));
        }
    }
    let ideal = record(&Contact::coulomb_viscous(MU0, 0.001), 0.3, 2.0, None);
    let r = fit(&ideal, LawSpec::CoulombViscous, &FitOptions::default()).unwrap();
    let t = r.mu0_trend.clone().unwrap();
    eprintln!("noiseless: {} ({})", r.verdict.name(), t.text());
    if t.significant {
        failures.push(format!("noiseless: {}", t.text()));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
