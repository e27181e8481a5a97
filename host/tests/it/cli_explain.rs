//! The `tribo explain --json` command-line contract, on records written by this test.

use crate::support::tribo;
use std::path::{Path, PathBuf};
use tribo_explain::serde_json::{self, Value};
use tribo_physics::integrate::Method;
use tribo_physics::law::FrictionLaw;
use tribo_physics::model::{Model, Rig};
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tribo-cli-explain-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The real rig (N = 0.3 N, x0 = 667 µm, 10 kHz, 16 bits, 300 Hz force low-pass), Coulomb–viscous
/// friction, and a force channel that lags the vibrometer by `lag_s`.
fn write_record(path: &Path, lag_s: f64) {
    write_record_with(path, lag_s, Some(300.0));
}

/// [`write_record`] with the force channel's low-pass `cutoff` (`None`: no filter, and the record
/// states none).
fn write_record_with(path: &Path, lag_s: f64, cutoff: Option<f64>) {
    let spec = RecordSpec {
        rig: Rig::REAL,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 1.3,
        rate_hz: 10_000.0,
    };
    let sensor = SensorModel {
        force_lag_s: lag_s,
        force_cutoff_hz: cutoff,
        seed: 5,
        ..SensorModel::default()
    };
    let model = Model::new(FrictionLaw::coulomb_viscous(0.02, 0.002));
    generate(&spec, &model, Method::dopri(1e-10), Some(&sensor))
        .unwrap()
        .save(path)
        .unwrap();
}

#[test]
fn json_contract_and_report() {
    let d = dir("lag");
    let rec = d.join("rec.csv");
    write_record(&rec, 3e-3);
    let report = d.join("report");
    let out = tribo(&[
        "explain",
        rec.to_str().unwrap(),
        "--json",
        "--report",
        report.to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_str(&stdout).expect("stdout is one JSON object");
    let missing: Vec<&str> = v["missing_effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_str().unwrap())
        .collect();
    assert_eq!(missing, ["sensor-lag"]);
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 1);
    let s = &steps[0];
    assert_eq!(s["effect"], "sensor-lag");
    let (g0, g1) = (
        s["gap_before"].as_f64().unwrap(),
        s["gap_after"].as_f64().unwrap(),
    );
    assert_eq!(v["gap_initial"].as_f64().unwrap(), g0);
    assert_eq!(v["gap_final"].as_f64().unwrap(), g1);
    assert!(g1 <= 0.5 * g0, "gap {g0} -> {g1}");
    let delay = s["params"]["delay_s"].as_f64().unwrap();
    assert!((delay - 3e-3).abs() < 2e-4, "delay {delay}");
    // The stated low-pass, as stated.
    assert_eq!(v["force_lowpass"]["source"], "record");
    assert_eq!(v["force_lowpass"]["cutoff_hz"].as_f64(), Some(300.0));
    assert!(v["force_lowpass"]["cutoff_hz_se"].is_null());
    for f in [
        "index.html",
        "envelope.svg",
        "residual.svg",
        "force.svg",
        "force_velocity.svg",
    ] {
        let p = report.join(f);
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(text.len() > 200, "{f} is nearly empty");
        if f.ends_with(".svg") {
            assert!(
                text.contains("<svg") && text.contains("<polyline"),
                "{f} has no curve"
            );
            assert!(text.contains("index") || f != "index.html");
        }
    }
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    assert!(html.contains("src=\"envelope.svg\"") && html.contains("sensor-lag"));
    let _ = std::fs::remove_dir_all(&d);
}

/// A force channel without a filter, whose record states none: the low-pass is fitted, found
/// absent and printed with its bound, in text and JSON; the 1 ms sensor delay is measured as such,
/// with a ± that the filter's confusion with a delay at its bound does not inflate.
#[test]
fn an_unstated_lowpass_is_fitted_and_printed() {
    let d = dir("nofilter");
    let rec = d.join("rec.csv");
    write_record_with(&rec, 1e-3, None);
    assert!(!std::fs::read_to_string(&rec)
        .unwrap()
        .contains("force_cutoff_hz"));
    let out = tribo(&["explain", rec.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(
        text.contains("force channel low-pass: none found (fitted: the record does not state it"),
        "{text}"
    );
    assert!(text.contains("start_scale = ") && text.contains("apparatus_mu1 = "));
    // The other nuisances of the chain, each with its ±: the displacement centre, the force
    // channel's gain, and its zero (not stated: fitted, and said to be inseparable from a
    // direction asymmetry).
    assert!(text.contains("displacement centre = "), "{text}");
    assert!(text.contains("force channel gain = "), "{text}");
    assert!(
        text.contains("force channel zero = ") && text.contains("cannot be told from it"),
        "{text}"
    );
    let out = tribo(&["explain", rec.to_str().unwrap(), "--json"]);
    let v: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    let c = &v["measurement_chain"];
    assert!(c["displacement_center_m_se"].as_f64().unwrap() > 0.0, "{c}");
    assert!(c["force_gain_se"].as_f64().unwrap() > 0.0, "{c}");
    assert_eq!(c["force_gain_source"], "fitted");
    assert_eq!(c["force_zero_source"], "fitted");
    assert!(c["force_zero_n_se"].as_f64().unwrap() > 0.0, "{c}");
    assert_eq!(c["force_zero_significant"], false);
    assert_eq!(v["force_cutoff_source"], "fitted");
    assert_eq!(v["force_lowpass"]["source"], "fitted");
    // At its bound (below a quarter of a sample): no cut-off, no linear ±, a profile bound.
    assert!(v["force_lowpass"]["cutoff_hz"].is_null());
    assert!(v["force_lowpass"]["time_constant_s_se"].is_null());
    assert!(
        v["force_lowpass"]["cutoff_at_least_hz"].as_f64().unwrap() > 1000.0,
        "{}",
        v["force_lowpass"]
    );
    assert_eq!(v["missing_effects"], serde_json::json!(["sensor-lag"]));
    // The zero stated on the command line: held there, said so, no ± of its own.
    let out = tribo(&[
        "explain",
        rec.to_str().unwrap(),
        "--json",
        "--force-zero-n",
        "0",
    ]);
    let z: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(z["measurement_chain"]["force_zero_source"], "option");
    assert_eq!(z["measurement_chain"]["force_zero_n"], 0.0);
    assert_eq!(z["missing_effects"], serde_json::json!(["sensor-lag"]));
    let delay = v["steps"][0]["params"]["delay_s"].as_f64().unwrap();
    let se = v["steps"][0]["params_se"]["delay_s"].as_f64().unwrap();
    assert!(
        (delay - 1e-3).abs() < (3.0 * se).max(5e-5),
        "delay {delay} ± {se}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn bad_input_is_a_clear_error() {
    let d = dir("bad");
    let rec = d.join("rec.csv");
    write_record(&rec, 0.0);
    // Truncate the file in the middle of a line.
    let text = std::fs::read_to_string(&rec).unwrap();
    std::fs::write(&rec, &text[..text.len() / 2 - 7]).unwrap();
    let out = tribo(&["explain", rec.to_str().unwrap(), "--json"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line") && !err.contains("panicked"), "{err}");
    // Unknown base law and unknown effect.
    for args in [
        ["--base", "bogus"],
        ["--only", "magic"],
        ["--force-zero-n", "nan"],
    ] {
        let out = tribo(&["explain", rec.to_str().unwrap(), args[0], args[1]]);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(args[1]) && !err.contains("panicked"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&d);
}
