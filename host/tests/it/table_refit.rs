//! `tribo table --refit`: the campaign table from fits made now (every run re-fitted, on every
//! core), not from those the catalog holds. Three demo runs (two at 0.3 N, one at 0.1 N): the
//! Coulomb–viscous re-fit gives the stored fits' table to 1e-9; a quadratic re-fit gives another
//! table of as many runs; a run that is no longer whole is left out as the stored table leaves it
//! out; the rig's own values are refused with what to do.

use crate::support;
use serde_json::Value;
use std::path::Path;

fn tribo_ok(args: &[&str]) -> Value {
    let o = support::tribo(args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("{args:?}: {e}: {}", String::from_utf8_lossy(&o.stdout)))
}

fn demo(out: &Path, load: &str) {
    let o = support::tribo(&[
        "demo",
        "--no-report",
        "--out",
        out.to_str().unwrap(),
        "--rig-load",
        load,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// The cells of a table's JSON as (mean, n), row-major.
fn cells(t: &Value) -> Vec<Option<(f64, u64)>> {
    t["cells"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| r.as_array().unwrap().iter())
        .map(|c| (!c.is_null()).then(|| (c["mean"].as_f64().unwrap(), c["n"].as_u64().unwrap())))
        .collect()
}

#[test]
fn table_refit_fits_every_run_now_and_says_which_it_could_not() {
    let dir = tempfile::tempdir().unwrap();
    demo(dir.path(), "0.3");
    demo(dir.path(), "0.3");
    demo(dir.path(), "0.1");
    let store = dir.path().join("runs");
    let s = store.to_str().unwrap();
    let stored = tribo_ok(&["table", "--store", s, "--json"]);
    let refit = tribo_ok(&["table", "--store", s, "--json", "--refit"]);
    assert_eq!(refit["refit"], "coulomb-viscous", "{refit}");
    assert_eq!(refit["cols"], stored["cols"], "{refit}");
    let (a, b) = (cells(&stored), cells(&refit));
    assert_eq!(a.len(), 2, "{stored}");
    for (x, y) in a.iter().zip(&b) {
        let ((mx, nx), (my, ny)) = (x.unwrap(), y.unwrap());
        assert_eq!(nx, ny);
        assert!((mx - my).abs() <= 1e-9 * mx.abs(), "{mx} vs {my}");
    }
    // Another law: as many runs, its own constants.
    let quad = tribo_ok(&[
        "table",
        "--store",
        s,
        "--json",
        "--refit",
        "--law",
        "quadratic",
    ]);
    assert_eq!(quad["refit"], "quadratic");
    let q = cells(&quad);
    assert_eq!(
        q.iter().map(|c| c.unwrap().1).collect::<Vec<_>>(),
        a.iter().map(|c| c.unwrap().1).collect::<Vec<_>>()
    );
    assert!(
        q.iter().zip(&a).any(|(q, a)| q.unwrap().0 != a.unwrap().0),
        "a quadratic re-fit gave the Coulomb–viscous table: {quad}"
    );
    // A run whose frame log is gone: not whole, so left out of the re-fitted table as of the
    // stored one (status 3, listed in `left_out`); the others are re-fitted.
    let runs: Vec<_> = std::fs::read_dir(&store)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_dir() && p.to_string_lossy().contains("N0.300"))
        .collect();
    std::fs::remove_file(runs[0].join("frames.log")).unwrap();
    let o = support::tribo(&["table", "--store", s, "--json", "--refit"]);
    assert_eq!(
        o.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let after: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(after["left_out"].as_array().unwrap().len(), 1, "{after}");
    assert_eq!(after["refit_failed"], serde_json::json!([]), "{after}");
    let n = |t: &Value| cells(t).iter().map(|c| c.map_or(0, |c| c.1)).sum::<u64>();
    assert_eq!(n(&after), 2, "{after}");
    // Refused, with what to do: the rig's values cannot be re-fitted on the host.
    let o = support::tribo(&["table", "--store", s, "--refit", "--value", "onboard-mu0"]);
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("--value mu0"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
}
