//! `tribo campaign PLAN.toml`: a series of runs over loads × temperatures × repetitions (the
//! thesis's temperature studies), resumable after an interruption without redoing finished runs.
//!
//! ```toml
//! name = "pao-temperature"    # stored with every run; identifies finished points on resume
//! loads_n = [0.2, 0.4]
//! temps_c = [25, 60]          # optional: omit for runs with the heater off
//! repeats = 3
//! sample = "steel AISI 52100"   # optional: label, sample, lubricant
//! lubricant = "PAO 6"
//! # optional: rate_hz, max_duration_s, mass_kg, stiffness_n_per_m, x0_m,
//! #           ramp_c_per_min, settle_tol_c, settle_s, settle_timeout_s, prompt_load
//! ```
//!
//! The settle defaults are `tribo run`'s (`tribo_wire::limits`: within 0.5 °C for 30 s, giving up
//! after 1800 s). While the campaign runs, prompts included, a heartbeat keeps the rig's lease; every
//! way the campaign ends switches heater and magnet off.

use super::run::{abort_flag, print_outcome, LinkArgs, Ui};
use crate::link::session::{record_run, HeaterPlan, RunPlan};
use anyhow::{bail, Context};
use serde::Deserialize;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use tribo_catalog::LabCatalog;
use tribo_store::catalog::{Axis, RunCatalog, Value};
use tribo_store::run::{list_run_dirs, META_FILE};
use tribo_store::{Catalog, Filter, RunMeta, RunStatus};
use tribo_wire::{Configure, HostMsg};

/// A campaign plan (PLAN.toml).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    pub name: String,
    pub loads_n: Vec<f32>,
    #[serde(default)]
    pub temps_c: Vec<f32>,
    #[serde(default = "one")]
    pub repeats: u32,
    #[serde(default)]
    pub label: Option<String>,
    #[serde(default)]
    pub sample: Option<String>,
    #[serde(default)]
    pub lubricant: Option<String>,
    #[serde(default)]
    pub rate_hz: Option<u32>,
    #[serde(default)]
    pub max_duration_s: Option<f32>,
    #[serde(default)]
    pub mass_kg: Option<f32>,
    #[serde(default)]
    pub stiffness_n_per_m: Option<f32>,
    #[serde(default)]
    pub x0_m: Option<f32>,
    #[serde(default = "ramp")]
    pub ramp_c_per_min: f32,
    #[serde(default = "tol")]
    pub settle_tol_c: f32,
    #[serde(default = "settle")]
    pub settle_s: f64,
    #[serde(default = "settle_timeout")]
    pub settle_timeout_s: f64,
    /// Ask the operator to turn the load knob when the load changes (on a terminal).
    #[serde(default = "yes")]
    pub prompt_load: bool,
}

fn one() -> u32 {
    1
}
fn ramp() -> f32 {
    10.0
}
fn tol() -> f32 {
    tribo_wire::limits::SETTLE_TOL_C
}
fn settle() -> f64 {
    tribo_wire::limits::SETTLE_S
}
fn settle_timeout() -> f64 {
    tribo_wire::limits::SETTLE_TIMEOUT_S
}
fn yes() -> bool {
    true
}

/// One run of a campaign.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    pub temp_c: Option<f32>,
    pub load_n: f32,
    pub repeat: u32,
}

impl Plan {
    pub fn load(path: &Path) -> anyhow::Result<Plan> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the plan {}", path.display()))?;
        // A plan that cannot be right is a usage error (status 2), as a wrong command line is.
        let p: Plan = toml::from_str(&text).map_err(|e| {
            crate::exit::Usage(format!("the campaign plan {}: {e}", path.display()))
        })?;
        p.check()
            .map_err(|e| crate::exit::Usage(format!("{}: {e:#}", path.display())))?;
        Ok(p)
    }

    fn check(&self) -> anyhow::Result<()> {
        super::run::check_settle(self.settle_tol_c, self.settle_s, self.settle_timeout_s).map_err(
            |why| {
                anyhow::anyhow!(
                    "settle_tol_c = {}, settle_s = {}, settle_timeout_s = {}: {why}",
                    self.settle_tol_c,
                    self.settle_s,
                    self.settle_timeout_s
                )
            },
        )?;
        if self.name.trim().is_empty() {
            bail!("`name` must not be empty (it identifies the campaign's runs when resuming)");
        }
        if self.loads_n.is_empty() || self.repeats == 0 {
            bail!("nothing to do: give at least one load in `loads_n` and `repeats` ≥ 1");
        }
        for p in self.points() {
            self.config(p.load_n).validate().map_err(|f| {
                anyhow::anyhow!(
                    "load {} N: {} is out of the rig's range",
                    p.load_n,
                    crate::link::field_name(f)
                )
            })?;
            if let Some(t) = p.temp_c {
                tribo_wire::HeaterSetpoint {
                    setpoint_c: t,
                    ramp_c_per_min: self.ramp_c_per_min,
                }
                .validate()
                .map_err(|f| {
                    anyhow::anyhow!(
                        "temperature {t} °C: {} is out of the rig's range",
                        crate::link::field_name(f)
                    )
                })?;
            }
        }
        Ok(())
    }

    /// Every run, temperatures outermost (heating is the slow part), then loads, then repetitions.
    pub fn points(&self) -> Vec<Point> {
        let temps: Vec<Option<f32>> = if self.temps_c.is_empty() {
            vec![None]
        } else {
            self.temps_c.iter().map(|t| Some(*t)).collect()
        };
        let mut v = vec![];
        for t in &temps {
            for l in &self.loads_n {
                for r in 1..=self.repeats {
                    v.push(Point {
                        temp_c: *t,
                        load_n: *l,
                        repeat: r,
                    });
                }
            }
        }
        v
    }

    /// The rig constants the plan leaves out, for which the real rig's values stand in (said at the
    /// start and recorded in every run's metadata).
    pub fn defaults(&self) -> Vec<String> {
        let real = Configure::real_rig(0.3);
        [
            (
                "mass_kg",
                self.mass_kg.is_none(),
                format!("{} kg", real.rig.mass_kg),
            ),
            (
                "stiffness_n_per_m",
                self.stiffness_n_per_m.is_none(),
                format!("{} N/m", real.rig.stiffness_n_per_m),
            ),
            (
                "x0_m",
                self.x0_m.is_none(),
                format!("{} m", real.initial_amplitude_m),
            ),
        ]
        .into_iter()
        .filter(|(_, missing, _)| *missing)
        .map(|(k, _, v)| format!("{k}={v}"))
        .collect()
    }

    pub fn config(&self, load: f32) -> Configure {
        let mut c = Configure::real_rig(load);
        if let Some(v) = self.rate_hz {
            c.sample_rate_hz = v;
        }
        if let Some(v) = self.max_duration_s {
            c.max_duration_s = v;
        }
        if let Some(v) = self.mass_kg {
            c.rig.mass_kg = v;
        }
        if let Some(v) = self.stiffness_n_per_m {
            c.rig.stiffness_n_per_m = v;
        }
        if let Some(v) = self.x0_m {
            c.initial_amplitude_m = v;
        }
        c
    }
}

/// The points of `plan` already done: a complete run of this campaign in `store` with the same
/// load, temperature setpoint and repetition.
pub fn finished(plan: &Plan, store: &Path) -> anyhow::Result<Vec<Point>> {
    // What the metadata claims, checked against the frame log: a run whose log was damaged or
    // cut since it was taken is not done (it is taken again; `tribo table` names it).
    let metas: Vec<RunMeta> = list_run_dirs(store)?
        .iter()
        .filter_map(|d| {
            let m = toml::from_str::<RunMeta>(&std::fs::read_to_string(d.join(META_FILE)).ok()?)
                .ok()?;
            let ours = m.status == RunStatus::Complete
                && m.campaign.as_deref() == Some(plan.name.as_str());
            (ours && tribo_store::Run::open(d).is_ok_and(|r| r.is_complete())).then_some(m)
        })
        .collect();
    Ok(plan
        .points()
        .into_iter()
        .filter(|p| {
            metas.iter().any(|m| {
                m.repeat == Some(p.repeat)
                    && (m.load_n - p.load_n as f64).abs() < 5e-4
                    && match (m.temp_setpoint_c, p.temp_c) {
                        (None, None) => true,
                        (Some(a), Some(b)) => (a - b as f64).abs() < 0.05,
                        _ => false,
                    }
            })
        })
        .collect())
}

/// `tribo campaign PLAN` with the `--store` and `--port` this command was given: what takes the
/// campaign up where it stopped (without them, another store's runs would count, or none).
fn resume_command(args: &Args) -> String {
    let mut c = format!("tribo campaign {}", args.plan.display());
    if let Some(s) = &args.link.store {
        c.push_str(&format!(" --store {}", s.display()));
    }
    if let Some(p) = &args.link.port {
        c.push_str(&format!(" --port {p}"));
    }
    if args.no_prompt {
        c.push_str(" --no-prompt");
    }
    c
}

/// Arguments of `tribo campaign`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The plan (TOML: name, loads_n, temps_c, repeats, …).
    pub plan: PathBuf,
    #[command(flatten)]
    pub link: LinkArgs,
    /// Never ask for the load knob (e.g. a virtual rig, or the load is already right).
    #[arg(long)]
    pub no_prompt: bool,
    /// Show what would be run and what is already done, and stop.
    #[arg(long)]
    pub dry_run: bool,
    /// The lab catalog (postgres://USER@HOST[:PORT]/DATABASE, default: $TRIBO_CATALOG): once the
    /// runs are taken they are synced to it (as `tribo sync`), and the table at the end is the
    /// lab's: the campaign's runs on every rig that took part. No password in the URL: it comes
    /// from PGPASSWORD or ~/.pgpass.
    #[arg(long, value_name = "URL")]
    pub catalog: Option<String>,
    /// No progress bar or messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let plan = Plan::load(&args.plan)?;
    let store = args.link.store();
    let done = finished(&plan, &store)?;
    let todo: Vec<Point> = plan
        .points()
        .into_iter()
        .filter(|p| !done.contains(p))
        .collect();
    println!(
        "campaign {:?}: {} runs planned, {} already done, {} to take",
        plan.name,
        plan.points().len(),
        done.len(),
        todo.len()
    );
    let defaults = plan.defaults();
    if !defaults.is_empty() {
        println!(
            "  the plan does not give {}: the real rig's values stand in (recorded with every run)",
            defaults.join(", ")
        );
    }
    if args.dry_run || todo.is_empty() {
        for p in &todo {
            println!(
                "  to do: load {} N, {}, repetition {}",
                p.load_n,
                p.temp_c.map_or("heater off".into(), |t| format!("{t} °C")),
                p.repeat
            );
        }
        // The campaign's runs that are stored but not whole: taken again, and said why.
        let left = crate::archive::left_out(
            &store,
            &Filter {
                campaign: Some(plan.name.clone()),
                ..Default::default()
            },
        )?;
        for l in &left {
            println!("  not done (to take again): {}: {}", l.dir.display(), l.why);
        }
        if todo.is_empty() {
            print_table(&plan, &store, args.catalog.as_deref(), args.quiet)?;
        }
        return Ok(());
    }
    let abort = abort_flag();
    // How to take the campaign up again: the same plan, store and port as this command line.
    let again = resume_command(&args);
    args.link.writable_store()?;
    let (mut link, info) = args.link.connect_and_announce(args.quiet)?;
    // Heartbeats while the campaign runs (prompts included); every exit leaves the rig safe.
    let _hold = link.hold();
    let mut last_load: Option<f32> = None;
    for (i, p) in todo.iter().enumerate() {
        if abort.load(Ordering::Relaxed) {
            break;
        }
        if last_load != Some(p.load_n)
            && plan.prompt_load
            && !args.no_prompt
            && std::io::stdin().is_terminal()
        {
            crate::errln!("set the load knob to {} N, then press Enter", p.load_n);
            let mut s = String::new();
            std::io::stdin().read_line(&mut s)?;
        }
        last_load = Some(p.load_n);
        if !args.quiet {
            crate::errln!(
                "[{}/{}] load {} N, {}, repetition {}/{}",
                i + 1,
                todo.len(),
                p.load_n,
                p.temp_c.map_or("heater off".into(), |t| format!("{t} °C")),
                p.repeat,
                plan.repeats
            );
        }
        let mut rp = RunPlan::new(plan.config(p.load_n));
        rp.heater = p.temp_c.map(|t| HeaterPlan {
            setpoint_c: t,
            ramp_c_per_min: plan.ramp_c_per_min,
            tolerance_c: plan.settle_tol_c,
            settle_s: plan.settle_s,
            timeout_s: plan.settle_timeout_s,
        });
        rp.keep_heater = true;
        rp.label = plan.label.clone();
        rp.sample = plan.sample.clone();
        rp.lubricant = plan.lubricant.clone();
        rp.campaign = Some(plan.name.clone());
        rp.repeat = Some(p.repeat);
        rp.defaults = defaults.clone();
        let mut ui = Ui::new(args.quiet);
        let o = record_run(&mut link, &info, &store, &rp, &abort, &mut |e| ui.on(e));
        ui.finish();
        let o = o.with_context(|| {
            format!(
                "campaign {:?} stopped; run `{again}` again to resume",
                plan.name
            )
        })?;
        print_outcome(&o)?;
        if let Some(e) = o.incomplete() {
            // A run of the campaign is not stored whole: stop, say how to resume, exit status 3.
            return Err(anyhow::Error::new(e).context(format!(
                "campaign interrupted: run `{again}` again to resume where it stopped (an \
                 incomplete run is taken again)"
            )));
        }
        if o.aborted || abort.load(Ordering::Relaxed) {
            return Err(crate::exit::Interrupted(format!(
                "campaign interrupted after {} of {} runs: run `{again}` again to resume where it stopped",
                i + usize::from(!o.aborted),
                todo.len()
            ))
            .into());
        }
        if o.link_lost.is_some() {
            println!("campaign interrupted: run `{again}` again to resume where it stopped");
            return Ok(());
        }
    }
    let _ = link.command(HostMsg::HeaterOff);
    if abort.load(Ordering::Relaxed) {
        return Err(crate::exit::Interrupted(format!(
            "campaign interrupted: run `{again}` again to resume"
        ))
        .into());
    }
    print_table(&plan, &store, args.catalog.as_deref(), args.quiet)
}

/// The campaign's tables (μ0 and μ1, host fit): the lab's when a lab catalog is given (this
/// store synced to it first), else the store's own.
fn print_table(
    plan: &Plan,
    store: &Path,
    catalog: Option<&str>,
    quiet: bool,
) -> anyhow::Result<()> {
    let f = Filter {
        campaign: Some(plan.name.clone()),
        ..Default::default()
    };
    let (cat, what): (Box<dyn RunCatalog>, _) = match super::sync::lab_url(catalog)? {
        Some(url) => {
            // A server that cannot be reached is waited for a little, not a sync's minute: the
            // runs are safe in the store, and `tribo sync` sends them later.
            let opts = tribo_catalog::SyncOptions {
                wait: std::time::Duration::from_secs(10),
                ..Default::default()
            };
            let synced = tribo_catalog::sync(store, &url, &opts, &mut |_, _| {}).and_then(|r| {
                if !quiet {
                    crate::errln!(
                        "synced to {}: {} new, {} updated, {} already there",
                        url.shown(),
                        r.pushed.inserted,
                        r.pushed.updated,
                        r.unchanged
                    );
                }
                LabCatalog::connect(&url)
            });
            match synced {
                Ok(lab) => (Box::new(lab), "every rig in the lab catalog"),
                Err(e) => {
                    // The runs are whole and stored: show this PC's table, then say what failed.
                    print_tables(&Catalog::open(store)?, &f, "this PC's runs")?;
                    return Err(anyhow::Error::new(e).context(format!(
                        "the campaign's runs are stored in {}, but syncing them to the lab catalog \
                         failed: run `tribo sync` when {} can be reached",
                        store.display(),
                        url.shown()
                    )));
                }
            }
        }
        None => (Box::new(Catalog::open(store)?), "this PC's runs"),
    };
    print_tables(cat.as_ref(), &f, what)
}

fn print_tables(cat: &dyn RunCatalog, f: &Filter, what: &str) -> anyhow::Result<()> {
    for v in [Value::Mu0, Value::Mu1] {
        let t = cat.table(Axis::Temp, Axis::Load, v, f)?;
        if !t.rows.is_empty() {
            println!(
                "{} (host fit, mean ± sd over repetitions; {what}):",
                if v == Value::Mu0 { "μ0" } else { "μ1" }
            );
            print!("{}", t.render());
        }
    }
    Ok(())
}
