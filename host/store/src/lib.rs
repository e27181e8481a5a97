//! Run store of the oscillating tribometer.
//!
//! A run is a folder:
//!
//! | file          | written                      | content                                                |
//! |---------------|------------------------------|--------------------------------------------------------|
//! | `frames.log`  | append-only, while recording | every frame the rig sent for this run, as received     |
//! | `meta.toml`   | at creation, rewritten atomically at the end | [`RunMeta`]: rig constants, sample, load, temperature, firmware |
//! | `result.toml` | atomically at the end        | [`Results`]: on-board result and the host's fit         |
//! | `samples.csv` | at the end (or `Run::export_csv`) | SI samples in the physics CSV format (`# mass_kg=…`) |
//!
//! The frame log ([`log`]) is the truth; everything else can be rebuilt from it and the
//! metadata. A killed process or a pulled cable never corrupts what was already written: each record
//! is written with one `write` call and carries its length and CRC, so at worst the last record is
//! torn, and [`log::LogReader`] / [`RunWriter::resume`] cut it off and say so. Damage elsewhere is
//! an error that names the place, unless salvaged: then every record whose CRC holds is kept.
//!
//! What a run holds is read from its log, never taken from its metadata: [`Run::completeness`]
//! says which blocks are missing (acquisition gaps the rig reported are not), whether run events,
//! the result or the end are missing, in one line (`incomplete: 79 of 156 blocks (missing …)`);
//! [`Run::open`] derives the run's status from it. A frame is filed once ([`RunWriter::file_frame`]:
//! a copy received again is compared, not logged), so a complete run's log holds exactly the rig's
//! frames ([`Run::frames`], in the rig's order).
//!
//! The [`catalog`] indexes all runs of a store in SQLite (`catalog.sqlite` at the store's root); it
//! is an index only and [`catalog::RunCatalog::reindex`] rebuilds it from the folders.

#![warn(missing_docs)]

/// The run catalog: every run of the store indexed in one SQLite file.
pub mod catalog;
/// The frame log: the crash-safe append-only file of a run's frames.
pub mod log;
/// A run folder: its log, metadata and results, read back and written.
pub mod run;
mod time;

pub use catalog::{AnyCatalog, Catalog, CatalogRow, Filter, Reindexed, RunCatalog};
pub use log::{LogHeader, LogReader, LogWriter, Recovery};
pub use run::{
    Completeness, DeviceMeta, Filed, HostFit, Results, Run, RunMeta, RunStatus, RunWriter, Samples,
};
pub use time::utc_now_rfc3339;

use std::fmt;

/// Any store failure: its kind (for callers that react differently), what went wrong and where
/// and what to do next (the message), and the error underneath, if any, as its source (the
/// `io::Error`, the SQLite or TOML error): `Display` says the message only, the CLI prints the
/// chain.
#[derive(Debug, thiserror::Error)]
#[error("{msg}")]
pub struct StoreError {
    /// What kind of error (what the caller can do about it).
    pub kind: ErrorKind,
    /// The message.
    pub msg: String,
    #[source]
    source: Option<Box<dyn std::error::Error + Send + Sync>>,
}

/// Broad class of a [`StoreError`], for callers that react differently.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// Reading or writing a file failed.
    Io,
    /// The log or a metadata file is damaged (not just a torn tail).
    Corrupt,
    /// Not a run folder / not a store.
    NotFound,
    /// A caller's mistake (bad filter, bad value).
    Invalid,
    /// The SQLite catalog failed (opening, querying or writing it).
    Catalog,
    /// A value given on the command line that cannot be right (a catalog URL with an unknown
    /// parameter, no scheme, a password in it): the CLI exits with its usage status (2).
    Usage,
}

impl StoreError {
    /// An error of kind `kind` with nothing underneath.
    pub fn new(kind: ErrorKind, msg: impl Into<String>) -> Self {
        StoreError {
            kind,
            msg: msg.into(),
            source: None,
        }
    }
    /// An error of kind `kind` caused by `source`.
    pub fn caused(
        kind: ErrorKind,
        msg: impl Into<String>,
        source: impl std::error::Error + Send + Sync + 'static,
    ) -> Self {
        StoreError {
            kind,
            msg: msg.into(),
            source: Some(Box::new(source)),
        }
    }
    pub(crate) fn io(ctx: impl fmt::Display, e: std::io::Error) -> Self {
        StoreError::caused(ErrorKind::Io, ctx.to_string(), e)
    }
}

/// The store's result type.
pub type Result<T, E = StoreError> = std::result::Result<T, E>;

/// Default store directory: `$TRIBO_STORE`, else `./runs`.
pub fn default_store_dir() -> std::path::PathBuf {
    std::env::var_os("TRIBO_STORE")
        .filter(|s| !s.is_empty())
        .map(Into::into)
        .unwrap_or_else(|| "runs".into())
}

#[cfg(test)]
mod tests;
