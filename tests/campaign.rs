//! `tribo campaign`: loads × temperatures × repetitions, resumable without redoing finished runs.

mod host_common;

use host_common::*;
use std::path::Path;
use tribo::campaign::{finished, Plan, Point};
use tribo::cmd::campaign::Args;
use tribo::link::args::LinkArgs;
use tribo::link::Address;
use tribo_store::catalog::{AnyCatalog, Axis, Bin, Value};
use tribo_store::{Filter, RunCatalog};

fn write_plan(dir: &Path, text: &str) -> std::path::PathBuf {
    let p = dir.join("plan.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn args(plan: &Path, port: &Address, store: &Path) -> Args {
    Args {
        plan: plan.to_owned(),
        link: LinkArgs {
            port: Some(port.clone()),
            store: Some(store.to_owned()),
        },
        no_prompt: true,
        dry_run: false,
        catalog: None,
        quiet: true,
    }
}

#[test]
fn plan_orders_points_and_rejects_bad_plans() {
    let d = tempfile::tempdir().unwrap();
    let p = Plan::load(&write_plan(
        d.path(),
        "name = \"t\"\nloads_n = [0.2, 0.4]\ntemps_c = [25, 60]\nrepeats = 2\n",
    ))
    .unwrap();
    let pts = p.points();
    assert_eq!(pts.len(), 8);
    // Temperatures outermost: the heater changes once per temperature.
    assert_eq!(
        pts[0],
        Point {
            temp_c: Some(25.0),
            load_n: 0.2,
            repeat: 1
        }
    );
    assert_eq!(
        pts[1],
        Point {
            temp_c: Some(25.0),
            load_n: 0.2,
            repeat: 2
        }
    );
    assert_eq!(pts[4].temp_c, Some(60.0));
    let bad = Plan::load(&write_plan(d.path(), "name = \"t\"\nloads_n = [0.9]\n")).unwrap_err();
    assert!(format!("{bad:#}").contains("load 0.9 N"), "{bad:#}");
    let bad = Plan::load(&write_plan(
        d.path(),
        "name = \"t\"\nloads_n = [0.2]\ntemps_c = [150]\n",
    ))
    .unwrap_err();
    assert!(format!("{bad:#}").contains("150 °C"), "{bad:#}");
    let bad = Plan::load(&write_plan(d.path(), "name = \"t\"\nloadz = [0.2]\n")).unwrap_err();
    assert!(format!("{bad:#}").contains("loadz"), "{bad:#}");
}

#[test]
fn campaign_resumes_without_redoing_finished_runs() {
    let (port, truth) = virtual_rig(0.015, 0.003, 7, 20.0);
    let d = tempfile::tempdir().unwrap();
    let store = d.path().join("runs");
    let plan_path = write_plan(
        d.path(),
        "name = \"resume\"\nloads_n = [0.3]\nrepeats = 3\nmax_duration_s = 8.0\n",
    );
    let plan = Plan::load(&plan_path).unwrap();

    tribo::cmd::campaign::run(args(&plan_path, &port, &store)).unwrap();
    let dirs = tribo_store::run::list_run_dirs(&store).unwrap();
    assert_eq!(dirs.len(), 3);
    assert_eq!(finished(&plan, &store).unwrap(), plan.points());
    // The plan gives no mass, stiffness or x0: the real rig's values stood in, and every run's
    // metadata says so.
    for d in &dirs {
        let m = tribo_store::Run::open(d).unwrap().meta;
        for k in ["mass_kg=", "stiffness_n_per_m=", "x0_m="] {
            assert!(
                m.defaults.iter().any(|x| x.starts_with(k)),
                "{k} {:?}",
                m.defaults
            );
        }
    }

    // Interrupted campaign: repetition 2 never happened.
    let victim = dirs
        .iter()
        .find(|d| tribo_store::Run::open(d).unwrap().meta.repeat == Some(2))
        .unwrap()
        .clone();
    std::fs::remove_dir_all(&victim).unwrap();
    assert_eq!(finished(&plan, &store).unwrap().len(), 2);
    tribo::cmd::campaign::run(args(&plan_path, &port, &store)).unwrap();
    let after = tribo_store::run::list_run_dirs(&store).unwrap();
    assert_eq!(after.len(), 3, "only the missing repetition was taken");
    for d in dirs.iter().filter(|d| **d != victim) {
        assert!(
            after.contains(d),
            "finished run {} kept, not redone",
            d.display()
        );
    }
    // Nothing left to do: no run taken.
    tribo::cmd::campaign::run(args(&plan_path, &port, &store)).unwrap();
    assert_eq!(tribo_store::run::list_run_dirs(&store).unwrap().len(), 3);

    // The campaign table: one cell, three repetitions, mean within the method's precision.
    let cat = RunCatalog::open(&store).unwrap();
    cat.reindex().unwrap();
    let t = cat
        .table(
            Axis::Temp,
            Axis::Load,
            Value::Mu0,
            &Filter {
                campaign: Some("resume".into()),
                ..Default::default()
            },
        )
        .unwrap();
    // The plan sets no temperature: every run is in the one heater-off row, whatever the plate read.
    assert_eq!(t.rows, vec![Bin::HeaterOff]);
    assert_eq!(t.cols, vec![Bin::LoadMn(300)]);
    let cell = t.cells[0][0].unwrap();
    assert_eq!(cell.n, 3);
    assert!((cell.mean - truth.0).abs() < 1e-3, "{cell:?} vs {truth:?}");
    assert!(cell.sd.unwrap() < 1e-3, "repeat spread {cell:?}");
}

#[test]
fn a_campaign_over_loads_on_the_virtual_rig_gets_the_same_dimensionless_friction_at_each_load() {
    // `tribo rig --virtual`: the simulated knob follows each run's load.
    let rig = tribo::virtual_rig::VirtualArgs {
        mu0: Some(0.02),
        mu1: Some(0.004),
        speed: 20.0,
        ..Default::default()
    };
    let (port, _) = rig.listen("127.0.0.1:0", |_| {}).unwrap();
    let port = RigOnTcp::from(port);
    let d = tempfile::tempdir().unwrap();
    let store = d.path().join("runs");
    let plan_path = write_plan(
        d.path(),
        "name = \"loads\"\nloads_n = [0.2, 0.5]\nmax_duration_s = 8.0\n",
    );
    tribo::cmd::campaign::run(args(&plan_path, &port, &store)).unwrap();
    let cat = RunCatalog::open(&store).unwrap();
    let f = Filter {
        campaign: Some("loads".into()),
        ..Default::default()
    };
    let rows = cat.list(&f).unwrap();
    assert_eq!(rows.len(), 2);
    // μ0 is dimensionless (friction / load): if the simulated load had stayed put while the host
    // divided by another, μ0 would scale with the ratio (0.5/0.3 or 0.2/0.3).
    for r in &rows {
        let mu0 = r.host_mu0.unwrap();
        assert!((mu0 - 0.02).abs() < 1e-3, "load {} N: μ0 {mu0}", r.load_n);
    }
    // A heavier load stops the pin sooner: fewer cycles (Coulomb decrement μ0 N / k per half-cycle).
    let cycles = |l: f64| {
        rows.iter()
            .find(|r| (r.load_n - l).abs() < 1e-6)
            .unwrap()
            .cycles
            .unwrap()
    };
    assert!(
        cycles(0.5) < cycles(0.2),
        "{} vs {}",
        cycles(0.5),
        cycles(0.2)
    );
    // A heater-off campaign whose knob turns between runs (the virtual rig rebuilds, its plate
    // read anew): one "heater off" row in the table and one "heater off" series in the report's
    // figure, whatever each run's plate read (it split into 22, 38 and 39 °C cells of one run each).
    let t = cat.table(Axis::Temp, Axis::Load, Value::Mu0, &f).unwrap();
    assert_eq!(t.rows, vec![Bin::HeaterOff], "{}", t.render());
    assert_eq!(t.cols, vec![Bin::LoadMn(200), Bin::LoadMn(500)]);
    let points: Vec<_> = rows
        .iter()
        .map(tribo_report::store::campaign_point)
        .collect();
    let report = tribo_report::campaign_report(&points, &Default::default()).unwrap();
    let means: Vec<&str> = report.figures[0].panels[0]
        .series
        .iter()
        .map(|s| s.name.as_str())
        .filter(|n| n.contains("mean"))
        .collect();
    assert_eq!(means, ["heater off (mean ± sd)"]);
}
