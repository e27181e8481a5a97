//! The first mechanism of issue 32, as a new user meets it: records whose force channel has no
//! filter at all (and whose header therefore states none), with a frictional lag of 2–3 ms or a
//! sensor delay of 1–2 ms, at ×10 and ×30 the simulator's default noise; and the rig's 300 Hz
//! filter with its header line lost. Prints what `tribo explain` names and measures.
//!
//! `cargo run --release -p tribo-explain --example unstated_filter`

#[path = "../tests/support/mod.rs"]
mod support;

use support::{record, Contact};
use tribo_explain::{explain, ExplainOptions};
use tribo_physics::sensor::SensorModel;

/// Name, contact, force low-pass (Hz), sensor delay (s), the constant measured and its truth.
type Case = (&'static str, Contact, Option<f64>, f64, &'static str, f64);

fn main() {
    let cv = Contact::coulomb_viscous(0.02, 0.002);
    let lag = |s: f64| Contact {
        memory_s: s,
        ..cv.clone()
    };
    let cases: Vec<Case> = vec![
        (
            "no filter, frictional lag 2 ms",
            lag(2e-3),
            None,
            0.0,
            "memory_s",
            2e-3,
        ),
        (
            "no filter, frictional lag 3 ms",
            lag(3e-3),
            None,
            0.0,
            "memory_s",
            3e-3,
        ),
        (
            "no filter, sensor delay 1 ms",
            cv.clone(),
            None,
            1e-3,
            "delay_s",
            1e-3,
        ),
        (
            "no filter, sensor delay 2 ms",
            cv.clone(),
            None,
            2e-3,
            "delay_s",
            2e-3,
        ),
        ("no filter, clean", cv.clone(), None, 0.0, "", 0.0),
        (
            "300 Hz unstated, clean",
            cv.clone(),
            Some(300.0),
            0.0,
            "",
            0.0,
        ),
        (
            "300 Hz unstated, frictional lag 2 ms",
            lag(2e-3),
            Some(300.0),
            0.0,
            "memory_s",
            2e-3,
        ),
        (
            "300 Hz unstated, sensor delay 1 ms",
            cv.clone(),
            Some(300.0),
            1e-3,
            "delay_s",
            1e-3,
        ),
    ];
    for noise in [10.0, 30.0] {
        for (i, (name, c, fc, delay, key, truth)) in cases.iter().enumerate() {
            let chain = SensorModel {
                disp_noise_m: 2e-8 * noise,
                vel_noise_m_s: 2e-5 * noise,
                force_noise_n: 2e-4 * noise,
                force_cutoff_hz: *fc,
                force_lag_s: *delay,
                seed: 100 + i as u64 + (noise as u64) * 1000,
                ..SensorModel::default()
            };
            let mut rec = record(c, 0.3, 1.3, Some(&chain));
            rec.force_cutoff_hz = None;
            let t = std::time::Instant::now();
            let e = explain(&rec, &ExplainOptions::default()).expect("explain");
            let named = if e.missing_effects.is_empty() {
                e.conclusion.name().to_string()
            } else {
                e.missing_effects.join("+")
            };
            let measured = e
                .steps
                .iter()
                .find_map(|s| Some((s.params.get(*key)?, s.params_se.get(*key)?)))
                .map_or(String::new(), |(v, se)| {
                    format!(
                        "{key} = {:.3} ± {:.3} ms (truth {:.1} ms)",
                        1e3 * v,
                        1e3 * se,
                        1e3 * truth
                    )
                });
            println!(
                "×{noise:<3} {name:<38} {named:<34} {measured:<48} filter {:?} {} ({:.1} s)",
                e.force_cutoff_hz.map(|f| f.round()),
                e.force_cutoff_source,
                t.elapsed().as_secs_f64()
            );
        }
    }
}
