//! The nuisances of the measurement chain are fitted, never guessed: a record that does not state
//! its force channel's low-pass (a channel with no filter at all, or the rig's 300 Hz one with the
//! header line lost) is explained as well as one that states it, and the low-pass is printed with
//! its ±. The records come from the independent generator of `support` (its own equations and
//! integrator), at ten times the simulator's default noise.

mod support;

use support::{record, Contact};
use tribo_explain::{explain, Conclusion, ExplainOptions, Explanation};
use tribo_physics::record::Record;
use tribo_physics::sensor::SensorModel;

const MU0: f64 = 0.02;

fn cv() -> Contact {
    Contact::coulomb_viscous(MU0, 0.002)
}

/// The rig's acquisition chain at ×10 the default noise (x 2e-7 m, v 2e-4 m/s, force 2e-3 N),
/// with the force channel's low-pass `cutoff` and a sensor delay `lag_s`.
fn chain(cutoff: Option<f64>, lag_s: f64, seed: u64) -> SensorModel {
    SensorModel {
        disp_noise_m: 2e-7,
        vel_noise_m_s: 2e-4,
        force_noise_n: 2e-3,
        force_cutoff_hz: cutoff,
        force_lag_s: lag_s,
        seed,
        ..SensorModel::default()
    }
}

/// The record without its `# force_cutoff_hz` line.
fn unstated(mut rec: Record) -> Record {
    rec.force_cutoff_hz = None;
    rec
}

fn named(e: &Explanation) -> String {
    if e.missing_effects.is_empty() {
        e.conclusion.name().to_string()
    } else {
        e.missing_effects.join("+")
    }
}

/// The value and ± of a named effect's constant.
fn param(e: &Explanation, k: &str) -> (f64, f64) {
    let st = e
        .steps
        .iter()
        .find(|s| s.params.contains_key(k))
        .unwrap_or_else(|| panic!("no step has {k}:\n{}", e.to_text()));
    (st.params[k], st.params_se[k])
}

/// Within 3σ or 15 % of the truth (the criterion of "measured").
fn close(v: (f64, f64), truth: f64) -> bool {
    (v.0 - truth).abs() <= (3.0 * v.1).max(0.15 * truth.abs())
}

/// The four records of the first mechanism: a force channel with no filter and a
/// frictional lag of 2–3 ms or a sensor delay of 1–2 ms. Before the low-pass was fitted, explain
/// took 300 Hz for them, then named a cubic stiffness beside the lag or measured the delay at a
/// quarter of itself.
#[test]
fn an_unfiltered_force_channel_is_not_given_a_filter() {
    let mut failures = Vec::new();
    let cases: [(&str, Contact, f64, &str, &str, f64); 4] = [
        (
            "frictional lag 2 ms",
            Contact {
                memory_s: 2e-3,
                ..cv()
            },
            0.0,
            "frictional-lag",
            "memory_s",
            2e-3,
        ),
        (
            "frictional lag 3 ms",
            Contact {
                memory_s: 3e-3,
                ..cv()
            },
            0.0,
            "frictional-lag",
            "memory_s",
            3e-3,
        ),
        (
            "sensor delay 1 ms",
            cv(),
            1e-3,
            "sensor-lag",
            "delay_s",
            1e-3,
        ),
        (
            "sensor delay 2 ms",
            cv(),
            2e-3,
            "sensor-lag",
            "delay_s",
            2e-3,
        ),
    ];
    for (i, (name, c, lag, want, k, truth)) in cases.into_iter().enumerate() {
        let rec = record(&c, 0.3, 1.3, Some(&chain(None, lag, 70 + i as u64)));
        assert_eq!(rec.force_cutoff_hz, None, "the record states no filter");
        let e = explain(&rec, &ExplainOptions::default()).unwrap();
        let got = named(&e);
        let v = (got == want).then(|| param(&e, k));
        eprintln!("{name}: {got} {v:?}");
        if got != want || !close(v.unwrap_or((f64::NAN, 0.0)), truth) {
            failures.push(format!(
                "{name}: {got} {v:?}, not {want} at {truth}\n{}",
                e.to_text()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The fitted low-pass itself: none found on a channel without one (a cut-off above 1 kHz within
/// 2σ), the rig's 300 Hz found within its ± on one whose header lost the line, the stated one
/// printed as stated; in text and JSON. A clean record stays clean whichever way.
#[test]
fn the_force_lowpass_is_fitted_and_printed_with_its_uncertainty() {
    let clean_none = record(&cv(), 0.3, 1.3, Some(&chain(None, 0.0, 81)));
    let e = explain(&clean_none, &ExplainOptions::default()).unwrap();
    assert_eq!(e.conclusion, Conclusion::BaseAdequate, "{}", e.to_text());
    let l = e.force_lowpass.clone().unwrap();
    assert_eq!(l.source, "fitted");
    let at_least = l.cutoff_at_least_hz.unwrap();
    assert!(at_least > 1000.0, "no filter: {l:?}\n{}", e.to_text());
    assert!(e
        .to_text()
        .contains("force channel low-pass: none found (fitted"));

    let stated = record(&cv(), 0.3, 1.3, Some(&chain(Some(300.0), 0.0, 82)));
    assert_eq!(stated.force_cutoff_hz, Some(300.0));
    let e = explain(&stated, &ExplainOptions::default()).unwrap();
    assert_eq!(e.conclusion, Conclusion::BaseAdequate, "{}", e.to_text());
    let l = e.force_lowpass.clone().unwrap();
    assert_eq!((l.source.as_str(), l.cutoff_hz), ("record", Some(300.0)));
    assert!(e
        .to_text()
        .contains("force channel low-pass: 300 Hz (stated by the record)"));

    let lost = unstated(stated);
    let e = explain(&lost, &ExplainOptions::default()).unwrap();
    assert_eq!(e.conclusion, Conclusion::BaseAdequate, "{}", e.to_text());
    let l = e.force_lowpass.clone().unwrap();
    let (fc, se) = (l.cutoff_hz.unwrap(), l.cutoff_hz_se.unwrap());
    assert_eq!(l.source, "fitted");
    assert!(
        se > 0.0 && se < 60.0 && (fc - 300.0).abs() <= 3.0 * se,
        "fitted {fc} ± {se} Hz for 300"
    );
    let j: serde_json::Value = serde_json::from_str(&e.to_json().unwrap()).unwrap();
    assert_eq!(j["force_lowpass"]["source"], "fitted");
    assert!(j["force_lowpass"]["cutoff_hz_se"].as_f64().unwrap() > 0.0);
    assert_eq!(j["force_cutoff_source"], "fitted");
    assert!(
        j["final_model"]["params_se"]["force_lowpass_s"]
            .as_f64()
            .unwrap()
            > 0.0
    );
}

/// The rig's 300 Hz filter unstated, with a frictional lag of 2 ms beside it: the lag is named
/// and measured, the filter found.
#[test]
fn a_lost_filter_line_does_not_hide_a_frictional_lag() {
    let c = Contact {
        memory_s: 2e-3,
        ..cv()
    };
    let rec = unstated(record(&c, 0.3, 1.3, Some(&chain(Some(300.0), 0.0, 90))));
    let e = explain(&rec, &ExplainOptions::default()).unwrap();
    assert_eq!(named(&e), "frictional-lag", "{}", e.to_text());
    let v = param(&e, "memory_s");
    assert!(close(v, 2e-3), "memory {v:?}\n{}", e.to_text());
    let l = e.force_lowpass.unwrap();
    assert!(
        (l.cutoff_hz.unwrap() - 300.0).abs() <= 3.0 * l.cutoff_hz_se.unwrap() + 15.0,
        "{l:?}"
    );
}
