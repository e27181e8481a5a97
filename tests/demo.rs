//! `tribo demo`: a virtual rig, a run through the serial path, saved, fitted and drawn — and the
//! run it leaves is what `tribo fit` and `tribo report` read.

use tribo::cmd::demo::{demo, Args};
use tribo::virtual_rig::VirtualArgs;
use tribo_physics::identify::{fit, FitOptions};
use tribo_physics::LawSpec;

#[test]
fn demo_records_fits_and_draws_a_run_that_fit_and_report_can_read() {
    let out = tempfile::tempdir().unwrap();
    let args = Args {
        out: out.path().to_owned(),
        rig: VirtualArgs {
            speed: 20.0,
            mu0: Some(0.015),
            mu1: Some(0.003),
            ..Default::default()
        },
        no_report: false,
        quiet: true,
    };
    let o = demo(&args).unwrap();
    let run = &o.run;
    assert!(run.is_complete());
    assert!(run.dir().starts_with(out.path().join("runs")));
    // Truth: the contact's constants plus the apparatus damping (0.0011) in μ1.
    let (t0, t1) = (0.015, 0.003 + 0.0011);
    let h = run.host_fit().unwrap();
    assert!(
        (h.mu0 - t0).abs() < 1e-3 && (h.mu1 - t1).abs() < 2e-4,
        "{h:?}"
    );

    // `tribo fit RUN`: the run folder loads as a record and fits to the same constants.
    let rec = tribo::load_record(run.dir()).unwrap();
    let f = fit(&rec, LawSpec::CoulombViscous, &FitOptions::default()).unwrap();
    assert!(
        (f.mu[0] - t0).abs() < 1e-3 && (f.mu[1] - t1).abs() < 2e-4,
        "{:?}",
        f.mu
    );

    // The demo's report: an HTML page and its figures, each a real SVG.
    let html = std::fs::read_to_string(out.path().join("report").join("report.html")).unwrap();
    assert!(
        html.contains("<svg") || html.contains(".svg"),
        "figures referenced from the page"
    );
    let svgs: Vec<_> = std::fs::read_dir(out.path().join("report"))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "svg"))
        .collect();
    assert!(svgs.len() >= 3, "{svgs:?}");
    for s in &svgs {
        let text = std::fs::read_to_string(s).unwrap();
        assert!(
            text.starts_with("<svg") && text.len() > 1000,
            "{}",
            s.display()
        );
    }
    // `tribo report RUN` on the stored run.
    let again = out.path().join("again");
    let rec = tribo::load_record(run.dir()).unwrap();
    let files = tribo_report::store::write_run_report(run, &rec, &again).unwrap();
    assert!(files.html.is_file());
}
