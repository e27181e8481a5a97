//! Adapters from the run store (`tribo-store`): a run folder to a run report, catalog rows to a
//! campaign report.

use crate::campaign::CampaignPoint;
use crate::run::ReportInputs;
use crate::{write_campaign_report, write_record_report, CampaignInputs, ReportError, ReportFiles};
use std::path::Path;
use tribo_physics::Record;
use tribo_store::{CatalogRow, Run};

/// What the report shows of a stored run besides its samples: metadata lines and the on-board
/// result; the host fits are redone by the report (all laws of [`crate::ReportOptions::laws`]).
pub fn run_inputs(run: &Run) -> ReportInputs {
    let m = run.meta();
    let mut meta = vec![
        ("run".to_string(), m.id.clone()),
        ("created".into(), m.created.clone()),
        ("status".into(), m.status.name().into()),
        // What the frame log holds, never what the metadata claims: "complete: 156 of 156
        // blocks", or "incomplete: 79 of 156 blocks (missing …)".
        ("completeness".into(), run.completeness().summary()),
    ];
    for (k, v) in [
        ("label", &m.label),
        ("sample", &m.sample),
        ("lubricant", &m.lubricant),
        ("campaign", &m.campaign),
    ] {
        if let Some(v) = v {
            meta.push((k.into(), v.clone()));
        }
    }
    if let Some(r) = m.repeat {
        meta.push(("repetition".into(), r.to_string()));
    }
    match (m.temp_setpoint_c, m.temp_c) {
        (Some(s), Some(t)) => meta.push((
            "temperature".into(),
            format!("{t:.1} °C (setpoint {s:.0} °C)"),
        )),
        (Some(s), None) => meta.push(("temperature".into(), format!("setpoint {s:.0} °C"))),
        (None, Some(t)) => meta.push(("temperature".into(), format!("{t:.1} °C (heater off)"))),
        (None, None) => {}
    }
    if let Some(d) = &m.device {
        meta.push(("firmware".into(), d.firmware.clone()));
        meta.push(("rig serial".into(), d.serial.clone()));
    }
    if !run.is_complete() {
        meta.push((
            "to complete it".into(),
            format!(
                "`tribo pull {}` fetches what is missing while the rig holds it",
                run.dir().display()
            ),
        ));
    }
    if let Some(r) = &run.recovery {
        meta.push(("frame log".into(), r.to_string()));
    }
    if let Some(h) = run.host_fit() {
        meta.push((
            "stored host fit".into(),
            format!(
                "{}: μ0 = {:.5} ± {:.1e}, μ1 = {:.5} ± {:.1e}, gap {:.3} %{}",
                h.law,
                h.mu0,
                h.mu0_se,
                h.mu1,
                h.mu1_se,
                100.0 * h.gap,
                h.verdict
                    .as_deref()
                    .map_or(String::new(), |v| format!(" ({v})"))
            ),
        ));
    }
    if let (Some(h), Some(ob)) = (run.host_fit(), run.result()) {
        if let Some(c) = crate::crosscheck::CrossCheck::of_stored(h, ob) {
            meta.push(("host vs on-board".into(), c.summary()));
        }
    }
    ReportInputs {
        title: format!("Run {}", m.id),
        meta,
        onboard: run.result().copied(),
        ..ReportInputs::default()
    }
}

/// Writes the report of a stored run into `out_dir`: `rec` its samples as the loader opened them
/// (`tribo::load::open`, the one path from a folder to a record), the on-board result from
/// `result.toml`.
pub fn write_run_report(
    run: &Run,
    rec: &Record,
    out_dir: &Path,
) -> Result<ReportFiles, ReportError> {
    write_record_report(rec, &run_inputs(run), out_dir)
}

/// A campaign point from a catalog row: the host fit (the one estimator of a law; a run without
/// one has no point, never the on-board estimate in its place); cycles from the on-board analysis.
pub fn campaign_point(row: &CatalogRow) -> CampaignPoint {
    CampaignPoint {
        run: row.id.clone(),
        load_n: row.load_n,
        temp_c: row.temp_c,
        temp_setpoint_c: row.temp_setpoint_c,
        mu0: row.host_mu0,
        mu1: row.host_mu1,
        mu0_se: row.host_mu0_se,
        mu1_se: row.host_mu1_se,
        cycles: row.cycles.map(f64::from),
    }
}

/// Writes the report of catalogued runs (e.g. one campaign) into `out_dir`.
pub fn write_catalog_report(
    rows: &[CatalogRow],
    title: &str,
    out_dir: &Path,
) -> Result<ReportFiles, ReportError> {
    let points: Vec<CampaignPoint> = rows.iter().map(campaign_point).collect();
    let inputs = CampaignInputs {
        title: title.into(),
        ..CampaignInputs::default()
    };
    write_campaign_report(&points, &inputs, out_dir)
}
