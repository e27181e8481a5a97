//! `tribo sync`: pushes this PC's runs to the lab catalog (PostgreSQL); reading it and fetching a
//! run's log from it are in [`crate::lab`].

use crate::lab::lab_url;
use crate::outln;
use anyhow::bail;
use std::path::PathBuf;
use std::time::Duration;
use tribo_catalog::SyncOptions;

/// `tribo sync --help`: what it does, in full.
pub const LONG_ABOUT: &str = "Push this PC's runs to the lab catalog (PostgreSQL).

Pushes every run of this PC's store to the lab catalog, a PostgreSQL database many PCs share: its \
metadata, the on-board and host results with their ±, its campaign, the rig's serial number, the \
frame log's SHA-256 and where the log is. The logs themselves stay where they are.

Safe to run at any time, as often as wanted, from every PC at once: a run the lab already holds as \
this PC has it is not sent again; runs go in batches, each one transaction, so a sync killed midway \
leaves whole runs and the next one sends the rest; a run completed later (by `tribo pull`) updates \
its row; a fuller copy of a run from another PC is never replaced by a shorter one. A server that \
restarts, or a network that drops, is waited for (--wait).

The first sync against an empty database creates the catalog's tables: run it once as the \
catalog's owner (README, \"A catalog for the whole lab\"). Then `tribo runs`, `table` and `report \
CAMPAIGN` read the lab with --catalog URL (or TRIBO_CATALOG), across rigs (--rig SERIAL), and \
`tribo pull --from-catalog SERIAL/RUN` copies a run from a shared folder.

Example, the password in ~/.pgpass (labserver:5432:tribo:rig2:PASSWORD, mode 0600):
  tribo sync --catalog 'postgres://rig2@labserver/tribo?sslmode=verify-full&sslrootcert=lab-ca.pem'";

/// Arguments of `tribo sync` (what it does: [`LONG_ABOUT`]).
#[derive(clap::Args, Debug)]
#[command(
    after_long_help = "--json prints one JSON object: {\"local\", \"inserted\", \"updated\", \"kept\", \"unchanged\", \"fuller_elsewhere\", \"reconnects\", \"skipped\": [{\"path\", \"why\"}]}."
)]
pub struct Args {
    /// Run store directory (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// The lab catalog: `postgres://USER@HOST[:PORT]/DATABASE[?sslmode=verify-full&sslrootcert=CA.pem]`
    /// (default: $TRIBO_CATALOG). No password in it: it comes from PGPASSWORD or ~/.pgpass.
    #[arg(long, value_name = "URL")]
    pub catalog: Option<String>,
    /// This PC's name in the lab catalog (default: its host name).
    #[arg(long)]
    pub pc: Option<String>,
    /// The store's folder as the other PCs reach it, when it is on a shared folder (e.g.
    /// `\\labserver\runs\rig2` or `/mnt/lab/rig2`): recorded as where the logs are, so that
    /// `tribo pull --from-catalog` works from any PC (default: the store's path on this PC).
    #[arg(long, value_name = "DIR")]
    pub shared_as: Option<PathBuf>,
    /// Runs sent per transaction.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub batch: u32,
    /// Seconds to wait for a server that cannot be reached (down, restarting, network cut)
    /// before giving up; what was sent stays.
    #[arg(long, default_value_t = 60)]
    pub wait: u64,
    /// Print one JSON object (set by the global `--json`; its shape is in `after_long_help`).
    #[arg(skip)]
    pub json: bool,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let store = args
        .store
        .clone()
        .unwrap_or_else(tribo_store::default_store_dir);
    let Some(url) = lab_url(args.catalog.as_deref())? else {
        bail!(
            "no lab catalog given: `tribo sync --catalog postgres://USER@HOST/DATABASE` or set \
             TRIBO_CATALOG (README, \"A catalog for the whole lab\")"
        );
    };
    let mut opts = SyncOptions {
        batch: args.batch as usize,
        wait: Duration::from_secs(args.wait),
        shared_as: args.shared_as.clone(),
        ..SyncOptions::default()
    };
    if let Some(pc) = &args.pc {
        opts.pc = pc.clone();
    }
    let quiet = args.quiet || args.json;
    if !quiet {
        crate::errln!(
            "syncing {} to {} as PC {:?}",
            store.display(),
            url.shown(),
            opts.pc
        );
    }
    let mut last = std::time::Instant::now();
    let r = tribo_catalog::sync(&store, &url, &opts, &mut |done, todo| {
        if !quiet && (done == todo || last.elapsed() > Duration::from_secs(1)) {
            crate::errln!("  {done} of {todo} runs sent");
            last = std::time::Instant::now();
        }
    })?;
    if args.json {
        let skipped: Vec<serde_json::Value> = r
            .skipped
            .iter()
            .map(|(p, why)| serde_json::json!({ "path": p, "why": why }))
            .collect();
        crate::out::print_json(serde_json::json!({
            "catalog": url.shown(), "pc": opts.pc, "local": r.local,
            "inserted": r.pushed.inserted, "updated": r.pushed.updated, "kept": r.pushed.kept,
            "unchanged": r.unchanged, "fuller_elsewhere": r.fuller_elsewhere,
            "reconnects": r.reconnects, "skipped": skipped,
        }))?;
        return not_synced(&r.skipped);
    }
    outln!(
        "{} local runs: {} new in the lab catalog, {} updated, {} already there as here{}",
        r.local,
        r.pushed.inserted,
        r.pushed.updated,
        r.unchanged,
        match r.fuller_elsewhere + r.pushed.kept {
            0 => String::new(),
            n => format!(
                ", {n} kept as the lab has them (as full a copy or fuller, from another PC)"
            ),
        }
    )?;
    if r.reconnects > 0 {
        outln!(
            "the server was lost {} time(s) and waited for; every batch was sent whole",
            r.reconnects
        )?;
    }
    for (p, why) in &r.skipped {
        outln!("not synced: {}: {why}", p.display())?;
    }
    not_synced(&r.skipped)
}

/// A sync that left runs of this PC out (a damaged log, a run of no known rig) finished but is
/// not whole: status 3, the runs having been named each with why.
fn not_synced(skipped: &[(std::path::PathBuf, String)]) -> anyhow::Result<()> {
    if skipped.is_empty() {
        return Ok(());
    }
    Err(crate::exit::Incomplete(format!(
        "{} run{} of this PC not synced (listed with why): repair {} (a damaged log: `tribo pull \
         --salvage RUN`) and run `tribo sync` again",
        skipped.len(),
        if skipped.len() == 1 { "" } else { "s" },
        if skipped.len() == 1 { "it" } else { "them" }
    ))
    .into())
}
