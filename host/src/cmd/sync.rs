//! `tribo sync`: pushes this PC's runs to the lab catalog (PostgreSQL), and what the other
//! commands share to read it (`--catalog URL`, `TRIBO_CATALOG`) and to fetch a run's log from
//! where the catalog says it is (`tribo pull --from-catalog ID`).

use crate::outln;
use anyhow::{bail, Context};
use std::path::{Path, PathBuf};
use std::time::Duration;
use tribo_catalog::{LabCatalog, LabUrl, RunCatalog, SyncOptions};

/// The help of `--catalog` in `runs`, `table`, `report` and `pull`.
pub const CATALOG_HELP: &str = "The lab catalog to read instead of this PC's own: a PostgreSQL URL, postgres://USER@HOST[:PORT]/DATABASE[?sslmode=verify-full&sslrootcert=CA.pem] (default: $TRIBO_CATALOG, else the store's SQLite catalog). No password in it: it comes from PGPASSWORD or ~/.pgpass";

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
pub struct Args {
    /// Run store directory (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
    /// The lab catalog: postgres://USER@HOST[:PORT]/DATABASE[?sslmode=verify-full&sslrootcert=CA.pem]
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
    /// Print one JSON object: `{"local", "inserted", "updated", "kept", "unchanged",
    /// "fuller_elsewhere", "reconnects", "skipped": [{"path", "why"}]}`.
    #[arg(long)]
    pub json: bool,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// The lab catalog's URL (`--catalog`, else `TRIBO_CATALOG`), parsed.
pub fn lab_url(catalog: Option<&str>) -> anyhow::Result<Option<LabUrl>> {
    Ok(match tribo_catalog::lab_url(catalog) {
        Some(u) => Some(LabUrl::parse(&u)?),
        None => None,
    })
}

/// The catalog a reading command was pointed at: the lab's (`--catalog`, `TRIBO_CATALOG`), else
/// the store's own.
pub fn open_catalog(catalog: Option<&str>, store: &Path) -> anyhow::Result<Box<dyn RunCatalog>> {
    Ok(tribo_catalog::open(catalog, store)?)
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

/// `tribo pull --from-catalog ID`: copies the run the lab catalog names (a run folder's name, or
/// `SERIAL/RUN`) from where its log is (a shared folder, or this PC) into `store`, checking the
/// log's SHA-256.
pub fn pull_from_catalog(catalog: Option<&str>, id: &str, store: &Path) -> anyhow::Result<()> {
    let Some(url) = lab_url(catalog)? else {
        bail!(
            "--from-catalog needs the lab catalog: give --catalog postgres://USER@HOST/DATABASE or \
             set TRIBO_CATALOG"
        );
    };
    let lab = LabCatalog::connect(&url)?;
    let found = lab.find(id)?;
    let r = match found.as_slice() {
        [] => bail!(
            "no run {id:?} in {}: give a run's name or SERIAL/RUN as `tribo runs --catalog URL` lists them",
            lab.describe()
        ),
        [r] => &r.run,
        many => bail!(
            "{id:?} names {} runs in the lab catalog ({}): give SERIAL/RUN",
            many.len(),
            many.iter()
                .map(|r| format!("{}/{}", r.run.rig_serial, r.run.rig_run))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    };
    let from = PathBuf::from(&r.log_dir);
    let log = from.join(tribo_store::run::LOG_FILE);
    if !log.is_file() {
        bail!(
            "run {}/{} ({}) has its log on PC {:?} at {}, which this PC cannot reach: copy the run \
             folder by hand, or keep the store on a shared folder and sync it with --shared-as",
            r.rig_serial,
            r.rig_run,
            r.row.id,
            r.pc,
            from.display()
        );
    }
    let hash = tribo_catalog::sync::file_sha256(&log)
        .with_context(|| format!("reading {}", log.display()))?;
    if hash != r.log_sha256 {
        bail!(
            "the log at {} is not the one the lab catalog holds (SHA-256 {} there, {} in the catalog): \
             it changed since PC {:?} last synced; run `tribo sync` there first",
            log.display(),
            &hash[..12],
            &r.log_sha256[..12.min(r.log_sha256.len())],
            r.pc
        );
    }
    let dest = store.join(&r.row.id);
    if dest.join(tribo_store::run::LOG_FILE).is_file() {
        let here = tribo_catalog::sync::file_sha256(&dest.join(tribo_store::run::LOG_FILE))?;
        if here == r.log_sha256 {
            outln!("{}: already here, the same log", dest.display())?;
            return Ok(());
        }
        bail!(
            "{} exists with another log: move it away first, or pull into another --store",
            dest.display()
        );
    }
    // Copied beside, then renamed: a copy cut short never looks like a run.
    let part = store.join(format!(".{}.part", r.row.id));
    let _ = std::fs::remove_dir_all(&part);
    std::fs::create_dir_all(&part).with_context(|| format!("creating {}", part.display()))?;
    for e in std::fs::read_dir(&from).with_context(|| format!("reading {}", from.display()))? {
        let e = e?;
        if e.file_type()?.is_file() {
            std::fs::copy(e.path(), part.join(e.file_name()))
                .with_context(|| format!("copying {}", e.path().display()))?;
        }
    }
    let copied = tribo_catalog::sync::file_sha256(&part.join(tribo_store::run::LOG_FILE))?;
    if copied != r.log_sha256 {
        let _ = std::fs::remove_dir_all(&part);
        bail!(
            "the copy of {} does not match the catalog's SHA-256 (the log changed during the copy): try again",
            log.display()
        );
    }
    std::fs::rename(&part, &dest).with_context(|| format!("renaming to {}", dest.display()))?;
    let run = tribo_store::Run::open(&dest)?;
    tribo_store::Catalog::open(store)?.upsert(&run)?;
    outln!(
        "{}: run {}/{} from PC {:?} ({}), {}",
        dest.display(),
        r.rig_serial,
        r.rig_run,
        r.pc,
        from.display(),
        run.completeness().summary()
    )?;
    Ok(())
}
