//! Runs and records: a run folder on its sample grid, a CSV record, a simulated record, as dicts
//! of numpy arrays (the Python side wraps them in `Run` and `Record`).

use crate::errors::{failure, Failure, Res};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::{Path, PathBuf};
use tribo_physics::record::Units;
use tribo_physics::Record;
use tribo_store::ErrorKind;

fn arr<'py>(py: Python<'py>, v: Vec<f64>) -> Bound<'py, PyAny> {
    PyArray1::from_vec(py, v).into_any()
}

fn opt_arr<'py>(py: Python<'py>, v: Option<Vec<f64>>) -> Bound<'py, PyAny> {
    match v {
        Some(v) => arr(py, v),
        None => py.None().into_bound(py),
    }
}

/// A run laid out on its sample grid: every index from 0 to the last sample held.
struct GridRun {
    t: Vec<f64>,
    x: Vec<f64>,
    v: Vec<f64>,
    ft: Option<Vec<f64>>,
    temp: Option<Vec<f64>>,
    ecr: Option<Vec<f64>>,
    mask: Vec<bool>,
    ecr_range: Option<Vec<u8>>,
    ecr_settling: Option<Vec<bool>>,
    gaps: Vec<(u64, u64)>,
    ecr_changes: Vec<(u64, u8, u64)>,
    missing: Vec<u32>,
    complete: bool,
    completeness: String,
    status: String,
    recovery: Option<String>,
    meta: String,
    results: String,
    rig: (f64, f64, f64),
    rate_hz: f64,
}

fn open_grid(path: &Path, allow_incomplete: bool) -> Res<GridRun> {
    let run = match tribo_store::Run::open(path) {
        Ok(r) => r,
        Err(e) if e.kind == ErrorKind::Corrupt => {
            if allow_incomplete {
                tribo_store::Run::open_salvage(path).map_err(|e| {
                    Failure::Tribo(format!("cannot read the run {}: {e}", path.display()))
                })?
            } else {
                // What salvaging would leave missing, to name it.
                let missing = tribo_store::Run::open_salvage(path)
                    .map(|r| r.missing_blocks())
                    .unwrap_or_default();
                let named = if missing.is_empty() {
                    String::new()
                } else {
                    format!(
                        " (blocks lost in the damage: {})",
                        tribo_store::run::block_ranges(&missing)
                    )
                };
                return Err(Failure::Incomplete {
                    msg: format!(
                        "{}: {e}{named}. Open it with allow_incomplete=True (what is intact, its \
                         holes NaN and `mask` True there), or repair it with `tribo pull \
                         --salvage {}`",
                        path.display(),
                        path.display()
                    ),
                    path: path.into(),
                    missing,
                });
            }
        }
        Err(e) => {
            return Err(Failure::Tribo(format!(
                "cannot read the run {}: {e}",
                path.display()
            )))
        }
    };
    let missing = run.missing_blocks();
    let completeness = run.completeness().summary();
    if !allow_incomplete && (!run.is_complete() || run.recovery.is_some()) {
        return Err(Failure::Incomplete {
            msg: format!(
                "{}: {completeness}. Open it with allow_incomplete=True (its holes NaN and `mask` \
                 True there), or fetch what is missing with `tribo pull {}`",
                path.display(),
                path.display()
            ),
            path: path.into(),
            missing,
        });
    }
    let s = run
        .samples_si()
        .map_err(|e| Failure::Tribo(format!("cannot read the run {}: {e}", path.display())))?;
    let clock = run.clock();
    let n = s.index.last().map_or(0, |&l| l as usize + 1);
    let dense = s.index.len() == n;
    let (t, x, v, ft, temp, ecr, mask, ecr_range, ecr_settling) = if dense {
        (
            s.t,
            s.x,
            s.v,
            s.force,
            s.temp_c,
            s.ecr_ohm,
            vec![false; n],
            s.ecr_range,
            s.ecr_settling,
        )
    } else {
        let place = |col: &[f64]| {
            let mut g = vec![f64::NAN; n];
            for (&i, &val) in s.index.iter().zip(col) {
                g[i as usize] = val;
            }
            g
        };
        let mut mask = vec![true; n];
        for &i in &s.index {
            mask[i as usize] = false;
        }
        let t = (0..n as u64).map(|i| clock.time_s(i)).collect();
        let ecr_range = s.ecr_range.as_ref().map(|r| {
            let mut g = vec![0u8; n];
            for (&i, &val) in s.index.iter().zip(r) {
                g[i as usize] = val;
            }
            g
        });
        let ecr_settling = s.ecr_settling.as_ref().map(|r| {
            let mut g = vec![false; n];
            for (&i, &val) in s.index.iter().zip(r) {
                g[i as usize] = val;
            }
            g
        });
        (
            t,
            place(&s.x),
            place(&s.v),
            s.force.as_deref().map(place),
            s.temp_c.as_deref().map(place),
            s.ecr_ohm.as_deref().map(place),
            mask,
            ecr_range,
            ecr_settling,
        )
    };
    let cfg = run.config();
    let clean = tribo_store::run::clean;
    Ok(GridRun {
        t,
        x,
        v,
        ft,
        temp,
        ecr,
        mask,
        ecr_range,
        ecr_settling,
        gaps: run
            .gaps()
            .map(|g| (g.first_sample as u64, g.count as u64))
            .collect(),
        ecr_changes: run
            .ecr_changes()
            .map(|c| (c.first_sample as u64, c.range, c.settling as u64))
            .collect(),
        missing,
        complete: run.is_complete(),
        completeness,
        status: run.meta().status.name().to_string(),
        recovery: run.recovery.as_ref().map(|r| r.to_string()),
        meta: serde_json::to_string(run.meta()).map_err(|e| Failure::Tribo(e.to_string()))?,
        results: serde_json::to_string(&run.results).map_err(|e| Failure::Tribo(e.to_string()))?,
        rig: (
            clean(cfg.rig.mass_kg),
            clean(cfg.rig.stiffness_n_per_m),
            clean(cfg.rig.load_n),
        ),
        rate_hz: clock.rate_hz(),
    })
}

/// Opens a run folder: a dict of its samples on the sample grid (numpy float64 in SI units, NaN
/// and `mask` True where a sample is missing), its gaps, ECR ranges, metadata and results.
#[pyfunction]
#[pyo3(signature = (path, allow_incomplete = false))]
pub(crate) fn open_run<'py>(
    py: Python<'py>,
    path: PathBuf,
    allow_incomplete: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let g = py
        .detach(|| open_grid(&path, allow_incomplete))
        .map_err(|f| f.into_py(py))?;
    let d = PyDict::new(py);
    d.set_item("path", path.display().to_string())?;
    d.set_item("t", arr(py, g.t))?;
    d.set_item("x", arr(py, g.x))?;
    d.set_item("v", arr(py, g.v))?;
    d.set_item("ft", opt_arr(py, g.ft))?;
    d.set_item("temp", opt_arr(py, g.temp))?;
    d.set_item("ecr", opt_arr(py, g.ecr))?;
    d.set_item("mask", PyArray1::from_vec(py, g.mask))?;
    d.set_item("ecr_range", g.ecr_range.map(|r| PyArray1::from_vec(py, r)))?;
    d.set_item(
        "ecr_settling",
        g.ecr_settling.map(|r| PyArray1::from_vec(py, r)),
    )?;
    d.set_item("gaps", g.gaps)?;
    d.set_item("ecr_changes", g.ecr_changes)?;
    d.set_item("missing_blocks", g.missing)?;
    d.set_item("complete", g.complete)?;
    d.set_item("completeness", g.completeness)?;
    d.set_item("status", g.status)?;
    d.set_item("recovery", g.recovery)?;
    d.set_item("meta", g.meta)?;
    d.set_item("results", g.results)?;
    d.set_item("rig", g.rig)?;
    d.set_item("sample_rate_hz", g.rate_hz)?;
    Ok(d)
}

fn record_dict<'py>(
    py: Python<'py>,
    rec: Record,
    path: Option<&Path>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("path", path.map(|p| p.display().to_string()))?;
    d.set_item(
        "units",
        match rec.units {
            Units::Si => "si",
            Units::Dimensionless => "dimensionless",
        },
    )?;
    d.set_item(
        "rig",
        rec.rig.map(|r| (r.mass_kg, r.stiffness_n_per_m, r.load_n)),
    )?;
    d.set_item("force_cutoff_hz", rec.force_cutoff_hz)?;
    d.set_item("t", arr(py, rec.t))?;
    d.set_item("x", arr(py, rec.x))?;
    d.set_item("v", arr(py, rec.v))?;
    d.set_item("ft", opt_arr(py, rec.ft))?;
    d.set_item("temp", opt_arr(py, rec.temp))?;
    d.set_item("ecr", opt_arr(py, rec.ecr))?;
    Ok(d)
}

/// Reads a record (CSV in the physics formats) as a dict of numpy arrays and its rig constants.
#[pyfunction]
pub(crate) fn read_record<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let rec = py
        .detach(|| {
            tribo::load::open(&path, tribo::Holes::Keep)
                .map(|o| o.record)
                .map_err(|e| failure(e.into(), Some(&path)))
        })
        .map_err(|f| f.into_py(py))?;
    record_dict(py, rec, Some(&path))
}

/// The record `tribo sim` makes with these options (JSON: `tribo sim`'s option names with `_`,
/// e.g. `{"law": "quadratic", "noise": true}`), as a dict: the simulator called directly.
#[pyfunction]
pub(crate) fn simulate<'py>(py: Python<'py>, options: String) -> PyResult<Bound<'py, PyDict>> {
    let rec = py
        .detach(|| -> Res<Record> {
            let o: tribo::simulate::SimOptions = serde_json::from_str(&options)
                .map_err(|e| Failure::Value(format!("simulate: {e}")))?;
            tribo::simulate::simulate(&o)
                .map(|(rec, _)| rec)
                .map_err(|e| failure(e, None))
        })
        .map_err(|f| f.into_py(py))?;
    record_dict(py, rec, None)
}
