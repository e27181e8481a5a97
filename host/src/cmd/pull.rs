//! `tribo pull [RUN]`: completes a stored run from the rig — the stored copy of the rig's last run
//! (found by the rig's serial number and run number), or the run folder RUN — fetching exactly the
//! blocks it lacks and the run's end, with retries while the rig answers; or fetches the rig's last
//! run into a new folder. Exits 3 when the run is still not whole (the rig no longer holds part of
//! it, or stopped answering), saying exactly what is missing and why.

use crate::link::args::LinkArgs;
use crate::link::session::{pull_run, RunNotHeld};
use crate::ui::{print_outcome, Ui};
use std::path::PathBuf;

/// Arguments of `tribo pull`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig to pull from, and the run store.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Run folder to complete (default: the stored copy of the rig's last run, or a new folder).
    pub run: Option<PathBuf>,
    /// Repair a damaged frame log: keep every record whose checksum holds, wherever the damage is
    /// (the damaged file is kept beside it as frames.log.damaged), then fetch what is missing.
    #[arg(long)]
    pub salvage: bool,
    /// Fetch this run's log from where the lab catalog says it is (a shared folder) instead of
    /// from a rig: a run's name or SERIAL/RUN, as `tribo runs --catalog URL` lists them. The log's
    /// SHA-256 is checked against the catalog's.
    #[arg(long, value_name = "ID", conflicts_with_all = ["run", "salvage"])]
    pub from_catalog: Option<String>,
    /// The lab catalog to fetch the run from instead of a rig.
    #[arg(long, value_name = "URL", help = super::common::CATALOG_HELP)]
    pub catalog: Option<String>,
    /// No progress bar or messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(id) = &args.from_catalog {
        let said = crate::lab::pull_from_catalog(args.catalog.as_deref(), id, &args.link.store())?;
        crate::outln!("{said}")?;
        return Ok(());
    }
    let (mut link, info) = match (args.link.connect(), &args.run) {
        (Ok(c), _) => c,
        // No rig to fetch from: a salvage still repairs the log here and says what is missing.
        (Err(e), Some(dir)) if args.salvage => return salvage_offline(dir, e),
        (Err(e), _) => return Err(e),
    };
    let mut ui = Ui::new(args.quiet);
    let o = pull_run(
        &mut link,
        &info,
        &args.link.store(),
        args.run.as_deref(),
        args.salvage,
        &mut |p| ui.on(p),
    );
    ui.finish();
    let o = match (o, &args.run) {
        (Ok(o), _) => o,
        // The rig has moved on: the folder (repaired, with --salvage) is all there is of the run.
        (Err(e), Some(dir)) if e.downcast_ref::<RunNotHeld>().is_some() => {
            return settle_folder(dir, &e)
        }
        (Err(e), _) => return Err(e),
    };
    print_outcome(&o)?;
    match o.incomplete() {
        // Finished, but the run is not stored whole: exit status 3.
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

/// `--salvage` with no rig reachable: the log is repaired (every intact record kept, the damaged
/// file beside it), the catalog updated, and what is missing said; status 3, since the run is not
/// whole until the rig gives the rest.
fn salvage_offline(dir: &std::path::Path, why: anyhow::Error) -> anyhow::Result<()> {
    let (w, recovery) = tribo_store::RunWriter::resume(dir, true)
        .map_err(|e| anyhow::anyhow!("cannot salvage {}: {e}", dir.display()))?;
    drop(w);
    if let Some(r) = recovery {
        crate::errln!("{}: {r}", dir.display());
    }
    let run = tribo_store::Run::open(dir)?;
    let summary = run.completeness().summary();
    if let Some(store) = dir.parent() {
        if let Ok(cat) = tribo_store::RunCatalog::open(store) {
            let _ = cat.upsert(&run);
        }
    }
    crate::outln!("{}: salvaged offline: {summary}", dir.display())?;
    if run.is_complete() {
        // Every record of the run survived the damage: it is whole, nothing to fetch.
        return Ok(());
    }
    Err(crate::exit::Incomplete(format!(
        "{}: salvaged, but no rig could be reached to fetch what is missing ({}); `tribo pull {}` \
         fetches it while the rig holds the run",
        dir.display(),
        crate::exit::chain_text(why.as_ref()),
        dir.display()
    ))
    .into())
}

/// The rig no longer holds the run of folder `dir` (`why`): what the folder holds (resumed, and
/// repaired with `--salvage`) is all there is. Status 0 when that is the whole run, else 3 saying
/// what is missing for good.
fn settle_folder(dir: &std::path::Path, why: &anyhow::Error) -> anyhow::Result<()> {
    let run = tribo_store::Run::open(dir)?;
    if let Some(store) = dir.parent() {
        if let Ok(cat) = tribo_store::RunCatalog::open(store) {
            let _ = cat.upsert(&run);
        }
    }
    let summary = run.completeness().summary();
    crate::outln!("{}: {summary}", dir.display())?;
    if run.is_complete() {
        crate::errln!("note: {why}; the folder holds the whole run");
        return Ok(());
    }
    Err(crate::exit::Incomplete(format!("{why}; the folder stays {summary}")).into())
}
