//! `tribo campaign PLAN.toml`: a series of runs over loads × temperatures × repetitions, resumable
//! after an interruption without redoing finished runs (the plan: [`crate::campaign`]).

use crate::campaign::{finished, Plan, Point};
use crate::link::args::LinkArgs;
use crate::link::session::{record_run, HeaterPlan, RunPlan};
use crate::ui::{abort_flag, print_outcome, Ui};
use anyhow::Context;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use tribo_catalog::LabCatalog;
use tribo_store::catalog::{AnyCatalog, Axis, Value};
use tribo_store::{Filter, RunCatalog};
use tribo_wire::HostMsg;

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
    /// The rig to run the campaign on, and the run store.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Never ask for the load knob (e.g. a virtual rig, or the load is already right).
    #[arg(long)]
    pub no_prompt: bool,
    /// Show what would be run and what is already done, and stop.
    #[arg(long)]
    pub dry_run: bool,
    /// The lab catalog (`postgres://USER@HOST[:PORT]/DATABASE`, default: $TRIBO_CATALOG): once the
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
    let (cat, what): (Box<dyn AnyCatalog>, _) = match crate::lab::lab_url(catalog)? {
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
                    print_tables(&RunCatalog::open(store)?, &f, "this PC's runs")?;
                    return Err(anyhow::Error::new(e).context(format!(
                        "the campaign's runs are stored in {}, but syncing them to the lab catalog \
                         failed: run `tribo sync` when {} can be reached",
                        store.display(),
                        url.shown()
                    )));
                }
            }
        }
        None => (Box::new(RunCatalog::open(store)?), "this PC's runs"),
    };
    print_tables(cat.as_ref(), &f, what)
}

fn print_tables(cat: &dyn AnyCatalog, f: &Filter, what: &str) -> anyhow::Result<()> {
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
