//! Every run is itself: a run is never filed with another run's blocks, and a run number never
//! names two runs of one rig.
//!
//! The four commands of issue 22 against one virtual rig (a process of its own, as fast as it can
//! go): run A at 0.3 N, run B at 0.1 N (the rig's load knob turned), a pull of A (the rig now holds
//! B: refused), then the "victim" run at 0.3 N. Before, turning the knob rebuilt the virtual rig,
//! which numbered its runs from 1 again: B was the rig's "run 1" too, the refused pull of A started
//! B's blocks on their way, and they were filed into the victim ("incomplete: 164 of 156 blocks",
//! a host fit 0.024 ± 0.002 where the rig said 0.0200).

use crate::support;

use crate::support::{RigProcess, TRIBO};
use std::path::Path;
use std::process::Command;

fn tribo(args: &[&str], store: &Path) -> std::process::Output {
    support::command(args)
        .arg("--store")
        .arg(store)
        .output()
        .expect("tribo runs")
}

fn meta(dir: &Path) -> toml::Table {
    toml::from_str(&std::fs::read_to_string(dir.join("meta.toml")).unwrap()).unwrap()
}

#[test]
fn a_refused_pull_between_runs_puts_no_block_of_another_run_into_the_next() {
    let rig = RigProcess::start(f64::INFINITY);
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("runs");
    let run = |load: &str, label: Option<&str>| {
        let mut a = vec!["run", "--quiet", "--port", &rig.addr, "--load", load];
        if let Some(l) = label {
            a.extend(["--label", l]);
        }
        let out = tribo(&a, &store);
        assert!(
            out.status.success(),
            "{a:?}: {}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    run("0.3", Some("A"));
    run("0.1", None);
    let folder = |label: &str| {
        std::fs::read_dir(&store)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.file_name().unwrap().to_string_lossy().ends_with(label))
            .unwrap_or_else(|| panic!("no run labelled {label}"))
    };
    let a = folder("-A");
    let out = Command::new(TRIBO)
        .args(["pull", a.to_str().unwrap(), "--port", &rig.addr])
        .output()
        .unwrap();
    // The rig holds a newer run: nothing of A can be fetched, and nothing needs to be (its folder
    // holds it whole): said, status 0 (the contract: done, the data whole).
    assert_eq!(
        out.status.code(),
        Some(0),
        "the pull of a replaced run that is whole: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("newer run"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = run("0.3", Some("victim"));
    // Stored whole: "complete: N of N blocks", no block more than the rig's run has.
    let whole = text.split("(complete: ").nth(1).and_then(|t| {
        let mut w = t.split_whitespace();
        let (held, _, of) = (w.next()?, w.next()?, w.next()?);
        Some(held == of)
    });
    assert_eq!(whole, Some(true), "{text}");
    let v = folder("-victim");
    // Three runs of one rig, three run numbers, one serial.
    let ids: Vec<i64> = ["-A", "N0.100", "-victim"]
        .iter()
        .map(|l| {
            let m = meta(&folder(l));
            m["device_run_id"].as_integer().unwrap()
        })
        .collect();
    assert_eq!(ids, [1, 2, 3], "run numbers go on when the load knob turns");
    // `tribo table --json`: the two loads, the 0.3 N cell from A and the victim.
    let o = tribo(&["table", "--json"], &store);
    assert!(o.status.success());
    let t: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(t["cols"], serde_json::json!([0.1, 0.3]), "{t}");
    assert_eq!(t["cells"][0][1]["n"], 2, "{t}");
    let serial = |p: &Path| meta(p)["device"]["serial"].as_str().unwrap().to_string();
    assert_eq!(serial(&a), serial(&v));
    // The victim's host fit is the rig's own result, within their σ.
    let fit = Command::new(TRIBO)
        .args(["fit", v.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(fit.status.success());
    let j: serde_json::Value = serde_json::from_slice(&fit.stdout).unwrap();
    assert_eq!(j["verdict"], "adequate", "{j}");
    assert_eq!(j["cross_check"]["agree"], true, "{j}");
}

/// Two virtual rigs started apart are two rigs: their serial numbers differ.
#[test]
fn each_virtual_rig_has_its_own_serial() {
    let (a, b) = (
        RigProcess::start(f64::INFINITY),
        RigProcess::start(f64::INFINITY),
    );
    let (sa, sb) = (a.info().serial, b.info().serial);
    assert_ne!(sa, sb);
    assert_eq!(sa >> 24, 0x74_7269_626f, "{sa:016x}");
    // `tribo status --json`: one object, the same serial.
    let o = Command::new(TRIBO)
        .args(["status", "--json", "--port", &a.addr])
        .output()
        .unwrap();
    assert!(o.status.success());
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["serial"], format!("{sa:016x}"), "{j}");
    assert!(j["status"]["state"].is_string(), "{j}");
}

/// A store that cannot be written (a file in the way) is refused before anything is sent to the
/// rig: the sphere is never released with nobody able to record it.
#[test]
fn an_unwritable_store_is_refused_before_the_release() {
    let mut rig = RigProcess::start(f64::INFINITY);
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("afile"), b"").unwrap();
    let out = tribo(
        &["run", "--quiet", "--port", &rig.addr, "--load", "0.3"],
        &dir.path().join("afile").join("runs"),
    );
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("cannot be written") && err.contains("nothing was sent"),
        "{err}"
    );
    rig.drain(std::time::Duration::from_millis(300));
    let console = rig.console();
    assert!(
        !console.contains("release") && !console.contains("arm"),
        "{console}"
    );
}

/// A run whose frame log is damaged is listed by `tribo runs` as damaged (it used to vanish), and
/// `tribo pull --salvage` with no rig reachable keeps every intact record, says what is missing and
/// exits 3; the run is then listed as incomplete.
#[test]
fn a_damaged_run_is_listed_and_salvaged_without_the_rig() {
    let rig = RigProcess::start(f64::INFINITY);
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("runs");
    let out = tribo(
        &[
            "run", "--quiet", "--port", &rig.addr, "--load", "0.3", "--label", "d",
        ],
        &store,
    );
    assert!(out.status.success());
    drop(rig);
    let run = std::fs::read_dir(&store)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir())
        .unwrap();
    let log = run.join("frames.log");
    let mut bytes = std::fs::read(&log).unwrap();
    for b in &mut bytes[4000..4100] {
        *b ^= 0x5a;
    }
    std::fs::write(&log, bytes).unwrap();
    let list = |store: &Path| {
        let o = Command::new(TRIBO)
            .args(["runs", "--json", "--store"])
            .arg(store)
            .output()
            .unwrap();
        assert!(o.status.success());
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()
    };
    let v = list(&store);
    assert_eq!(v["damaged"].as_array().unwrap().len(), 1, "{v}");
    assert_eq!(v["damaged"][0]["status"], "damaged");
    let o = Command::new(TRIBO)
        .args(["pull", "--salvage", "--port", "tcp://127.0.0.1:1"])
        .arg(&run)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(3), "{err}");
    assert!(
        err.contains("salvaged") && err.contains("no rig could be reached"),
        "{err}"
    );
    let v = list(&store);
    assert!(v["damaged"].as_array().unwrap().is_empty(), "{v}");
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 1);
    assert_eq!(runs[0]["status"], "incomplete", "{v}");
    assert!(
        runs[0]["completeness"]
            .as_str()
            .unwrap()
            .contains("missing"),
        "{v}"
    );
}

/// The apparatus run (load 0, the blades alone: a calibration) is recorded, fitted for its damping
/// μ_a with its ±, reported and replayed. (Before, `fit`, `report` and `replay` refused it: "load_n
/// must be finite and > 0".)
#[test]
fn the_apparatus_run_is_recorded_fitted_reported_and_replayed() {
    let rig = RigProcess::start(f64::INFINITY);
    let dir = tempfile::tempdir().unwrap();
    let store = dir.path().join("runs");
    let out = tribo(
        &[
            "run",
            "--quiet",
            "--port",
            &rig.addr,
            "--load",
            "0",
            "--max-duration",
            "4",
        ],
        &store,
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("the apparatus alone"), "{text}");
    let run = std::fs::read_dir(&store)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.is_dir())
        .unwrap();
    let fit = Command::new(TRIBO)
        .args(["fit", run.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(
        fit.status.success(),
        "{}",
        String::from_utf8_lossy(&fit.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&fit.stdout).unwrap();
    assert_eq!(j["apparatus"], true, "{j}");
    assert_eq!(j["law"], "viscous");
    // The virtual rig's apparatus damping is 0.0011.
    let (mu_a, se) = (j["mu_a"].as_f64().unwrap(), j["mu_a_se"].as_f64().unwrap());
    assert!(
        se > 0.0 && (mu_a - 0.0011).abs() < 5.0 * se + 1e-5,
        "μ_a {mu_a} ± {se}"
    );
    for cmd in [["report", "--no-png"].as_slice(), ["replay"].as_slice()] {
        let mut c = Command::new(TRIBO);
        c.arg(cmd[0]).arg(&run).args(&cmd[1..]);
        if cmd[0] == "report" {
            c.arg("-o").arg(dir.path().join("report"));
        }
        let o = c.output().unwrap();
        assert!(
            o.status.success(),
            "{cmd:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
}

/// A second host on a busy rig is told the rig serves one host at a time and that nothing was
/// sent or recorded (it was told "lost the link … `tribo pull` fetches the rest").
#[test]
fn a_second_host_on_a_busy_rig_is_told_why_and_that_nothing_was_recorded() {
    use std::io::{BufRead, BufReader};
    let rig = RigProcess::start(1.0);
    let dir = tempfile::tempdir().unwrap();
    let mut first = Command::new(TRIBO)
        .args(["run", "--port", &rig.addr, "--load", "0.1"])
        .arg("--store")
        .arg(dir.path().join("a"))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(first.stderr.take().unwrap());
    let mut line = String::new();
    while err.read_line(&mut line).unwrap() > 0 && !line.contains("recording run") {
        line.clear();
    }
    let out = tribo(
        &["run", "--quiet", "--port", &rig.addr, "--load", "0.3"],
        &dir.path().join("b"),
    );
    let msg = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{msg}");
    assert!(
        msg.contains("one host at a time") && msg.contains("nothing was recorded"),
        "{msg}"
    );
    assert!(!msg.contains("fetches the rest"), "{msg}");
    assert!(
        !dir.path().join("b").join("catalog.sqlite").exists() || {
            std::fs::read_dir(dir.path().join("b"))
                .unwrap()
                .all(|e| !e.unwrap().path().is_dir())
        }
    );
    let _ = first.wait();
}
