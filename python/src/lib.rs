//! `tribo._tribo`: the Rust side of the `tribo` Python package.
//!
//! Every function calls what the `tribo` command calls (the run store, the record reader, the one
//! fit, the explanation, the catalog, the Parquet writer), so a notebook gets the CLI's numbers
//! to the last digit. Samples cross into Python as numpy arrays that take over the Rust vectors
//! (no per-sample Python object); results cross as the CLI's `--json` text, which the Python
//! side (`tribo/__init__.py`) wraps in objects. The long computations (opening a run, a fit, an
//! explanation) release the GIL.
//!
//! One module per concept: [`errors`] (the exceptions), [`runs`] (runs and records), [`fits`]
//! (fits and explanations), [`catalog`] (the run catalog and Parquet).

mod catalog;
mod errors;
mod fits;
mod runs;

use errors::{IncompleteRun, NotAnalysable, RecordError, TriboError};
use pyo3::prelude::*;

#[pymodule]
fn _tribo(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("TriboError", py.get_type::<TriboError>())?;
    m.add("NotAnalysable", py.get_type::<NotAnalysable>())?;
    m.add("IncompleteRun", py.get_type::<IncompleteRun>())?;
    m.add("RecordError", py.get_type::<RecordError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(runs::open_run, m)?)?;
    m.add_function(wrap_pyfunction!(runs::read_record, m)?)?;
    m.add_function(wrap_pyfunction!(runs::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(fits::fit, m)?)?;
    m.add_function(wrap_pyfunction!(fits::fit_many, m)?)?;
    m.add_function(wrap_pyfunction!(fits::explain, m)?)?;
    m.add_function(wrap_pyfunction!(catalog::catalog_runs, m)?)?;
    m.add_function(wrap_pyfunction!(catalog::export_parquet, m)?)?;
    m.add_function(wrap_pyfunction!(catalog::export_catalog_parquet, m)?)?;
    Ok(())
}
