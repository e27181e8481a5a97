//! A Coulomb level drifting in time at constant temperature (running-in) is a named effect with
//! its constant: never "base-adequate". Records from the independent generator of `support`.

mod support;

use support::{record, Contact};
use tribo_explain::{explain, ExplainOptions, Explanation};
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

fn named(e: &Explanation) -> String {
    if e.missing_effects.is_empty() {
        e.conclusion.name().to_string()
    } else {
        e.missing_effects.join("+")
    }
}

/// μ0 growing (or falling) by 12 % over a 2 s run (μ0 0.01 at 0.3 N, the motion lasts 1.8 s),
/// with a steady temperature column or none. At ×1 the default noise running-in is named every
/// time and its rate measured within 3σ or 30 %; at ×3, near its detection limit on this record,
/// it is named in at least 3 of 4 and nothing else is ever named (one that is not named is
/// *unexplained* with the force channel's trend of μ0 said, not *base-adequate*, when that trend
/// shows it); the same contact without the drift gets no name. (At ×10 this record's drift is below the noise: measured evidence ≈ 1
/// against a threshold of 14.5.)
#[test]
fn running_in_is_named_and_measured() {
    let rate = 0.12 * MU0 / 2.0;
    let mut failures = Vec::new();
    let mut k = 0u64;
    let mut named_at_3 = 0;
    for noise in [1.0, 3.0] {
        for sign in [1.0, -1.0] {
            for steady_temp in [true, false] {
                k += 1;
                let c = Contact {
                    running_in_per_s: sign * rate,
                    thermal: steady_temp.then_some((0.0, 0.0, 1.0)),
                    ..Contact::coulomb_viscous(MU0, 0.001)
                };
                let rec = record(&c, 0.3, 2.0, Some(&chain(noise, 300 + k)));
                let e = explain(&rec, &ExplainOptions::default()).unwrap();
                let got = named(&e);
                let v = e.steps.iter().find_map(|s| {
                    Some((
                        s.params.get("dmu0_dt_per_s")?,
                        s.params_se.get("dmu0_dt_per_s")?,
                    ))
                });
                let truth = sign * rate;
                // 3σ or 30 %: with the force channel's gain a fitted nuisance, the ×1 rising record
                // without a temperature column measures +7.64e-4 ± 4.9e-5 for 6.0e-4 (27 %, 3.4σ;
                // +7.18e-4 ± 3.8e-5 with the gain held at 1): the rate's ± under-covers on it.
                let measured =
                    v.is_some_and(|(v, se)| (v - truth).abs() <= (3.0 * se).max(0.3 * rate));
                let ok = if noise == 1.0 {
                    got == "running-in" && measured
                } else if got == "running-in" {
                    named_at_3 += 1;
                    measured
                } else {
                    // Not named: never base-adequate when the force channel's trend shows the
                    // drift (then unexplained, the drift said where the model disagrees).
                    let trend = e.mu0_trend.as_ref().is_some_and(|t| t.significant);
                    if trend {
                        got == "unexplained" && e.disagreement.iter().any(|d| d.contains("a drift"))
                    } else {
                        got == "base-adequate"
                    }
                };
                eprintln!("×{noise} sign {sign} temp {steady_temp}: {got} {v:?} (truth {truth:e})");
                if !ok {
                    failures.push(format!(
                        "×{noise} {sign} {steady_temp}: {got} {v:?} for {truth:e}\n{}",
                        e.to_text()
                    ));
                }
            }
        }
        let clean = record(
            &Contact::coulomb_viscous(MU0, 0.001),
            0.3,
            2.0,
            Some(&chain(noise, 400 + noise as u64)),
        );
        let e = explain(&clean, &ExplainOptions::default()).unwrap();
        eprintln!("×{noise} clean: {}", named(&e));
        if named(&e) != "base-adequate" {
            failures.push(format!("×{noise} clean: {}\n{}", named(&e), e.to_text()));
        }
    }
    assert!(named_at_3 >= 3, "named {named_at_3} of 4 at ×3");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
