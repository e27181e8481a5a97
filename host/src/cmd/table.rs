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
    let t = cat.table(rows, cols, value, &filter)?;
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
    outln!("{} (mean ± sd over repetitions, (n) runs)", args.value)?;
    crate::out!("{}", t.render())?;
    left_out()
}
