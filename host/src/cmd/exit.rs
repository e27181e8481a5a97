//! The exit statuses of `tribo`, one contract for every command (documented in the README):
//!
//! | status | meaning |
//! |---|---|
//! | 0 | done, and the data is whole |
//! | 1 | error: nothing usable was produced (the message says what to do next) |
//! | 2 | usage: the command line was wrong (clap's own status, or a value the rig would refuse) |
//! | 3 | finished, but the data is incomplete or not analysable: the output says exactly what is missing |
//! | 130, 143, 129 | interrupted by Ctrl-C (SIGINT), SIGTERM or SIGHUP (128 + the signal's number): stopped cleanly, the rig made safe, what was received kept |
//!
//! Decided here only: a library function that finished with incomplete data returns
//! [`crate::exit::Incomplete`] as its error (after printing or storing everything it has), and
//! [`status_of`] maps it to status 3, as it maps the library's other typed errors
//! ([`crate::exit`], the loader's [`LoadError`], the analysis's [`AnalysisError`], the store's
//! usage errors). Any other error is status 1.

use crate::analysis::AnalysisError;
use crate::exit::{Incomplete, Interrupted, Usage};
use crate::load::LoadError;
use crate::signals::Signal;

/// The statuses `tribo` exits with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    /// 0: done, and the data is whole.
    Ok,
    /// 1: an error; nothing usable was produced.
    Error,
    /// 2: a wrong command line (or a value the rig would refuse).
    Usage,
    /// 3: finished, but the data is incomplete or not analysable.
    Incomplete,
    /// Stopped by this signal: 128 + its number (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP).
    Interrupted(Signal),
}

impl Status {
    /// The process's exit status.
    pub const fn code(self) -> u8 {
        match self {
            Status::Ok => 0,
            Status::Error => 1,
            Status::Usage => 2,
            Status::Incomplete => 3,
            Status::Interrupted(s) => s.status(),
        }
    }
}

/// The status of the loader's error: 3 for a run whose data is not whole, else 1.
fn load_status(e: &LoadError) -> Status {
    if e.is_incomplete() {
        Status::Incomplete
    } else {
        Status::Error
    }
}

/// The status of an analysis's refusal: 2 for a value out of range, 3 for a record that cannot
/// be analysed (as written, or a non-finite sample) or a run not whole, else 1.
fn analysis_status(e: &AnalysisError) -> Status {
    match e.innermost() {
        AnalysisError::Load(l) => load_status(l),
        AnalysisError::NonFinite(_) | AnalysisError::NotAnalysable(_) => Status::Incomplete,
        AnalysisError::Usage(_) => Status::Usage,
        AnalysisError::Request(_)
        | AnalysisError::Rig(_)
        | AnalysisError::Fit(_)
        | AnalysisError::Of { .. } => Status::Error,
    }
}

/// The status an error from a command maps to.
pub fn status_of(e: &anyhow::Error) -> Status {
    let typed = |c: &(dyn std::error::Error + 'static)| {
        c.downcast_ref::<AnalysisError>()
            .map(analysis_status)
            .or_else(|| c.downcast_ref::<LoadError>().map(load_status))
    };
    if e.chain().any(|c| c.downcast_ref::<Interrupted>().is_some()) {
        Status::Interrupted(crate::signals::received().unwrap_or(Signal::Interrupt))
    } else if e
        .chain()
        .any(|c| c.downcast_ref::<Incomplete>().is_some() || typed(c) == Some(Status::Incomplete))
    {
        Status::Incomplete
    } else if e.chain().any(|c| {
        c.downcast_ref::<Usage>().is_some()
            || typed(c) == Some(Status::Usage)
            || c.downcast_ref::<tribo_store::StoreError>()
                .is_some_and(|s| s.kind == tribo_store::ErrorKind::Usage)
    }) {
        Status::Usage
    } else {
        Status::Error
    }
}

/// For a `--json` command that stops on an error before printing its object: prints one object
/// all the same, `{"record", "verdict": "not-analysable" | "interrupted" | "error", "status",
/// "message"}` (the status the process exits with, the message with its causes), so that a
/// script reading standard output always gets one object. Returns the error.
pub fn json_on_error(json: bool, record: &std::path::Path, e: anyhow::Error) -> anyhow::Error {
    if json && !crate::out::json_printed() {
        let _ = crate::out::print_json(error_json(record, &e));
    }
    e
}

/// The `--json` object of a record whose command failed before printing its own (see
/// [`json_on_error`]).
pub fn error_json(record: &std::path::Path, e: &anyhow::Error) -> serde_json::Value {
    let status = status_of(e);
    let verdict = match status {
        Status::Incomplete => "not-analysable",
        Status::Interrupted(_) => "interrupted",
        _ => "error",
    };
    let message = e
        .chain()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(": ");
    serde_json::json!({
        "record": record.display().to_string(),
        "verdict": verdict,
        "status": status.code(),
        "message": message,
    })
}

/// Prints an error that ends the command, as the chain of its causes, one per line, and returns
/// the status to exit with.
pub fn report(e: &anyhow::Error) -> Status {
    let status = status_of(e);
    let label = match status {
        Status::Incomplete => "incomplete",
        Status::Interrupted(_) => "interrupted",
        _ => "error",
    };
    crate::errln!("{label}: {e}");
    for cause in e.chain().skip(1) {
        crate::errln!("  caused by: {cause}");
    }
    status
}
