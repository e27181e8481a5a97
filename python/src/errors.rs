//! The package's exceptions: every error of the library sorted into the one a script catches
//! (`TriboError` and its subclasses), from the loader's and the analysis's typed errors.

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::path::{Path, PathBuf};
use tribo::analysis::AnalysisError;
use tribo::load::LoadError;
use tribo_physics::record::{RecordError as RecError, RecordErrorKind};
use tribo_store::ErrorKind;

create_exception!(
    _tribo,
    TriboError,
    PyException,
    "Any failure of tribo; the message says what went wrong and what to do next."
);
create_exception!(
    _tribo,
    NotAnalysable,
    TriboError,
    "The record cannot be analysed (no oscillation, too few half cycles, a saturated or stuck \
     channel, a non-finite sample, or not plausible as written: another unit than its header \
     says): nothing is fitted. `reason` names why (or is None)."
);
create_exception!(
    _tribo,
    IncompleteRun,
    TriboError,
    "The run has holes: blocks not received, acquisition gaps, or a damaged frame log. \
     `missing_blocks` lists the blocks not received; `path` is the run."
);
create_exception!(
    _tribo,
    RecordError,
    TriboError,
    "A record that cannot be read: `file`, `line` and `column` say where (None when unknown)."
);

/// An error made without the GIL, turned into a Python exception with it.
#[derive(Debug)]
pub(crate) enum Failure {
    Tribo(String),
    Value(String),
    NotAnalysable {
        msg: String,
        reason: Option<String>,
    },
    Incomplete {
        msg: String,
        path: PathBuf,
        missing: Vec<u32>,
    },
    Record {
        msg: String,
        file: Option<PathBuf>,
        line: Option<usize>,
        column: Option<usize>,
    },
}

pub(crate) type Res<T> = Result<T, Failure>;

impl Failure {
    pub(crate) fn into_py(self, py: Python<'_>) -> PyErr {
        let set = |e: &PyErr, k: &str, v: Bound<'_, PyAny>| {
            let _ = e.value(py).setattr(k, v);
        };
        match self {
            Failure::Tribo(m) => TriboError::new_err(m),
            Failure::Value(m) => PyValueError::new_err(m),
            Failure::NotAnalysable { msg, reason } => {
                let e = NotAnalysable::new_err(msg);
                set(&e, "reason", reason.into_pyobject(py).unwrap().into_any());
                e
            }
            Failure::Incomplete { msg, path, missing } => {
                let e = IncompleteRun::new_err(msg);
                set(
                    &e,
                    "path",
                    path.display()
                        .to_string()
                        .into_pyobject(py)
                        .unwrap()
                        .into_any(),
                );
                set(
                    &e,
                    "missing_blocks",
                    PyList::new(py, missing).unwrap().into_any(),
                );
                e
            }
            Failure::Record {
                msg,
                file,
                line,
                column,
            } => {
                let e = RecordError::new_err(msg);
                let file = file.map(|f| f.display().to_string());
                set(&e, "file", file.into_pyobject(py).unwrap().into_any());
                set(&e, "line", line.into_pyobject(py).unwrap().into_any());
                set(&e, "column", column.into_pyobject(py).unwrap().into_any());
                e
            }
        }
    }
}

/// The error with its causes, as the CLI prints them on one line.
fn chain(e: &anyhow::Error) -> String {
    e.chain()
        .map(|c| c.to_string())
        .collect::<Vec<_>>()
        .join(": ")
}

pub(crate) fn record_failure(e: &RecError) -> Failure {
    if e.kind() == RecordErrorKind::NonFinite {
        return Failure::NotAnalysable {
            msg: format!("not analysable: {}", tribo::exit::chain_text(e)),
            reason: Some("non-finite".into()),
        };
    }
    let (mut file, mut line, mut column) = (None, None, None);
    let mut cur = e;
    loop {
        match cur {
            RecError::In { path, source } => {
                file.get_or_insert_with(|| path.clone());
                cur = source;
            }
            RecError::Syntax { line: l, col, .. } => {
                line = Some(*l);
                column = Some(*col);
                break;
            }
            RecError::Io { path, .. } => {
                file.get_or_insert_with(|| path.clone());
                break;
            }
            _ => break,
        }
    }
    Failure::Record {
        msg: tribo::exit::chain_text(e),
        file,
        line,
        column,
    }
}

/// Sorts an error of the library into the exception a script catches.
pub(crate) fn failure(e: anyhow::Error, path: Option<&Path>) -> Failure {
    if let Some(inc) = e.downcast_ref::<tribo::exit::Incomplete>() {
        return Failure::NotAnalysable {
            msg: inc.0.clone(),
            reason: None,
        };
    }
    if let Some(ae) = e.downcast_ref::<AnalysisError>() {
        if let Some(f) = analysis_failure(ae, &e) {
            return f;
        }
    }
    if let Some(le) = e.downcast_ref::<LoadError>() {
        if let Some(f) = load_failure(le, &e) {
            return f;
        }
    }
    if let Some(r) = e.downcast_ref::<RecError>() {
        return record_failure(r);
    }
    let msg = chain(&e);
    match path {
        Some(p) if !msg.contains(&p.display().to_string()) => {
            Failure::Tribo(format!("{}: {msg}", p.display()))
        }
        _ => Failure::Tribo(msg),
    }
}

/// The exception of the analysis's typed error (`None`: a plain `TriboError`): a value out of
/// range is a `ValueError` (`UsageError` on the Python side), a record that cannot be analysed
/// `NotAnalysable`, the loader's errors as [`load_failure`] sorts them.
fn analysis_failure(ae: &AnalysisError, e: &anyhow::Error) -> Option<Failure> {
    match ae.innermost() {
        AnalysisError::Load(le) => load_failure(le, e),
        AnalysisError::NonFinite(_) => Some(Failure::NotAnalysable {
            msg: chain(e),
            reason: Some("non-finite".into()),
        }),
        AnalysisError::NotAnalysable(_) => Some(Failure::NotAnalysable {
            msg: chain(e),
            reason: None,
        }),
        AnalysisError::Usage(_) => Some(Failure::Value(chain(e))),
        AnalysisError::Request(_)
        | AnalysisError::Rig(_)
        | AnalysisError::Fit(_)
        | AnalysisError::Of { .. } => None,
    }
}

/// The exception of the loader's typed error (`None`: a plain `TriboError`): a run with holes or
/// a damaged log is `IncompleteRun` (with the blocks missing), a record that cannot be read
/// `RecordError`.
fn load_failure(le: &LoadError, e: &anyhow::Error) -> Option<Failure> {
    match le {
        LoadError::Record(r) => Some(record_failure(r)),
        LoadError::Holes { path, .. } | LoadError::Incomplete { path, .. } => {
            let missing = tribo_store::Run::open(path)
                .map(|r| r.missing_blocks())
                .unwrap_or_default();
            Some(Failure::Incomplete {
                msg: chain(e),
                path: path.clone(),
                missing,
            })
        }
        LoadError::Run { path, source } if source.kind == ErrorKind::Corrupt => {
            Some(Failure::Incomplete {
                msg: format!(
                    "{}; `tribo pull --salvage {}` keeps every intact record",
                    chain(e),
                    path.display()
                ),
                path: path.clone(),
                missing: Vec::new(),
            })
        }
        LoadError::Run { .. } => None,
    }
}
