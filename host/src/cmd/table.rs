//! `tribo table --rows temp --cols load --value mu0`: campaign tables (the thesis's Tables 5–7)
//! with the spread over repetitions (mean ± sd).

use crate::outln;
use std::path::PathBuf;
use tribo_store::catalog::{Axis, Value};
use tribo_store::Filter;

/// Arguments of `tribo table`.
#[derive(clap::Args, Debug)]
#[command(
    after_long_help = "--json prints one JSON object: {\"value\", \"row_axis\", \"col_axis\", \"rows\": [..], \"cols\": [..], \"row_labels\": [..], \"col_labels\": [..], \"cells\": [[{\"mean\", \"sd\", \"n\"} | null, ..], ..]}.
Rows and columns are loads (N, to the mN) and heater setpoints (°C, to the degree); a temperature of null (labelled \"heater off\") holds every run taken with the heater off, whatever its plate read."
)]
pub struct Args {
    /// Run store directory (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// What the rows are: `temp` or `load`.
    #[arg(long, default_value = "temp", value_parser = ["temp", "load"])]
    pub rows: String,
    /// What the columns are: `load` or `temp`.
    #[arg(long, default_value = "load", value_parser = ["temp", "load"])]
    pub cols: String,
    /// mu0 or mu1 (host fit, as the thesis), onboard-mu0 or onboard-mu1 (the rig's).
    #[arg(long, default_value = "mu0", value_parser = ["mu0", "mu1", "onboard-mu0", "onboard-mu1"])]
    pub value: String,
    /// Only this campaign's runs.
    #[arg(long)]
    pub campaign: Option<String>,
    /// Only this rig's runs (its serial number).
    #[arg(long, value_name = "SERIAL")]
    pub rig: Option<String>,
    /// Only the runs taken in this period.
    #[command(flatten)]
    pub period: super::common::Period,
    /// This PC's catalog of runs, or the lab's.
    #[arg(long, value_name = "URL", help = super::common::CATALOG_HELP)]
    pub catalog: Option<String>,
    /// Print one JSON object (set by the global `--json`; its shape is in `after_long_help`).
    #[arg(skip)]
    pub json: bool,
    /// Re-fit every run of the table on this PC with `--law` (the host fit's options) on every
    /// core, instead of reading the fits the catalog holds (the store is not changed): what a
    /// changed law does to a campaign. A run that cannot be re-fitted is left out and said why.
    #[arg(long)]
    pub refit: bool,
    /// The law `--refit` fits (μ0 and μ1 are its constant and linear terms).
    #[arg(long, default_value = "coulomb-viscous", requires = "refit")]
    pub law: tribo_physics::LawSpec,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    args.period.check()?;
    let store = args
        .store
        .clone()
        .unwrap_or_else(tribo_store::default_store_dir);
    let lab = tribo_catalog::lab_url(args.catalog.as_deref()).is_some();
    if !lab && !store.is_dir() {
        anyhow::bail!("no run store at {}: run a campaign first (`tribo campaign PLAN.toml`), or point --store at one", store.display());
    }
    let rows: Axis = args.rows.parse()?;
    let cols: Axis = args.cols.parse()?;
    let value: Value = args.value.parse()?;
    let cat = crate::lab::open_catalog(args.catalog.as_deref(), &store)?;
    let filter = args.period.apply(Filter {
        campaign: args.campaign.clone(),
        rig: args.rig.clone(),
        ..Default::default()
    });
    let (t, refit_failed) = if args.refit {
        if lab {
            anyhow::bail!(
                "--refit fits the runs of this PC's store: drop --catalog (the lab catalog holds \
                 their fits, not their samples)"
            );
        }
        if matches!(value, Value::OnboardMu0 | Value::OnboardMu1) {
            anyhow::bail!(
                "--refit re-fits on the host: use --value mu0 or mu1 (the rig's own fit is what \
                 it sent)"
            );
        }
        let runs = cat.runs(&tribo_store::catalog::table_filter(rows, cols, &filter)?)?;
        let (runs, failed) = refit_runs(runs, args.law);
        (
            tribo_store::catalog::tabulate(&runs, rows, cols, value),
            failed,
        )
    } else {
        (cat.table(rows, cols, value, &filter)?, Vec::new())
    };
    // The runs of this PC's store the table cannot hold (damaged, incomplete): said, status 3.
    let left = if lab {
        Vec::new()
    } else {
        crate::archive::left_out(&store, &filter)?
    };
    let left_out = || match crate::archive::report_left_out("table", &left) {
        Some(e) => Err(e.into()),
        None => Ok(()),
    };
    if args.json {
        let axis = |a: Axis| match a {
            Axis::Load => "load_n",
            Axis::Temp => "temp_c",
        };
        let cells: Vec<Vec<serde_json::Value>> = t
            .cells
            .iter()
            .map(|row| {
                row.iter()
                    .map(|c| match c {
                        Some(c) => serde_json::json!({ "mean": c.mean, "sd": c.sd, "n": c.n }),
                        None => serde_json::Value::Null,
                    })
                    .collect()
            })
            .collect();
        crate::out::print_json(serde_json::json!({
            "value": args.value,
            "row_axis": axis(t.row_axis),
            "col_axis": axis(t.col_axis),
            "rows": t.row_values(),
            "cols": t.col_values(),
            "row_labels": t.rows.iter().map(|b| b.label()).collect::<Vec<_>>(),
            "col_labels": t.cols.iter().map(|b| b.label()).collect::<Vec<_>>(),
            "cells": cells,
            "refit": args.refit.then(|| args.law.to_string()),
            "refit_failed": refit_failed
                .iter()
                .map(|(dir, why)| serde_json::json!({"run": dir.display().to_string(), "why": why}))
                .collect::<Vec<_>>(),
            "left_out": left
                .iter()
                .map(|l| serde_json::json!({"run": l.dir.display().to_string(), "why": l.why}))
                .collect::<Vec<_>>(),
        }))?;
        return left_out();
    }
    if t.rows.is_empty() {
        outln!(
            "no complete run with a {} value in {}: nothing to tabulate",
            args.value,
            cat.describe()
        )?;
        return left_out();
    }
    if args.refit {
        outln!(
            "{} of the {} law re-fitted now (mean ± sd over repetitions, (n) runs)",
            args.value,
            args.law
        )?;
    } else {
        outln!("{} (mean ± sd over repetitions, (n) runs)", args.value)?;
    }
    crate::out!("{}", t.render())?;
    left_out()
}

/// Re-fits `runs` with `law` on every core (a progress bar on stderr when it is a terminal): the
/// runs with their host μ0 and μ1 replaced, in input order, and those that could not be re-fitted
/// (their folder and why), each also said on stderr.
fn refit_runs(
    runs: Vec<tribo_store::catalog::CatalogRow>,
    law: tribo_physics::LawSpec,
) -> (
    Vec<tribo_store::catalog::CatalogRow>,
    Vec<(PathBuf, String)>,
) {
    let bar = indicatif::ProgressBar::new(runs.len() as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} runs re-fitted ({per_sec})",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let fits = tribo_physics::identify::map_on_every_core(
        &runs,
        |row| refit(&row.path, law),
        || bar.inc(1),
    );
    bar.finish_and_clear();
    let mut ok = Vec::new();
    let mut failed = Vec::new();
    for (mut row, fit) in runs.into_iter().zip(fits) {
        match fit {
            Ok((mu0, mu1)) => {
                row.host_mu0 = mu0;
                row.host_mu1 = mu1;
                ok.push(row);
            }
            Err(why) => {
                crate::errln!("{}: not re-fitted: {why}", row.path.display());
                failed.push((row.path, why));
            }
        }
    }
    (ok, failed)
}

/// One run's re-fit with `law` (the apparatus alone: its damping, [`tribo_physics::identify::
/// law_for`]): μ0 and μ1 where the law has them.
fn refit(
    dir: &std::path::Path,
    law: tribo_physics::LawSpec,
) -> Result<(Option<f64>, Option<f64>), String> {
    use tribo_physics::identify::{fit, law_for, FitOptions};
    let run = tribo_store::Run::open(dir).map_err(|e| format!("{e:#}"))?;
    if run.gaps().next().is_some() {
        return Err(format!(
            "{} samples lost in acquisition gaps: the envelope cannot be fitted across them",
            run.lost_samples()
        ));
    }
    let rec = run.record().map_err(|e| format!("its samples: {e:#}"))?;
    let spec = law_for(&rec, law);
    let r = fit(&rec, spec, &FitOptions::default()).map_err(|e| format!("the fit: {e:#}"))?;
    let mu = |j: usize| {
        spec.powers()
            .contains(&j)
            .then(|| r.mu.get(j).copied())
            .flatten()
            .filter(|v| v.is_finite())
    };
    Ok((mu(0), mu(1)))
}
