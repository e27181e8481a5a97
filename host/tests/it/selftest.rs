//! `tribo selftest` against a virtual rig in a process of its own (`tribo rig --virtual`), as a
//! technician runs it: every measured row passes on a sound rig (exit 0), and a broken converter
//! input (`--fault`) fails its row, named, with a non-zero exit.

use crate::support::{command, RigProcess};
use std::process::Output;

/// A `tribo rig --virtual --speed 2` process with `extra` flags, killed when dropped.
fn rig(extra: &[&str]) -> RigProcess {
    RigProcess::start_with(2.0, extra)
}

fn selftest(r: &RigProcess, extra: &[&str]) -> Output {
    command(&["selftest", "--port", &r.addr, "--seconds", "1"])
        .args(extra)
        .output()
        .expect("tribo selftest runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn a_sound_virtual_rig_passes_every_measured_row() {
    let r = rig(&[]);
    let o = selftest(&r, &["--json"]);
    let (out, err) = (text(&o.stdout), text(&o.stderr));
    assert!(o.status.success(), "{out}\n{err}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
    assert_eq!(v["passed"], true, "{v:#}");
    assert_eq!(v["failed"].as_array().unwrap().len(), 0);
    let rows = v["rows"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["row"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "sample-rate",
            "hse-vs-lsi",
            "input-displacement",
            "input-velocity",
            "input-force",
            "input-ecr",
            "flash",
            "flash-flags",
            "thermocouple",
            "output-heater",
            "output-magnet",
            "output-ecr-source",
            "output-ecr-range",
            "output-lamps",
            "link-throughput",
            "reset-record",
            "watchdog"
        ]
    );
    let row = |n: &str| rows.iter().find(|r| r["row"] == n).unwrap();
    // Only the controller's flags need the chip; everything else was measured and passed.
    for r in rows {
        let want = if r["row"] == "flash-flags" {
            "hardware-only"
        } else {
            "pass"
        };
        assert_eq!(r["verdict"], want, "{r:#}");
    }
    let rate = &row("sample-rate")["figures"];
    assert!(rate["ppm"].as_f64().unwrap().abs() < 200.0, "{rate}");
    assert!(rate["samples"].as_u64().unwrap() > 9_000, "{rate}");
    // The simulated LSI (31.84 kHz) through a timer on a sound HSE: 25 MHz × 8 / 31 840 Hz =
    // 6281.4 ticks per interval.
    let clock = &row("hse-vs-lsi")["figures"];
    let (n, sum) = (
        clock["intervals"].as_u64().unwrap(),
        clock["ticks_sum"].as_u64().unwrap(),
    );
    assert!(n >= 32 && clock["overcaptures"] == 0, "{clock}");
    let lsi = 25e6 * 8.0 / (sum as f64 / n as f64);
    assert!((lsi - 31_840.0).abs() < 1.0, "{lsi} Hz: {clock}");
    let flash = &row("flash")["figures"];
    assert_eq!(flash["mismatches"], 0);
    // The simulated flash erases a sector in the STM32H743's typical 1.1 s (device time).
    assert!(flash["erase_us"].as_u64().unwrap() >= 1_100_000, "{flash}");
    assert_eq!(row("link-throughput")["figures"]["missing"], 0);
    let tc = &row("thermocouple");
    assert!(
        tc["summary"]
            .as_str()
            .unwrap()
            .contains("open-circuit detection on"),
        "{tc:#}"
    );
    assert_eq!(
        tc["figures"]["registers"][0], 0x91,
        "CR0 as configured: {tc:#}"
    );
    // Every output read back at every step, each row saying what the board cannot sense.
    for o in [
        "output-heater",
        "output-magnet",
        "output-ecr-source",
        "output-ecr-range",
        "output-lamps",
    ] {
        let f = &row(o)["figures"];
        assert_eq!(
            (f["sensed"].as_bool(), f["steps"].as_u64()),
            (Some(true), Some(5)),
            "{o}"
        );
        assert!(
            row(o)["summary"].as_str().unwrap().contains("not sensed: "),
            "{o}"
        );
    }
    // Each input at rest within its window (the identity judged).
    for i in [
        "input-displacement",
        "input-velocity",
        "input-force",
        "input-ecr",
    ] {
        assert_eq!(row(i)["figures"]["identity"], true, "{:#}", row(i));
    }
    assert_eq!(row("reset-record")["figures"]["cause"], "Panic");
    assert_eq!(row("watchdog")["figures"]["cause"], "Watchdog");
    assert!(
        row("watchdog")["figures"]["message"]
            .as_str()
            .unwrap()
            .contains("thermocouple"),
        "{v:#}"
    );
    // The table, as a technician reads it, from the same rig after its two resets.
    let o = selftest(&r, &["--no-reset"]);
    let out = text(&o.stdout);
    assert!(o.status.success(), "{out}\n{}", text(&o.stderr));
    assert!(out.contains("self-test of the rig on tcp://"), "{out}");
    assert!(out.contains("\nsample-rate        pass  "), "{out}");
    assert!(
        out.contains("\nflash-flags        --    hardware only"),
        "{out}"
    );
    assert!(
        !out.contains("reset-record"),
        "--no-reset leaves it out: {out}"
    );
}

#[test]
fn a_stuck_input_fails_its_row_by_name() {
    let r = rig(&["--fault", "stuck:v=40000"]);
    let o = selftest(&r, &["--no-reset"]);
    let (out, err) = (text(&o.stdout), text(&o.stderr));
    assert_eq!(o.status.code(), Some(1), "{out}\n{err}");
    assert!(
        out.contains("input-velocity     FAIL  PC0") && out.contains("stuck at code 40000"),
        "{out}"
    );
    assert_eq!(out.matches("FAIL").count(), 1, "only that row fails: {out}");
    assert!(
        err.contains("self-test failed: input-velocity"),
        "the error names the row: {err}"
    );
}

#[test]
fn a_dead_front_end_fails_as_a_rail_in_the_json_too() {
    let r = rig(&["--fault", "dead:ecr", "--fault", "stuck:x"]);
    let o = selftest(&r, &["--no-reset", "--json"]);
    let out = text(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
    assert_eq!(v["passed"], false);
    assert_eq!(
        v["failed"],
        serde_json::json!(["input-displacement", "input-ecr"]),
        "{v:#}"
    );
    let ecr = v["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["row"] == "input-ecr")
        .unwrap();
    assert_eq!(ecr["verdict"], "fail");
    assert!(
        ecr["summary"].as_str().unwrap().contains("at a rail"),
        "{ecr}"
    );
    assert_eq!(ecr["figures"]["max"], 0);
}

#[test]
fn a_fault_flag_that_names_no_channel_is_refused_with_the_forms_it_takes() {
    let o = command(&[])
        .args([
            "rig",
            "--virtual",
            "--listen",
            "127.0.0.1:0",
            "--fault",
            "stuck:z",
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = text(&o.stderr);
    assert!(
        err.contains("no channel \"z\"") && err.contains("stuck:CH=CODE"),
        "{err}"
    );
}

/// `tribo selftest` against a rig started with `--tc-fault FAULT`, no resets: (exit ok, the
/// thermocouple row, stdout, stderr).
fn thermocouple_with(fault: &str) -> (bool, serde_json::Value, String, String) {
    let r = rig(&["--tc-fault", fault]);
    let o = selftest(&r, &["--no-reset", "--json"]);
    let (out, err) = (text(&o.stdout), text(&o.stderr));
    let v: serde_json::Value = serde_json::from_str(out.trim()).expect("one JSON object");
    let row = v["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["row"] == "thermocouple")
        .cloned()
        .unwrap_or_else(|| panic!("no thermocouple row: {v:#}"));
    // Only the thermocouple row fails.
    let failed: Vec<&str> = v["failed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    assert_eq!(failed, ["thermocouple"], "{v:#}");
    (o.status.success(), row, out, err)
}

#[test]
fn an_open_thermocouple_fails_its_row_and_the_exit_status() {
    let (ok, row, out, err) = thermocouple_with("open");
    assert!(!ok, "exit 1: {out}\n{err}");
    assert_eq!(row["verdict"], "fail");
    assert!(
        row["summary"]
            .as_str()
            .unwrap()
            .contains("open thermocouple"),
        "{row:#}"
    );
    assert!(
        err.contains("thermocouple"),
        "named on standard error: {err}"
    );
}

#[test]
fn a_thermocouple_converter_that_lost_its_configuration_or_reads_a_hot_cold_junction_fails() {
    let (ok, row, ..) = thermocouple_with("reset");
    assert!(!ok);
    let s = row["summary"].as_str().unwrap();
    assert!(
        s.contains("configuration does not read back") && s.contains("CR0 0x00"),
        "{row:#}"
    );
    // 50 °C is the top of the plausible range: 55 °C fails it, named.
    let (ok, row, ..) = thermocouple_with("cj=55");
    assert!(!ok);
    assert!(
        row["summary"]
            .as_str()
            .unwrap()
            .contains("cold junction 55.0 °C"),
        "{row:#}"
    );
    let (ok, row, ..) = thermocouple_with("ones");
    assert!(!ok);
    assert!(row["summary"].as_str().unwrap().contains("0xFF"), "{row:#}");
}

/// `tribo selftest --no-reset --json` against a rig started with `flags`: (exit code, the JSON,
/// the failed rows).
fn judged(flags: &[&str], extra: &[&str]) -> (Option<i32>, serde_json::Value, Vec<String>) {
    let r = rig(flags);
    let mut args = vec!["--no-reset", "--json"];
    args.extend_from_slice(extra);
    let o = selftest(&r, &args);
    let out = text(&o.stdout);
    let v: serde_json::Value = serde_json::from_str(out.trim())
        .unwrap_or_else(|e| panic!("{e}: {out}\n{}", text(&o.stderr)));
    let failed = v["failed"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().to_string())
        .collect();
    (o.status.code(), v, failed)
}

fn row_of<'a>(v: &'a serde_json::Value, name: &str) -> &'a serde_json::Value {
    v["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["row"] == name)
        .unwrap_or_else(|| panic!("no row {name}: {v:#}"))
}

#[test]
fn a_stuck_output_fails_its_own_row_only_and_the_exit_status() {
    for (fault, row, read) in [
        ("heater", "output-heater", "read 0x1"),
        ("magnet", "output-magnet", "read 0x1"),
        ("ecr-source", "output-ecr-source", "read 0x000"),
        ("ecr-range", "output-ecr-range", "first drove 0x2, read 0x0"),
        ("lamps", "output-lamps", "first drove 0x4, read 0x0"),
    ] {
        let (code, v, failed) = judged(&["--stuck-output", fault], &[]);
        assert_eq!(code, Some(1), "{fault}: {v:#}");
        assert_eq!(failed, [row], "{fault}: only its row fails: {v:#}");
        let s = row_of(&v, row)["summary"].as_str().unwrap();
        assert!(
            s.contains(read) && s.contains("not sensed: "),
            "{fault}: {s}"
        );
    }
}

#[test]
fn swapped_inputs_and_a_grounded_input_with_a_small_offset_fail_the_inputs_rows() {
    // Displacement and force swapped: the force reads the held position (+0.33 N), the
    // displacement reads zero (a rest position): the force row fails.
    let (code, v, failed) = judged(&["--swap-channels", "x,f"], &[]);
    assert_eq!(code, Some(1), "{v:#}");
    assert_eq!(failed, ["input-force"], "{v:#}");
    assert!(
        row_of(&v, "input-force")["summary"]
            .as_str()
            .unwrap()
            .contains("not the force's signature at rest"),
        "{v:#}"
    );
    // Velocity and ECR swapped: the velocity reads the ECR's 0.1 V (-0.24 m/s) and fails; the
    // ECR pin reads mid-scale (1.65 V), a plausible ECR output: a swap fails one row at least.
    let (code, v, failed) = judged(&["--swap-channels", "v,ecr"], &[]);
    assert_eq!(code, Some(1));
    assert_eq!(failed, ["input-velocity"], "{v:#}");
    // A grounded force input, 300 counts off the rail and moving: the converter's own checks
    // pass it, its signature does not.
    let (code, v, failed) = judged(&["--fault", "ground:f"], &[]);
    assert_eq!(code, Some(1));
    assert_eq!(failed, ["input-force"], "{v:#}");
    let f = &row_of(&v, "input-force")["figures"];
    assert!(f["min"] != f["max"] && f["at_rail"] == 0, "{f}");
    // On a bare board (--open-inputs) only the converting is judged: the grounded input passes,
    // and the row says its identity was not judged.
    let (code, v, failed) = judged(&["--fault", "ground:f"], &["--open-inputs"]);
    assert_eq!(code, Some(0), "{v:#}");
    assert!(failed.is_empty());
    assert!(row_of(&v, "input-force")["summary"]
        .as_str()
        .unwrap()
        .contains("identity not judged"));
}

/// The LSI's frequency the hse-vs-lsi row's figures give, Hz.
fn lsi_hz(v: &serde_json::Value) -> f64 {
    let f = &row_of(v, "hse-vs-lsi")["figures"];
    let mean = f["ticks_sum"].as_f64().unwrap() / f["intervals"].as_f64().unwrap();
    f["timer_hz"].as_f64().unwrap() * f["periods_per_capture"].as_f64().unwrap() / mean
}

#[test]
fn an_hse_off_by_more_than_the_lsi_spread_fails_the_hse_row_only_and_the_exit_status() {
    // 10 % fast: the LSI (31.84 kHz) reads 28.95 kHz through the timer, below DS12110's
    // 29.76 kHz; 6 % slow: 33.87 kHz, above its 33.6 kHz. Every other row runs from the same
    // HSE and cannot see it.
    for (ppm, lsi) in [("100000", 31_840.0 / 1.10), ("-60000", 31_840.0 / 0.94)] {
        let (code, v, failed) = judged(&[&format!("--hse-error={ppm}")], &[]);
        assert_eq!(code, Some(1), "{ppm}: {v:#}");
        assert_eq!(failed, ["hse-vs-lsi"], "{ppm}: only its row fails: {v:#}");
        assert!((lsi_hz(&v) - lsi).abs() < 1.0, "{ppm}: {} Hz", lsi_hz(&v));
        let s = row_of(&v, "hse-vs-lsi")["summary"].as_str().unwrap();
        assert!(
            s.contains("outside DS12110's 29.76–33.60 kHz"),
            "{ppm}: {s}"
        );
    }
    // 3 % fast is inside the LSI's spread: the check cannot tell it (the LSI reads 30.91 kHz),
    // and the row says how far the HSE may be off.
    let (code, v, failed) = judged(&["--hse-error", "30000"], &[]);
    assert_eq!(code, Some(0), "{v:#}");
    assert!(failed.is_empty());
    assert!((lsi_hz(&v) - 31_840.0 / 1.03).abs() < 1.0, "{}", lsi_hz(&v));
    let s = row_of(&v, "hse-vs-lsi")["summary"].as_str().unwrap();
    assert!(s.contains("the HSE is within"), "{s}");
}

#[test]
fn a_velocity_force_swap_passes_the_self_test_at_rest_and_the_first_run_flags_it() {
    // At rest both read their zero: the self-test cannot see this swap (the README says so) ...
    let (code, v, failed) = judged(&["--swap-channels", "v,f"], &[]);
    assert_eq!(code, Some(0), "{v:#}");
    assert!(failed.is_empty(), "{v:#}");
    // ... the first run does: its velocity is not the displacement's derivative. A sound rig's
    // run says it is.
    let dir = tempfile::tempdir().unwrap();
    for (flags, want) in [
        (&["--swap-channels", "v,f"][..], "CHANNELS SWAPPED?"),
        (
            &[][..],
            "velocity is the displacement's derivative (gain 1.0",
        ),
    ] {
        let r = RigProcess::start_with(f64::INFINITY, flags);
        let store = dir.path().join(format!("runs{}", flags.len()));
        let o = command(&[
            "run", "--quiet", "--port", &r.addr, "--load", "0.3", "--store",
        ])
        .arg(&store)
        .output()
        .expect("tribo run runs");
        let out = text(&o.stdout);
        let line = out
            .lines()
            .find(|l| l.starts_with("channels"))
            .unwrap_or_else(|| panic!("{flags:?}: no channels line: {out}{}", text(&o.stderr)));
        assert!(line.contains(want), "{flags:?}: {line}");
        // `tribo fit --json` on the stored run says the same, fitted or not.
        let run_dir = std::fs::read_dir(&store)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.is_dir() && p.join("meta.toml").exists())
            .expect("the run's folder");
        let o = command(&["fit", "--json"]).arg(&run_dir).output().unwrap();
        let v: serde_json::Value = serde_json::from_str(text(&o.stdout).trim())
            .unwrap_or_else(|e| panic!("{e}: {}{}", text(&o.stdout), text(&o.stderr)));
        assert_eq!(
            v["channels"]["consistent"],
            flags.is_empty(),
            "{flags:?}: {v:#}"
        );
    }
}
