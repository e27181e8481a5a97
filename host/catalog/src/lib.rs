//! The lab catalog: every run of every rig and PC of a lab in one PostgreSQL database, next to
//! each PC's own run catalog (SQLite, `tribo-store`), which stays the default and needs nothing set up.
//!
//! * [`AnyCatalog`] is the one catalog interface: [`tribo_store::RunCatalog`] (the run catalog, a
//!   store's SQLite file) and [`LabCatalog`] (the lab catalog, a server) both implement it; [`open`] gives the one a command was
//!   pointed at (`--catalog URL`, `TRIBO_CATALOG`, else the store's own).
//! * [`url`]: the server's address, without a password (refused on the command line), with the
//!   password from `PGPASSWORD` or the password file, TLS (rustls) when the URL asks for it.
//! * [`schema`]: versioned migrations, run on first use under a lock, refused against a newer
//!   schema.
//! * [`sync`]: pushes a PC's runs (metadata, on-board and host results with their ±, campaign,
//!   rig serial, the frame log's SHA-256 and where it lives): idempotent, resumable, safe from
//!   many PCs at once (one transaction per batch, one row per rig serial and rig run number).
//!
//! The tests' PostgreSQL server and synthetic runs are in `tribo-testkit` (a dev-dependency).
#![warn(missing_docs)]

pub mod lab;
pub mod schema;
pub mod sync;
pub mod url;

pub use lab::{LabCatalog, LabRow, LabRun, PushCounts};
pub use sync::{sync, SyncOptions, SyncReport};
pub use tribo_store::AnyCatalog;
pub use url::LabUrl;

use std::path::Path;
use tribo_store::{ErrorKind, StoreError};

/// The catalog's results: its errors are the store's ([`StoreError`]), one kind for both catalogs.
pub type Result<T, E = StoreError> = std::result::Result<T, E>;

/// A catalog error with nothing underneath.
pub(crate) fn err(msg: impl Into<String>) -> StoreError {
    StoreError::new(ErrorKind::Catalog, msg)
}

/// A catalog URL that cannot be right, as given on the command line or in $TRIBO_CATALOG
/// (status 2, as for any usage error).
pub(crate) fn usage(msg: impl Into<String>) -> StoreError {
    StoreError::new(ErrorKind::Usage, msg)
}

/// [`usage`] caused by `e`.
pub(crate) fn caused_usage(
    msg: impl Into<String>,
    e: impl std::error::Error + Send + Sync + 'static,
) -> StoreError {
    StoreError::caused(ErrorKind::Usage, msg, e)
}

/// A catalog error caused by `e`.
pub(crate) fn caused(
    msg: impl Into<String>,
    e: impl std::error::Error + Send + Sync + 'static,
) -> StoreError {
    StoreError::caused(ErrorKind::Catalog, msg, e)
}

/// An error and its causes, one per line (what the CLI prints).
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut s = e.to_string();
    let mut c = e.source();
    while let Some(x) = c {
        s.push_str("\n  caused by: ");
        s.push_str(&x.to_string());
        c = x.source();
    }
    s
}

/// The catalog named by `catalog` (a `postgres://` URL), else by `TRIBO_CATALOG`, else the SQLite
/// catalog of the store at `store`, brought up to date with its run folders
/// ([`tribo_store::RunCatalog::refresh`]).
pub fn open(catalog: Option<&str>, store: &Path) -> Result<Box<dyn AnyCatalog>> {
    match lab_url(catalog) {
        Some(url) => Ok(Box::new(LabCatalog::connect(&LabUrl::parse(&url)?)?)),
        None => {
            let cat = tribo_store::RunCatalog::open(store)?;
            cat.refresh(false)?;
            Ok(Box::new(cat))
        }
    }
}

/// The lab catalog's URL: `catalog`, else `TRIBO_CATALOG` (empty = none).
pub fn lab_url(catalog: Option<&str>) -> Option<String> {
    catalog
        .map(str::to_string)
        .or_else(|| std::env::var("TRIBO_CATALOG").ok())
        .filter(|s| !s.trim().is_empty())
}
