//! The lab catalog as the commands reach it: its URL (`--catalog`, else `TRIBO_CATALOG`), the
//! catalog a reading command was pointed at, and a run copied from where the lab catalog says
//! its log is (`tribo pull --from-catalog`).

use anyhow::{bail, Context};
use std::path::{Path, PathBuf};
use tribo_catalog::{AnyCatalog, LabCatalog, LabUrl};

/// The lab catalog's URL (`--catalog`, else `TRIBO_CATALOG`), parsed.
pub fn lab_url(catalog: Option<&str>) -> anyhow::Result<Option<LabUrl>> {
    Ok(match tribo_catalog::lab_url(catalog) {
        Some(u) => Some(LabUrl::parse(&u)?),
        None => None,
    })
}

/// The catalog a reading command was pointed at: the lab's (`--catalog`, `TRIBO_CATALOG`), else
/// the store's own.
pub fn open_catalog(catalog: Option<&str>, store: &Path) -> anyhow::Result<Box<dyn AnyCatalog>> {
    Ok(tribo_catalog::open(catalog, store)?)
}

/// `tribo pull --from-catalog ID`: copies the run the lab catalog names (a run folder's name, or
/// `SERIAL/RUN`) from where its log is (a shared folder, or this PC) into `store`, checking the
/// log's SHA-256. Returns the line that says what it did.
pub fn pull_from_catalog(catalog: Option<&str>, id: &str, store: &Path) -> anyhow::Result<String> {
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
            return Ok(format!("{}: already here, the same log", dest.display()));
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
    tribo_store::RunCatalog::open(store)?.upsert(&run)?;
    Ok(format!(
        "{}: run {}/{} from PC {:?} ({}), {}",
        dest.display(),
        r.rig_serial,
        r.rig_run,
        r.pc,
        from.display(),
        run.completeness().summary()
    ))
}
