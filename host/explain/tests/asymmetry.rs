//! Direction asymmetry of μ0 is a named effect when the force channel's zero is known, and never
//! a name for a zero offset: the displacement centre, the force channel's gain and its zero are
//! nuisances fitted with every model and printed with their ±. Records from the independent
//! generator of `support`.

mod support;

use support::{record, Contact};
use tribo_explain::{explain, Conclusion, ExplainOptions, Explanation, FORCE_ZERO_OFFSET};
use tribo_physics::record::Record;
use tribo_physics::sensor::SensorModel;

const MU0: f64 = 0.02;
const LOAD: f64 = 0.3;

fn cv() -> Contact {
    Contact::coulomb_viscous(MU0, 0.002)
}

/// The rig's chain at `noise` × the simulator's default noise on every channel.
fn chain(noise: f64, seed: u64) -> SensorModel {
    SensorModel {
        disp_noise_m: 2e-8 * noise,
        vel_noise_m_s: 2e-5 * noise,
        force_noise_n: 2e-4 * noise,
        seed,
        ..SensorModel::default()
    }
}

/// μ0 forward `MU0 (1 + a/2)`, backward `MU0 (1 − a/2)`: (forward − backward) / mean = `a`.
fn asymmetric(a: f64) -> Contact {
    Contact {
        mu0: MU0 * (1.0 + a / 2.0),
        mu0_backward: Some(MU0 * (1.0 - a / 2.0)),
        ..cv()
    }
}

fn named(e: &Explanation) -> String {
    if e.missing_effects.is_empty() {
        e.conclusion.name().to_string()
    } else {
        e.missing_effects.join("+")
    }
}

/// The record with its force channel's zero stated (`# force_zero_n`).
fn zero_stated(mut rec: Record, z: f64) -> Record {
    rec.force_zero_n = Some(z);
    rec
}

/// The relative asymmetry a named step measured, with its ±.
fn asymmetry(e: &Explanation) -> Option<(f64, f64)> {
    e.steps.iter().find_map(|s| {
        Some((
            *s.params.get("asymmetry_relative")?,
            *s.params_se.get("asymmetry_relative")?,
        ))
    })
}

/// With the force channel's zero stated, a direction asymmetry of 5–40 % of μ0 (either direction
/// higher) is named and measured within 3σ, from ×1 to ×30 the default noise on every channel,
/// at the strength the noise allows (measured on this record: 5 % named at ×1; 10 % named for one
/// noise seed and missed for another at ×10; 40 % named and 20 % missed at ×30). Below its limit it
/// is missed, never misnamed.
#[test]
fn asymmetry_is_named_and_measured_when_the_force_zero_is_stated() {
    let mut failures = Vec::new();
    for (i, (a, noise, must)) in [
        (0.05, 1.0, true),
        (-0.05, 1.0, true),
        (0.4, 1.0, true),
        (0.1, 10.0, false),
        (0.2, 10.0, true),
        (-0.4, 10.0, true),
        (0.4, 30.0, true),
        (-0.4, 30.0, true),
        (0.2, 30.0, false),
    ]
    .into_iter()
    .enumerate()
    {
        let rec = zero_stated(
            record(
                &asymmetric(a),
                LOAD,
                1.3,
                Some(&chain(noise, 40 + i as u64)),
            ),
            0.0,
        );
        let e = explain(&rec, &ExplainOptions::default()).unwrap();
        let got = named(&e);
        let v = asymmetry(&e);
        eprintln!("{a:+} at ×{noise}: {got} {v:?}");
        let ok = match v {
            Some((v, se)) => got == "direction-asymmetry" && (v - a).abs() <= 3.0 * se,
            None => !must && got == "base-adequate",
        };
        if !ok {
            failures.push(format!("{a:+} at ×{noise}: {got} {v:?}\n{}", e.to_text()));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A zero offset is never named a direction asymmetry: the displacement zero 50 µm off (the force
/// zero stated) and the force channel's zero and gain off (0.6 mN, +3 %: stated zero) leave no
/// name, their nuisances found within 3σ; with the force zero not stated a force offset — or an
/// asymmetry — is "ambiguous": the record cannot tell them apart, and says so. At ×1 and ×30.
#[test]
fn a_zero_offset_is_never_named_asymmetry() {
    let mut failures = Vec::new();
    let mut check = |what: String, ok: bool, e: &Explanation| {
        eprintln!("{what}: {} ({})", named(e), if ok { "ok" } else { "WRONG" });
        if !ok {
            failures.push(format!("{what}\n{}", e.to_text()));
        }
    };
    for (k, noise) in [1.0, 30.0].into_iter().enumerate() {
        let seed = 60 + 10 * k as u64;
        // The vibrometer's zero 50 µm off.
        let mut rec = record(&cv(), LOAD, 1.3, Some(&chain(noise, seed)));
        rec.x.iter_mut().for_each(|x| *x += 50e-6);
        let e = explain(&zero_stated(rec, 0.0), &ExplainOptions::default()).unwrap();
        let c = e.measurement_chain.clone().unwrap();
        let centre_ok =
            (c.displacement_center_m - 50e-6).abs() <= 3.0 * c.displacement_center_m_se + 2e-8;
        check(
            format!(
                "×{noise} displacement zero 50 µm: centre {:.3e} ± {:.1e}",
                c.displacement_center_m, c.displacement_center_m_se
            ),
            e.conclusion == Conclusion::BaseAdequate && centre_ok,
            &e,
        );
        // The force channel reads 1.03 × the force + 0.6 mN.
        let mut rec = record(&cv(), LOAD, 1.3, Some(&chain(noise, seed + 1)));
        if let Some(f) = rec.ft.as_mut() {
            f.iter_mut().for_each(|f| *f = 1.03 * *f + 6e-4);
        }
        let e = explain(&zero_stated(rec.clone(), 6e-4), &ExplainOptions::default()).unwrap();
        let c = e.measurement_chain.clone().unwrap();
        let (g, g_se) = (c.force_gain.unwrap(), c.force_gain_se.unwrap());
        check(
            format!("×{noise} force gain 1.03, zero stated: gain {g:.4} ± {g_se:.4}"),
            e.conclusion == Conclusion::BaseAdequate
                && c.force_gain_source.as_deref() == Some("fitted")
                && (g - 1.03).abs() <= 3.0 * g_se,
            &e,
        );
        // The same, its zero not stated.
        let e = explain(&rec, &ExplainOptions::default()).unwrap();
        let c = e.measurement_chain.clone().unwrap();
        let (z, z_se) = (c.force_zero_n.unwrap(), c.force_zero_n_se.unwrap());
        check(
            format!("×{noise} force zero 0.6 mN not stated: zero {z:.3e} ± {z_se:.1e}"),
            e.conclusion == Conclusion::Ambiguous
                && e.missing_effects.is_empty()
                && e.ambiguous.iter().any(|a| a == FORCE_ZERO_OFFSET)
                && c.force_zero_source.as_deref() == Some("fitted")
                && (z - 6e-4).abs() <= 3.0 * z_se
                && e.answer().contains("force_zero_n"),
            &e,
        );
    }
    // An asymmetry with the zero not stated is the same offset: ambiguous, never base-adequate.
    let rec = record(&asymmetric(0.2), LOAD, 1.3, Some(&chain(1.0, 90)));
    let e = explain(&rec, &ExplainOptions::default()).unwrap();
    let c = e.measurement_chain.clone().unwrap();
    let as_asym = c.force_zero_as_asymmetry.unwrap();
    check(
        format!("20 % asymmetry, zero not stated: as an asymmetry {as_asym:.3}"),
        e.conclusion == Conclusion::Ambiguous
            && e.missing_effects.is_empty()
            && c.force_zero_significant
            && (as_asym - 0.2).abs() < 0.02,
        &e,
    );
    let j: serde_json::Value = serde_json::from_str(&e.to_json().unwrap()).unwrap();
    assert_eq!(j["measurement_chain"]["force_zero_source"], "fitted");
    assert!(j["measurement_chain"]["force_zero_n_se"].as_f64().unwrap() > 0.0);
    assert!(
        j["measurement_chain"]["displacement_center_m_se"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert!(j["measurement_chain"]["force_gain_se"].as_f64().unwrap() > 0.0);
    assert_eq!(j["conclusion"], "ambiguous");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
