//! The `tribo explain --json` command-line contract, on records written by this test.

use std::path::{Path, PathBuf};
use std::process::Command;
use tribo_explain::serde_json::{self, Value};
use tribo_physics::integrate::Method;
use tribo_physics::law::FrictionLaw;
use tribo_physics::model::{Model, Rig};
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};

fn tribo(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tribo"))
        .args(args)
        .output()
        .expect("run tribo")
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tribo-cli-explain-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The real rig (N = 0.3 N, x0 = 667 µm, 10 kHz, 16 bits, 300 Hz force low-pass), Coulomb–viscous
/// friction, and a force channel that lags the vibrometer by `lag_s`.
fn write_record(path: &Path, lag_s: f64) {
    let spec = RecordSpec {
        rig: Rig::REAL,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 1.3,
        rate_hz: 10_000.0,
    };
    let sensor = SensorModel {
        force_lag_s: lag_s,
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
    for args in [["--base", "bogus"], ["--only", "magic"]] {
        let out = tribo(&["explain", rec.to_str().unwrap(), args[0], args[1]]);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(args[1]) && !err.contains("panicked"), "{err}");
    }
    let _ = std::fs::remove_dir_all(&d);
}
