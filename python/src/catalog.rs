//! The run catalog (the store's SQLite index) and the Parquet export of runs and of the catalog.

use crate::errors::failure;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;
use tribo::export::{catalog_row_json, catalog_rows, catalog_table, Table};

/// The catalog's runs (`tribo runs --json`'s fields and the rest of each row) and the damaged
/// run folders, as JSON text `{"runs": [...], "damaged": [...]}`.
#[pyfunction]
#[pyo3(signature = (store, *, status=None, load=None, temp=None, campaign=None, label=None, rig=None, since=None, until=None, reindex=false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn catalog_runs(
    py: Python<'_>,
    store: PathBuf,
    status: Option<String>,
    load: Option<(f64, f64)>,
    temp: Option<(f64, f64)>,
    campaign: Option<String>,
    label: Option<String>,
    rig: Option<String>,
    since: Option<String>,
    until: Option<String>,
    reindex: bool,
) -> PyResult<String> {
    const DAMAGED: &str = "damaged";
    let only_damaged = status.as_deref() == Some(DAMAGED);
    let filter = tribo_store::Filter {
        campaign,
        label,
        status: status.clone().filter(|s| s != DAMAGED),
        load_min: load.map(|l| l.0),
        load_max: load.map(|l| l.1),
        temp_min: temp.map(|t| t.0),
        temp_max: temp.map(|t| t.1),
        rig,
        since,
        until,
    };
    let only_status = filter.selects_by_status_only();
    if let Err(e) = filter.check() {
        return Err(PyValueError::new_err(e.to_string()));
    }
    let (rows, damaged) = py
        .detach(|| catalog_rows(&store, &filter, reindex))
        .map_err(|e| failure(e, None).into_py(py))?;
    let runs: Vec<serde_json::Value> = if only_damaged {
        Vec::new()
    } else {
        rows.iter().map(catalog_row_json).collect()
    };
    let dmg: Vec<serde_json::Value> = if only_status && (status.is_none() || only_damaged) {
        damaged
            .iter()
            .map(|(p, why)| serde_json::json!({ "path": p, "status": DAMAGED, "why": why }))
            .collect()
    } else {
        Vec::new()
    };
    Ok(serde_json::json!({ "runs": runs, "damaged": dmg }).to_string())
}

/// Writes a run folder or record as Parquet (`tribo export --format parquet`); returns the rows.
#[pyfunction]
pub(crate) fn export_parquet(py: Python<'_>, source: PathBuf, output: PathBuf) -> PyResult<usize> {
    py.detach(|| {
        let t = Table::of_path(&source)?;
        t.write_parquet(&output)?;
        Ok(t.rows())
    })
    .map_err(|e: anyhow::Error| failure(e, Some(&source)).into_py(py))
}

/// Writes the catalog of a store as Parquet (`tribo export --catalog --format parquet`).
#[pyfunction]
pub(crate) fn export_catalog_parquet(
    py: Python<'_>,
    store: PathBuf,
    output: PathBuf,
) -> PyResult<usize> {
    py.detach(|| {
        let (rows, _) = catalog_rows(&store, &tribo_store::Filter::default(), false)?;
        catalog_table(&rows).write_parquet(&output)?;
        Ok(rows.len())
    })
    .map_err(|e: anyhow::Error| failure(e, None).into_py(py))
}
