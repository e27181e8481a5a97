//! `tribo runs`: lists and filters the runs of the store (from its SQLite catalog).

use super::common::Period;
use crate::export::{run_json, with_fields};
use crate::outln;
use std::path::PathBuf;
use tribo_store::{CatalogRow, Filter, RunCatalog, RunStatus};

/// Arguments of `tribo runs`. The `lost` column counts the samples a run's rig lost (acquisition
/// gaps: the run went on, and fits will not cross them).
#[derive(clap::Args, Debug)]
#[command(
    after_long_help = "--json prints one JSON object: {\"runs\": [{…}, …], \"damaged\": [{\"path\", \"why\"}, …]}."
)]
pub struct Args {
    /// Run store directory (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// Runs of this campaign (its `name` in PLAN.toml).
    #[arg(long)]
    pub campaign: Option<String>,
    /// Runs whose label contains this.
    #[arg(long)]
    pub label: Option<String>,
    /// Runs in this state.
    #[arg(long, value_parser = status_names())]
    pub status: Option<String>,
    /// Load range, N: `0.2` (±0.0005) or `0.1..0.4`.
    #[arg(long, value_parser = load_range)]
    pub load: Option<(f64, f64)>,
    /// Temperature range, °C: `60` (±0.5) or `25..60`.
    #[arg(long, value_parser = temp_range)]
    pub temp: Option<(f64, f64)>,
    /// Runs of this rig (its serial number, as `tribo devices` shows it).
    #[arg(long, value_name = "SERIAL")]
    pub rig: Option<String>,
    /// Only the runs taken in this period.
    #[command(flatten)]
    pub period: Period,
    /// This PC's catalog of runs, or the lab's.
    #[arg(long, value_name = "URL", help = super::common::CATALOG_HELP)]
    pub catalog: Option<String>,
    /// Rebuild the catalog from the run folders first.
    #[arg(long)]
    pub reindex: bool,
    /// Print the run folders only (for scripts).
    #[arg(long)]
    pub paths: bool,
    /// Print one JSON object (set by the global `--json`; its shape is in `after_long_help`).
    #[arg(skip)]
    pub json: bool,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

fn status_names() -> clap::builder::PossibleValuesParser {
    clap::builder::PossibleValuesParser::new(
        RunStatus::ALL
            .map(RunStatus::name)
            .into_iter()
            .chain([DAMAGED]),
    )
}

/// The state of a run folder whose frame log cannot be read as it is (damage, not a torn tail):
/// listed all the same, with what `tribo pull --salvage` does about it.
const DAMAGED: &str = "damaged";

fn load_range(s: &str) -> Result<(f64, f64), String> {
    parse_range(s, "load").map_err(|e| e.to_string())
}

fn temp_range(s: &str) -> Result<(f64, f64), String> {
    parse_range(s, "temp").map_err(|e| e.to_string())
}

/// `a` or `a..b` as an inclusive range.
pub fn parse_range(s: &str, what: &str) -> anyhow::Result<(f64, f64)> {
    let num = |t: &str| -> anyhow::Result<f64> {
        t.trim()
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                anyhow::anyhow!("{s:?} is not a number or range; write e.g. `0.3` or `0.1..0.4`")
            })
    };
    match s.split_once("..") {
        Some((a, b)) => {
            let (a, b) = (num(a)?, num(b)?);
            if a > b {
                anyhow::bail!("--{what} {s:?}: empty range; write the smaller bound first");
            }
            Ok((a, b))
        }
        None => {
            let v = num(s)?;
            // A single value matches what rounds to it.
            let tol = if what == "temp" { 0.5 } else { 5e-4 };
            Ok((v - tol, v + tol))
        }
    }
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    args.period.check()?;
    if let Some(url) = crate::lab::lab_url(args.catalog.as_deref())? {
        return lab(args, &url);
    }
    let store = args
        .store
        .clone()
        .unwrap_or_else(tribo_store::default_store_dir);
    if !store.is_dir() {
        anyhow::bail!("no run store at {}: take a run with `tribo run` or `tribo demo`, or point --store at one", store.display());
    }
    let cat = RunCatalog::open(&store)?;
    if let Some(r) = cat.refresh(args.reindex)? {
        if !args.quiet {
            crate::errln!(
                "catalog rebuilt from the run folders: {} runs, {} of them incomplete",
                r.indexed,
                r.incomplete.len()
            );
        }
        // What is incomplete is said even when quiet: it is a finding, not progress.
        for (d, why) in &r.incomplete {
            crate::errln!("{}: {why}", d.display());
        }
        for (d, e) in &r.unreadable {
            crate::errln!("skipped {}: {e}", d.display());
        }
    }
    // Folders the catalog cannot hold (their log is damaged): never hidden.
    let known: std::collections::BTreeSet<PathBuf> = cat
        .list(&Filter::default())?
        .into_iter()
        .map(|r| r.path)
        .collect();
    let only_filter_is_status = filter(&args, None).selects_by_status_only();
    let damaged: Vec<(PathBuf, String)> =
        if only_filter_is_status && args.status.as_deref().is_none_or(|s| s == DAMAGED) {
            tribo_store::run::list_run_dirs(&store)?
                .into_iter()
                .filter(|d| !known.contains(d))
                .map(|d| {
                    let why = match tribo_store::Run::open(&d) {
                        Ok(_) => "not in the catalog: `tribo runs --reindex`".to_string(),
                        Err(e) => e.to_string(),
                    };
                    (d, why)
                })
                .collect()
        } else {
            Vec::new()
        };
    let only_damaged = args.status.as_deref() == Some(DAMAGED);
    let status = args.status.clone().filter(|s| s != DAMAGED);
    let f = filter(&args, status);
    let rows = if only_damaged {
        Vec::new()
    } else {
        cat.list(&f)?
    };
    if args.json {
        let runs: Vec<serde_json::Value> = rows.iter().map(run_json).collect();
        let dmg: Vec<serde_json::Value> = damaged
            .iter()
            .map(|(p, why)| serde_json::json!({ "path": p, "status": DAMAGED, "why": why }))
            .collect();
        crate::out::print_json(serde_json::json!({ "runs": runs, "damaged": dmg }))?;
        return Ok(());
    }
    if args.paths {
        for r in rows {
            outln!("{}", r.path.display())?;
        }
        for (p, _) in &damaged {
            outln!("{}", p.display())?;
        }
        return Ok(());
    }
    if rows.is_empty() && !damaged.is_empty() {
        print_damaged(&damaged)?;
        return Ok(());
    }
    if rows.is_empty() {
        outln!("no run matches (try `tribo runs --reindex` if folders were copied in by hand)")?;
        return Ok(());
    }
    let any_lost = rows.iter().any(|r| r.lost_samples > 0);
    let incomplete = rows.iter().any(|r| r.status != "complete");
    let opt = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.5}"));
    outln!(
        "{:<44} {:<10} {:>11} {:>6} {:>7} {:>6} {:<12} {:>4} {:>9} {:>9} {:>9} {:>9}",
        "run",
        "status",
        "blocks",
        "lost",
        "load N",
        "°C",
        "campaign",
        "rep",
        "μ0 rig",
        "μ1 rig",
        "μ0 host",
        "μ1 host"
    )?;
    for r in &rows {
        outln!(
            "{:<44} {:<10} {:>11} {:>6} {:>7.3} {:>6} {:<12} {:>4} {:>9} {:>9} {:>9} {:>9}",
            r.id,
            r.status,
            match r.blocks_expected {
                Some(m) => format!("{}/{m}", r.blocks),
                None => format!("{}/?", r.blocks),
            },
            if r.lost_samples > 0 {
                r.lost_samples.to_string()
            } else {
                "—".into()
            },
            r.load_n,
            temp_cell(r),
            r.campaign.as_deref().unwrap_or("—"),
            r.repeat.map_or("—".into(), |x| x.to_string()),
            opt(r.onboard_mu0),
            opt(r.onboard_mu1),
            opt(r.host_mu0),
            opt(r.host_mu1),
        )?;
    }
    print_damaged(&damaged)?;
    if incomplete {
        outln!(
            "blocks: held/in the run (? = the run's end was not received); an incomplete run is \
             completed by `tribo pull RUN` while the rig holds it"
        )?;
    }
    temp_note(rows.iter())?;
    if any_lost {
        outln!(
            "lost: samples the rig's acquisition lost (its gap frames); fits refuse to cross a gap: \
             `tribo fit --longest-clean-stretch RUN` fits the longest stretch without one"
        )?;
    }
    Ok(())
}

/// What `~` in the temperature column means, when a listed run has it.
fn temp_note<'a>(mut rows: impl Iterator<Item = &'a CatalogRow>) -> anyhow::Result<()> {
    if rows.any(|r| r.temp_setpoint_c.is_none()) {
        outln!("°C: the heater's setpoint; ~22.4: the heater off, the plate read 22.4 °C")?;
    }
    Ok(())
}

/// A run's temperature in a listing: its setpoint, or `~` and the plate's reading with the heater
/// off (a campaign table's "heater off" cell).
fn temp_cell(r: &CatalogRow) -> String {
    match (r.temp_setpoint_c, r.temp_c) {
        (Some(t), _) => format!("{t:.1}"),
        (None, Some(t)) => format!("~{t:.1}"),
        (None, None) => "—".into(),
    }
}

/// The damaged run folders, each with its state and what to do.
fn print_damaged(damaged: &[(PathBuf, String)]) -> anyhow::Result<()> {
    for (p, why) in damaged {
        let name = p.file_name().map_or_else(
            || p.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        outln!("{name:<44} {DAMAGED:<10} {why}")?;
    }
    if !damaged.is_empty() {
        outln!(
            "damaged: the run's frame log cannot be read as it is; `tribo pull --salvage RUN` keeps \
             every intact record (with or without the rig) and fetches what is missing"
        )?;
    }
    Ok(())
}

/// `tribo runs --catalog URL`: the lab catalog's runs, across rigs and PCs.
fn lab(args: Args, url: &tribo_catalog::LabUrl) -> anyhow::Result<()> {
    if args.reindex {
        anyhow::bail!("--reindex rebuilds this PC's own catalog: leave --catalog out (or TRIBO_CATALOG unset), then `tribo sync`");
    }
    if args.status.as_deref() == Some(DAMAGED) {
        anyhow::bail!("the lab catalog holds no damaged run (a log that cannot be read is not synced): `tribo runs --status damaged` on the PC that holds it");
    }
    let lab = tribo_catalog::LabCatalog::connect(url)?;
    let f = filter(&args, args.status.clone());
    let rows = lab.lab_runs(&f)?;
    if args.json {
        let runs: Vec<serde_json::Value> = rows
            .iter()
            .map(|l| {
                // The run as `tribo runs --json` gives it, and where the lab has it.
                let mut j = run_json(&l.run.row);
                with_fields(
                    &mut j,
                    serde_json::json!({
                        "rig": l.run.rig_serial, "rig_run": l.run.rig_run, "pc": l.run.pc,
                        "path": l.run.log_dir, "log_sha256": l.run.log_sha256,
                        "log_bytes": l.run.log_bytes, "synced_at": l.synced_at,
                        "sample": l.run.row.sample, "lubricant": l.run.row.lubricant,
                        "onboard_mu0_se": l.run.onboard_mu0_se,
                        "onboard_mu1_se": l.run.onboard_mu1_se,
                    }),
                );
                j
            })
            .collect();
        crate::out::print_json(
            serde_json::json!({ "catalog": url.shown(), "runs": runs, "damaged": [] }),
        )?;
        return Ok(());
    }
    if args.paths {
        for l in rows {
            outln!("{}", l.run.log_dir)?;
        }
        return Ok(());
    }
    if rows.is_empty() {
        outln!(
            "no run matches in the lab catalog at {} (`tribo sync` sends a PC's runs)",
            url.shown()
        )?;
        return Ok(());
    }
    let opt = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.5}"));
    outln!(
        "{:<16} {:>6} {:<12} {:<10} {:>11} {:>7} {:>6} {:<12} {:>4} {:>9} {:>9} {:>9} {:>9}  run",
        "rig",
        "run",
        "pc",
        "status",
        "blocks",
        "load N",
        "°C",
        "campaign",
        "rep",
        "μ0 rig",
        "μ1 rig",
        "μ0 host",
        "μ1 host"
    )?;
    for l in &rows {
        let r = &l.run.row;
        outln!(
            "{:<16} {:>6} {:<12} {:<10} {:>11} {:>7.3} {:>6} {:<12} {:>4} {:>9} {:>9} {:>9} {:>9}  {}",
            l.run.rig_serial,
            l.run.rig_run,
            l.run.pc,
            r.status,
            match r.blocks_expected {
                Some(m) => format!("{}/{m}", r.blocks),
                None => format!("{}/?", r.blocks),
            },
            r.load_n,
            temp_cell(r),
            r.campaign.as_deref().unwrap_or("—"),
            r.repeat.map_or("—".into(), |x| x.to_string()),
            opt(r.onboard_mu0),
            opt(r.onboard_mu1),
            opt(r.host_mu0),
            opt(r.host_mu1),
            r.id,
        )?;
    }
    temp_note(rows.iter().map(|l| &l.run.row))?;
    outln!(
        "{} runs from the lab catalog at {}; `tribo pull --from-catalog SERIAL/RUN` fetches one's log from a shared folder",
        rows.len(),
        url.shown()
    )?;
    Ok(())
}

/// The catalog filter the arguments ask for, with `status` (`damaged` is not a catalog state).
fn filter(args: &Args, status: Option<String>) -> Filter {
    Filter {
        campaign: args.campaign.clone(),
        label: args.label.clone(),
        status,
        load_min: args.load.map(|l| l.0),
        load_max: args.load.map(|l| l.1),
        temp_min: args.temp.map(|t| t.0),
        temp_max: args.temp.map(|t| t.1),
        rig: args.rig.clone(),
        since: args.period.since.clone(),
        until: args.period.until.clone(),
    }
}
