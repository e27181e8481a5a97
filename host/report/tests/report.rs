//! The report of simulated runs and campaigns: files, figure contents, HTML page, errors.

use std::collections::BTreeSet;
use std::path::Path;
use tribo_physics::integrate::Method;
use tribo_physics::model::Model;
use tribo_physics::record::Units;
use tribo_physics::sensor::{generate, Ecr, RecordSpec, SensorModel, Thermal};
use tribo_physics::{FrictionLaw, Record, Rig};
use tribo_report::plot::Style;
use tribo_report::{
    campaign_report, record_report, write_campaign_report, write_record_report, CampaignInputs,
    CampaignPoint, Figure, ReportError, ReportInputs,
};

/// A short loaded run on the real rig: quadratic law, 16-bit sensors, lagged 300 Hz force channel,
/// thermocouple and an ECR channel of the given regime.
fn simulated(ecr_level: f64, ecr_sigma: f64) -> Record {
    let model = Model::new(FrictionLaw::quadratic(0.02, 0.02, 0.002)).with_static_mu(0.025);
    let spec = RecordSpec {
        rig: Rig::REAL,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 0.8,
        rate_hz: 2000.0,
    };
    let sensor = SensorModel {
        force_lag_s: 0.003,
        thermal: Some(Thermal {
            start_c: 40.0,
            drift_c_per_s: 0.1,
            noise_c: 0.05,
        }),
        ecr: Some(Ecr {
            log10_sliding: ecr_level,
            log10_rest: 3.0,
            fluctuation_decades: ecr_sigma,
        }),
        ..SensorModel::default()
    };
    generate(&spec, &model, Method::dopri(1e-9), Some(&sensor)).unwrap()
}

const RUN_FIGURES: [&str; 8] = [
    "motion",
    "envelopes",
    "law",
    "windows",
    "force_velocity",
    "force_displacement",
    "ecr",
    "temperature",
];

/// Text contents of all `<text>` elements of an SVG document (which must parse as XML).
fn svg_texts(svg: &str) -> Vec<String> {
    let doc = roxmltree::Document::parse(svg).expect("SVG is well-formed XML");
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    doc.descendants()
        .filter(|n| n.has_tag_name("text"))
        .map(|n| n.text().unwrap_or("").trim().to_string())
        .collect()
}

/// Stroke/fill colours of the data marks (polylines and circles) of an SVG.
fn mark_colours(svg: &str) -> BTreeSet<String> {
    let doc = roxmltree::Document::parse(svg).unwrap();
    doc.descendants()
        .filter(|n| n.has_tag_name("polyline") || n.has_tag_name("circle"))
        .flat_map(|n| [n.attribute("stroke"), n.attribute("fill")])
        .flatten()
        .filter(|c| *c != "none")
        .map(str::to_string)
        .collect()
}

fn hex(c: plotters::style::RGBColor) -> String {
    format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
}

/// Every named series has its legend entry, and every series colour is drawn.
fn check_series(fig: &Figure, svg: &str) {
    let texts = svg_texts(svg);
    let named: Vec<&str> = fig
        .panels
        .iter()
        .flat_map(|p| p.series.iter())
        .filter(|s| !s.name.is_empty())
        .map(|s| s.name.as_str())
        .collect();
    for name in &named {
        assert!(
            texts.iter().any(|t| t == name),
            "figure {}: legend entry {name:?} missing",
            fig.name
        );
    }
    let drawn = mark_colours(svg);
    for s in fig.panels.iter().flat_map(|p| p.series.iter()) {
        assert!(
            s.data.len() >= 2,
            "figure {}: series {:?} is empty",
            fig.name,
            s.name
        );
        let c = hex(tribo_report::plot::color(s.color));
        assert!(
            drawn.contains(&c),
            "figure {}: series {:?} ({c}) not drawn",
            fig.name,
            s.name
        );
    }
}

fn assert_self_contained(html: &str) {
    let lower = html.to_ascii_lowercase();
    for bad in [
        "src=", "href=", "<link", "<script", "url(", "@import", "<img",
    ] {
        assert!(
            !lower.contains(bad),
            "page refers to something outside it: {bad}"
        );
    }
}

#[test]
fn a_full_run_writes_every_figure_and_a_self_contained_page() {
    let rec = simulated(7.0, 0.03);
    let dir = tempfile::tempdir().unwrap();
    let files = write_record_report(&rec, &ReportInputs::default(), dir.path()).unwrap();
    let names: Vec<&str> = files.figures.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, RUN_FIGURES);
    let report = record_report(&rec, &ReportInputs::default()).unwrap();
    let html = std::fs::read_to_string(&files.html).unwrap();
    assert_self_contained(&html);
    // One inline SVG per figure, each inside its own <figure>.
    assert_eq!(html.matches("<svg").count(), RUN_FIGURES.len());
    for (f, fig) in files.figures.iter().zip(&report.figures) {
        assert_eq!(f.name, fig.name);
        let svg = std::fs::read_to_string(&f.svg).unwrap();
        check_series(fig, &svg);
        let png = std::fs::read(f.png.as_ref().unwrap()).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{}", f.name);
        assert!(html.contains(&format!("id=\"fig-{}\"", f.name)));
        assert!(html.contains(&format!("{}.svg", f.name)));
    }
    // Expected series: envelope figure = measured + one per fitted law.
    let env = &report.figures[1];
    assert_eq!(env.series_count(), 1 + 4);
    // The ECR was a steady film at 10^7 Ω.
    assert!(html.contains("full film (EHL)"), "regime missing");
    assert!(files.notes.is_empty(), "{:?}", files.notes);
}

#[test]
fn the_envelope_drawn_touches_the_displacement_peaks() {
    let rec = simulated(7.0, 0.03);
    let report = record_report(&rec, &ReportInputs::default()).unwrap();
    let motion = &report.figures[0];
    let (x, env) = (&motion.panels[0].series[0], &motion.panels[0].series[1]);
    assert_eq!(x.style, Style::Line(1));
    let mut checked = 0;
    for w in x.data.windows(3) {
        let (a, b, c) = (w[0].1, w[1].1, w[2].1);
        // A displacement peak well above the noise and the stop.
        if b.abs() > 100.0 && b.abs() >= a.abs() && b.abs() >= c.abs() && a.signum() == b.signum() {
            let e = env
                .data
                .iter()
                .min_by(|p, q| (p.0 - w[1].0).abs().total_cmp(&(q.0 - w[1].0).abs()))
                .unwrap()
                .1;
            assert!(
                (e - b.abs()).abs() < 0.03 * b.abs(),
                "envelope {e} µm vs peak {b} µm at t = {}",
                w[1].0
            );
            checked += 1;
        }
    }
    assert!(checked >= 10, "only {checked} peaks checked");
}

#[test]
fn the_ecr_regime_shows_on_the_page() {
    let rec = simulated(5.0, 0.8);
    let r = record_report(&rec, &ReportInputs::default()).unwrap();
    assert!(r.summary_html.contains("mixed"));
    let ecr = r.figures.iter().find(|f| f.name == "ecr").unwrap();
    assert!(
        ecr.panels[0].title.contains("mixed"),
        "{}",
        ecr.panels[0].title
    );
}

#[test]
fn missing_channels_skip_their_figures_with_a_note() {
    let mut rec = simulated(7.0, 0.03);
    rec.ft = None;
    rec.ecr = None;
    rec.temp = None;
    let dir = tempfile::tempdir().unwrap();
    let files = write_record_report(&rec, &ReportInputs::default(), dir.path()).unwrap();
    let names: Vec<&str> = files.figures.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["motion", "envelopes", "law", "windows"]);
    assert!(
        files.notes.iter().any(|n| n.contains("force")),
        "{:?}",
        files.notes
    );
    assert!(
        files.notes.iter().any(|n| n.contains("ECR")),
        "{:?}",
        files.notes
    );
    let html = std::fs::read_to_string(&files.html).unwrap();
    assert!(html.contains("no force channel"));
    assert!(!dir.path().join("force_velocity.svg").exists());
}

#[test]
fn bad_records_are_clear_errors() {
    let good = simulated(7.0, 0.03);
    let dir = tempfile::tempdir().unwrap();
    // What a person reads: the error and its causes.
    let run = |rec: &Record| {
        write_record_report(rec, &ReportInputs::default(), dir.path()).map_err(|e| {
            let mut text = e.to_string();
            let mut cause = std::error::Error::source(&e);
            while let Some(c) = cause {
                text += &format!(": {c}");
                cause = c.source();
            }
            (e, text)
        })
    };

    let empty = Record::new(vec![], vec![], vec![], Some(Rig::REAL), Units::Si);
    let (e, said) = run(&empty).unwrap_err();
    assert!(
        matches!(e, ReportError::Input(_)) && said.contains("no samples"),
        "{said}"
    );

    let mut nan = good.clone();
    nan.x[10] = f64::NAN;
    let (e, said) = run(&nan).unwrap_err();
    assert!(
        matches!(e, ReportError::Record(_)) && said.contains("non-finite"),
        "{said}"
    );

    let mut nan_force = good.clone();
    nan_force.ft.as_mut().unwrap()[3] = f64::INFINITY;
    assert!(run(&nan_force).unwrap_err().1.contains("ft"));

    let mut bad_ecr = good.clone();
    bad_ecr.ecr.as_mut().unwrap()[0] = 0.0;
    assert!(run(&bad_ecr).unwrap_err().1.contains("ECR"));

    let mut no_rig = good.clone();
    no_rig.rig = None;
    assert!(run(&no_rig).unwrap_err().1.contains("rig constants"));

    let n = good.len();
    let at_rest = Record::new(
        good.t.clone(),
        vec![0.0; n],
        vec![0.0; n],
        Some(Rig::REAL),
        Units::Si,
    );
    assert!(run(&at_rest).unwrap_err().1.contains("no oscillation"));
    // Nothing half-written by the failures.
    assert!(!dir.path().join("report.html").exists());

    // A folder that cannot be made: the path named, the io::Error as the source.
    let file = dir.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let e = write_record_report(&good, &ReportInputs::default(), &file.join("report")).unwrap_err();
    assert!(
        matches!(&e, ReportError::Io { path, .. } if path.starts_with(&file)),
        "{e:?}"
    );
    let io = std::error::Error::source(&e).and_then(|s| s.downcast_ref::<std::io::Error>());
    assert!(io.is_some(), "{e:?}");
}

fn campaign() -> Vec<CampaignPoint> {
    let mut pts = Vec::new();
    for (ti, t) in [25.0, 60.0].into_iter().enumerate() {
        for (li, n) in [0.1, 0.3, 0.5].into_iter().enumerate() {
            for r in 0..3 {
                pts.push(CampaignPoint {
                    run: format!("run-{ti}-{li}-{r}"),
                    load_n: n,
                    temp_c: Some(t + 0.6 * r as f64),
                    temp_setpoint_c: Some(t),
                    mu0: Some(0.01 + 0.001 * ti as f64 + 0.0005 * r as f64),
                    mu1: Some(0.002),
                    mu0_se: None,
                    mu1_se: None,
                    cycles: Some(40.0 - 10.0 * li as f64 + r as f64),
                });
            }
        }
    }
    pts
}

#[test]
fn a_campaign_plots_means_with_spread_per_group() {
    let pts = campaign();
    let report = campaign_report(&pts, &CampaignInputs::default()).unwrap();
    let names: Vec<&str> = report.figures.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(
        names,
        ["mu0_vs_load", "mu1_vs_load", "cycles_vs_temperature"]
    );
    let mu0 = &report.figures[0].panels[0];
    // Two temperature settings (setpoints 25 and 60 °C, read 25.0/25.6/26.2 and 60.0/60.6/61.2 °C):
    // a mean line and the single runs each.
    assert_eq!(mu0.series.len(), 4);
    let mean = &mu0.series[0];
    assert_eq!(mean.name, "25 °C (mean ± sd)");
    assert_eq!(mean.data.len(), 3);
    // Mean and sample sd of 0.0100, 0.0105, 0.0110.
    let (x, m) = mean.data[1];
    assert!((x - 0.3).abs() < 1e-12);
    assert!((m - 0.0105).abs() < 1e-12);
    let (_, lo, hi) = mean.errors[1];
    assert!((hi - lo - 2.0 * 0.0005).abs() < 1e-12);
    assert_eq!(mu0.series[1].data.len(), 9);
    // Cycles against temperature: one series per load, a mean per temperature setting at the
    // setpoint, the single runs at their own temperatures.
    let cyc = &report.figures[2].panels[0];
    assert_eq!(cyc.series.len(), 6);
    assert_eq!(cyc.series[0].data.len(), 2);
    assert!((cyc.series[0].data[0].0 - 25.0).abs() < 1e-9);
    let xs: Vec<f64> = cyc.series[1].data.iter().map(|d| d.0).collect();
    assert_eq!(xs.len(), 6);
    assert!(xs.contains(&25.0) && xs.contains(&61.2));

    let dir = tempfile::tempdir().unwrap();
    let files = write_campaign_report(&pts, &CampaignInputs::default(), dir.path()).unwrap();
    let html = std::fs::read_to_string(&files.html).unwrap();
    assert_self_contained(&html);
    for (f, fig) in files.figures.iter().zip(&report.figures) {
        check_series(fig, &std::fs::read_to_string(&f.svg).unwrap());
        assert!(html.contains(&format!("id=\"fig-{}\"", f.name)));
    }
    assert!(html.contains("run-1-2-2"));
}

#[test]
fn campaign_gaps_are_notes_and_bad_points_errors() {
    let mut pts = campaign();
    for p in &mut pts {
        p.temp_c = None;
        p.temp_setpoint_c = None;
        p.cycles = None;
    }
    let r = campaign_report(&pts, &CampaignInputs::default()).unwrap();
    assert_eq!(r.figures.len(), 2);
    assert!(r.notes[0].contains("cycles-vs-temperature"));
    // No setpoint and no reading: the μ0 points form one group, the heater off.
    assert_eq!(
        r.figures[0].panels[0].series[0].name,
        "heater off (mean ± sd)"
    );
    // A setpoint that is not a number: the group is "not recorded", next to the others.
    pts[0].temp_setpoint_c = Some(f64::NAN);
    let r = campaign_report(&pts, &CampaignInputs::default()).unwrap();
    let names: Vec<&str> = r.figures[0].panels[0]
        .series
        .iter()
        .map(|s| s.name.as_str())
        .filter(|n| n.contains("mean"))
        .collect();
    assert_eq!(
        names,
        ["not recorded (mean ± sd)", "heater off (mean ± sd)"]
    );

    assert!(campaign_report(&[], &CampaignInputs::default()).is_err());
    pts[0].load_n = f64::NAN;
    let e = campaign_report(&pts, &CampaignInputs::default()).unwrap_err();
    assert!(e.to_string().contains("run-0-0-0"), "{e}");
}

#[test]
fn reports_can_skip_png() {
    let mut inputs = ReportInputs::default();
    inputs.options.png = false;
    inputs.options.laws = vec![tribo_physics::LawSpec::CoulombViscous];
    let mut rec = simulated(7.0, 0.03);
    rec.ecr = None;
    rec.temp = None;
    let dir = tempfile::tempdir().unwrap();
    let files = write_record_report(&rec, &inputs, dir.path()).unwrap();
    assert!(files.figures.iter().all(|f| f.png.is_none()));
    let pngs = std::fs::read_dir(dir.path())
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension() == Some("png".as_ref()))
        .count();
    assert_eq!(pngs, 0);
    assert!(Path::new(&files.html).exists());
}

#[test]
fn a_dimensionless_record_is_reported_in_dimensionless_units() {
    let model = Model::new(FrictionLaw::coulomb_viscous(0.05, 0.02));
    let taus: Vec<f64> = (0..3000).map(|i| i as f64 * 0.02).collect();
    let tr = tribo_physics::simulate(&model, 5.0, 0.0, &taus, Method::dopri(1e-9)).unwrap();
    let rec = Record::new(
        tr.tau.clone(),
        tr.y.clone(),
        tr.ydot.clone(),
        None,
        Units::Dimensionless,
    );
    let r = record_report(&rec, &ReportInputs::default()).unwrap();
    let names: Vec<&str> = r.figures.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["motion", "envelopes", "law", "windows"]);
    assert_eq!(r.figures[0].panels[0].x_label, "τ = Ωt");
    // A Coulomb–viscous record: the windowed constants stay those of the whole record.
    let w = &r.figures[3];
    for (panel, truth) in w.panels.iter().zip([0.05, 0.02]) {
        assert!(panel.series[0].data.len() >= 3);
        for &(_, m) in &panel.series[0].data {
            assert!(
                (m - truth).abs() < 0.02 * truth,
                "{}: {m} vs {truth}",
                panel.title
            );
        }
    }
    assert_eq!(r.figures[0].panels[0].y_label, "y = kx/N");
    // No SI axes without rig constants.
    assert!(r
        .figures
        .iter()
        .all(|f| f.panels.iter().all(|p| p.secondary.is_none())));
    assert!(!r.summary_html.contains("µm"));
    // The coulomb-viscous fit recovers the simulated constants (noise-free record).
    let row = r
        .summary_html
        .lines()
        .find(|l| l.contains("host fit: coulomb-viscous"))
        .unwrap()
        .to_string();
    assert!(
        row.contains("<td>0.05000 ± ") && row.contains("<td>0.02000 ± "),
        "{row}"
    );
    assert!(row.contains("adequate"), "{row}");
}

/// A constant μ0 measured with ± 1e-5 whose runs differ by 1e-7 across the loads is drawn flat:
/// the value axis spans at least 6 standard errors, and every run carries its ± as a bar. (An axis
/// fitted to the data alone spanned 1e-6 and drew the constant as a steep fall.)
#[test]
fn a_campaign_axis_never_stretches_a_difference_far_below_the_standard_error() {
    let mut pts = Vec::new();
    for (i, n) in [0.1, 0.3, 0.5, 0.7].into_iter().enumerate() {
        pts.push(CampaignPoint {
            run: format!("run-{i}"),
            load_n: n,
            temp_c: Some(25.0),
            temp_setpoint_c: Some(25.0),
            mu0: Some(0.02 - 1e-7 * i as f64),
            mu1: Some(0.004),
            mu0_se: Some(1e-5),
            mu1_se: Some(2e-5),
            cycles: Some(30.0),
        });
    }
    let report = campaign_report(&pts, &CampaignInputs::default()).unwrap();
    let mu0 = &report.figures[0].panels[0];
    let (lo, hi) = mu0
        .y_range
        .expect("a value axis set from the standard errors");
    assert!(hi - lo >= 6.0 * 1e-5 * 0.999, "axis spans {}", hi - lo);
    assert!(lo < 0.02 - 3e-7 && hi > 0.02, "{lo} .. {hi}");
    let bars = mu0
        .series
        .iter()
        .find(|s| s.name.contains("standard error"))
        .expect("the runs' ± drawn");
    assert_eq!(bars.errors.len(), 4);
    assert!(bars.errors.iter().all(|e| (e.2 - e.1 - 2e-5).abs() < 1e-12));
}

/// The campaign figure and `tribo table` bin the same runs the same way (one rule,
/// `tribo_store::catalog::Bin`): heater-off runs whose plates read 22.0 and 38.8 °C are one
/// "heater off" group (they were split into 22 and 39 °C groups of one run), a setpoint of 29.5 °C
/// is the 30 °C setting in both (the figure clustered by proximity, the table rounded), and every
/// mean the figure draws is the table's cell.
#[test]
fn the_campaign_figure_groups_runs_as_the_campaign_table_does() {
    use tribo_store::catalog::{tabulate, Axis, Bin, Value};
    use tribo_store::CatalogRow;
    let runs: [(Option<f64>, f64, f64, f64); 7] = [
        // (setpoint, plate reading, load, μ0)
        (None, 22.0, 0.3, 0.020),
        (None, 38.8, 0.3, 0.022),
        (None, 25.0, 0.5, 0.021),
        (Some(29.5), 29.5, 0.3, 0.030),
        (Some(30.4), 30.4, 0.3, 0.031),
        (Some(30.4), 30.4, 0.4995, 0.032),
        (Some(60.0), 60.0, 0.3, 0.040),
    ];
    let rows: Vec<CatalogRow> = runs
        .iter()
        .enumerate()
        .map(|(i, &(sp, t, n, mu0))| CatalogRow {
            id: format!("run-{i}"),
            path: format!("runs/run-{i}").into(),
            created: "2026-11-26T00:00:00Z".into(),
            status: "complete".into(),
            label: None,
            sample: None,
            lubricant: None,
            campaign: Some("c".into()),
            repeat: None,
            load_n: n,
            temp_c: sp.or(Some(t)),
            temp_setpoint_c: sp,
            firmware: None,
            serial: None,
            samples: 1000,
            missing_blocks: 0,
            verdict: None,
            cycles: Some(20),
            onboard_mu0: None,
            onboard_mu1: None,
            host_mu0: Some(mu0),
            host_mu1: Some(0.004),
            host_gap: None,
            host_mu0_se: None,
            host_mu1_se: None,
            lost_samples: 0,
            blocks: 10,
            blocks_expected: Some(10),
            completeness: "complete".into(),
        })
        .collect();
    let t = tabulate(&rows, Axis::Temp, Axis::Load, Value::Mu0);
    assert_eq!(
        t.rows,
        [Bin::HeaterOff, Bin::SetpointC(30), Bin::SetpointC(60)]
    );
    assert_eq!(t.cols, [Bin::LoadMn(300), Bin::LoadMn(500)]);
    assert_eq!(t.cells[0][0].unwrap().n, 2, "{}", t.render());
    assert_eq!(t.cells[1][0].unwrap().n, 2, "{}", t.render());
    assert!(t.render().contains("heater off"), "{}", t.render());

    let points: Vec<CampaignPoint> = rows
        .iter()
        .map(tribo_report::store::campaign_point)
        .collect();
    let report = campaign_report(&points, &CampaignInputs::default()).unwrap();
    let panel = &report.figures[0].panels[0];
    let means: Vec<_> = panel
        .series
        .iter()
        .filter(|s| s.name.ends_with("(mean ± sd)"))
        .collect();
    let names: Vec<&str> = means.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "heater off (mean ± sd)",
            "30 °C (mean ± sd)",
            "60 °C (mean ± sd)"
        ]
    );
    for (r, s) in means.iter().enumerate() {
        let cells: Vec<f64> = t.cells[r].iter().flatten().map(|c| c.mean).collect();
        let drawn: Vec<f64> = s.data.iter().map(|d| d.1).collect();
        assert_eq!(drawn.len(), cells.len(), "{}", s.name);
        for (a, b) in drawn.iter().zip(&cells) {
            assert!((a - b).abs() < 1e-15, "{}: drawn {a}, table {b}", s.name);
        }
    }
}
