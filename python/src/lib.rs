//! `tribo._tribo`: the Rust side of the `tribo` Python package.
//!
//! Every function calls what the `tribo` command calls (the run store, the record reader, the one
//! fit, the explanation, the catalog, the Parquet writer), so a notebook gets the CLI's numbers
//! to the last digit. Samples cross into Python as numpy arrays that take over the Rust vectors
//! (no per-sample Python object); results cross as the CLI's `--json` text, which the Python
//! side (`tribo/__init__.py`) wraps in objects. The long computations (opening a run, a fit, an
//! explanation) release the GIL.

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use std::path::{Path, PathBuf};
use tribo::export::{catalog_row_json, catalog_rows, catalog_table, Table};
use tribo::load::{LoadError, RigFlags};
use tribo_physics::identify::LawSpec;
use tribo_physics::record::{RecordError as RecError, RecordErrorKind, Units};
use tribo_physics::{Record, Rig};
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
enum Failure {
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

type Res<T> = Result<T, Failure>;

impl Failure {
    fn into_py(self, py: Python<'_>) -> PyErr {
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

fn record_failure(e: &RecError) -> Failure {
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
fn failure(e: anyhow::Error, path: Option<&Path>) -> Failure {
    if let Some(inc) = e.downcast_ref::<tribo::exit::Incomplete>() {
        return Failure::NotAnalysable {
            msg: inc.0.clone(),
            reason: None,
        };
    }
    if let Some(le) = e.downcast_ref::<LoadError>() {
        match le {
            LoadError::Record(r) => return record_failure(r),
            LoadError::Holes { path, .. } | LoadError::Incomplete { path, .. } => {
                let missing = tribo_store::Run::open(path)
                    .map(|r| r.missing_blocks())
                    .unwrap_or_default();
                return Failure::Incomplete {
                    msg: chain(&e),
                    path: path.clone(),
                    missing,
                };
            }
            LoadError::Run { path, source } if source.kind == ErrorKind::Corrupt => {
                return Failure::Incomplete {
                    msg: format!(
                        "{}; `tribo pull --salvage {}` keeps every intact record",
                        chain(&e),
                        path.display()
                    ),
                    path: path.clone(),
                    missing: Vec::new(),
                };
            }
            LoadError::Run { .. } => {}
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
fn open_run<'py>(
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
fn read_record<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
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
fn simulate<'py>(py: Python<'py>, options: String) -> PyResult<Bound<'py, PyDict>> {
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

/// A record given as arrays (from Python), or read from a path as `tribo fit` reads it.
enum Source {
    Path(PathBuf),
    Arrays(Box<Record>, String),
}

#[allow(clippy::too_many_arguments)]
fn source_of(
    path: Option<PathBuf>,
    t: Option<PyReadonlyArray1<'_, f64>>,
    x: Option<PyReadonlyArray1<'_, f64>>,
    v: Option<PyReadonlyArray1<'_, f64>>,
    ft: Option<PyReadonlyArray1<'_, f64>>,
    temp: Option<PyReadonlyArray1<'_, f64>>,
    ecr: Option<PyReadonlyArray1<'_, f64>>,
    rig: Option<(f64, f64, f64)>,
    dimensionless: bool,
    name: Option<String>,
    stated_cutoff_hz: Option<f64>,
) -> PyResult<Source> {
    if let Some(p) = path {
        return Ok(Source::Path(p));
    }
    let col = |a: Option<PyReadonlyArray1<'_, f64>>| -> PyResult<Option<Vec<f64>>> {
        a.map(|a| Ok(a.as_slice()?.to_vec())).transpose()
    };
    let (Some(t), Some(x), Some(v)) = (col(t)?, col(x)?, col(v)?) else {
        return Err(PyValueError::new_err(
            "give a path, or the arrays t, x and v of a record",
        ));
    };
    let units = if dimensionless {
        Units::Dimensionless
    } else {
        Units::Si
    };
    let rig = match (rig, dimensionless) {
        (_, true) => Some(Rig::UNIT),
        (Some((m, k, n)), false) => {
            Some(Rig::new(m, k, n).map_err(|e| PyValueError::new_err(e.to_string()))?)
        }
        (None, false) => None,
    };
    let mut rec = Record::new(t, x, v, rig, units);
    rec.ft = col(ft)?;
    rec.temp = col(temp)?;
    rec.ecr = col(ecr)?;
    // What the record states of its force channel's low-pass travels with its arrays (the drift
    // check and explain read it, as they do from a file's header).
    if let Some(fc) = stated_cutoff_hz {
        if !(fc.is_finite() && fc > 0.0) {
            return Err(PyValueError::new_err(format!(
                "force_cutoff_hz must be a finite cut-off > 0 Hz, got {fc}"
            )));
        }
    }
    rec.force_cutoff_hz = stated_cutoff_hz;
    Ok(Source::Arrays(
        Box::new(rec),
        name.unwrap_or_else(|| "<record>".into()),
    ))
}

impl Source {
    /// The record ready to fit, as [`tribo::load::open`] opens a path (with the rig constants its
    /// metadata says were defaults, and the run), and its name.
    fn load(self, holes: tribo::Holes) -> Res<(tribo::load::Opened, PathBuf)> {
        match self {
            Source::Path(p) => {
                let o =
                    tribo::load::open_analysable(&p, holes).map_err(|e| failure(e, Some(&p)))?;
                Ok((o, p))
            }
            Source::Arrays(rec, name) => {
                rec.validate().map_err(|e| record_failure(&e))?;
                let o = tribo::load::Opened {
                    record: *rec,
                    defaults: Vec::new(),
                    run: None,
                };
                Ok((o, PathBuf::from(name)))
            }
        }
    }
}

struct FitArgs {
    law: LawSpec,
    flags: RigFlags,
    apparatus_mu1: f64,
    windows: usize,
    holes: tribo::Holes,
}

/// `tribo fit --json`'s object, made by the function the command calls.
fn fit_json(src: Source, a: FitArgs) -> Res<String> {
    use tribo::analysis::{fit_law, FitOutcome, FitRequest};
    let (opened, path) = src.load(a.holes)?;
    let mut rec = opened.record;
    let name = path.display().to_string();
    let req = FitRequest {
        law: a.law,
        flags: a.flags,
        apparatus_mu1: a.apparatus_mu1,
        windows: a.windows,
    };
    let f = match fit_law(&name, &mut rec, &opened.defaults, opened.run.as_ref(), &req)
        .map_err(|e| failure(e, Some(&path)))?
    {
        FitOutcome::Fitted(f) => f,
        FitOutcome::NotAnalysable { why, .. } => {
            return Err(Failure::NotAnalysable {
                msg: format!("{name}: not analysable: {why}; no constant is fitted"),
                reason: Some(why.name().to_string()),
            })
        }
    };
    let j = f
        .json(&name, &rec)
        .map_err(|e| Failure::Tribo(e.to_string()))?;
    Ok(j.to_string())
}

fn holes(longest_clean_stretch: bool) -> tribo::Holes {
    if longest_clean_stretch {
        tribo::Holes::LongestCleanStretch
    } else {
        tribo::Holes::Refuse
    }
}

/// `tribo fit --json` of a path or of arrays: the JSON text.
#[pyfunction]
#[pyo3(signature = (path=None, *, law="coulomb-viscous", mass_kg=None, stiffness=None, load_n=None,
    apparatus_mu1=0.0, windows=0, longest_clean_stretch=false, t=None, x=None, v=None, ft=None,
    temp=None, ecr=None, rig=None, dimensionless=false, name=None, stated_cutoff_hz=None))]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    path: Option<PathBuf>,
    law: &str,
    mass_kg: Option<f64>,
    stiffness: Option<f64>,
    load_n: Option<f64>,
    apparatus_mu1: f64,
    windows: usize,
    longest_clean_stretch: bool,
    t: Option<PyReadonlyArray1<'_, f64>>,
    x: Option<PyReadonlyArray1<'_, f64>>,
    v: Option<PyReadonlyArray1<'_, f64>>,
    ft: Option<PyReadonlyArray1<'_, f64>>,
    temp: Option<PyReadonlyArray1<'_, f64>>,
    ecr: Option<PyReadonlyArray1<'_, f64>>,
    rig: Option<(f64, f64, f64)>,
    dimensionless: bool,
    name: Option<String>,
    stated_cutoff_hz: Option<f64>,
) -> PyResult<String> {
    let law: LawSpec = law
        .parse()
        .map_err(|e| PyValueError::new_err(format!("law {law:?}: {e}")))?;
    let src = source_of(
        path,
        t,
        x,
        v,
        ft,
        temp,
        ecr,
        rig,
        dimensionless,
        name,
        stated_cutoff_hz,
    )?;
    let a = FitArgs {
        law,
        flags: RigFlags {
            mass_kg,
            stiffness_n_per_m: stiffness,
            load_n,
        },
        apparatus_mu1,
        windows,
        holes: holes(longest_clean_stretch),
    };
    py.detach(|| fit_json(src, a)).map_err(|f| f.into_py(py))
}

/// `tribo explain --json`'s object, made as the command makes it.
fn explain_json(src: Source, opts: tribo_explain::ExplainOptions, h: tribo::Holes) -> Res<String> {
    let (opened, path) = src.load(h)?;
    let record = &opened.record;
    let not_analysable = |e: tribo_explain::ExplainError| -> Failure {
        if e.is_not_analysable() {
            Failure::NotAnalysable {
                msg: format!("{}: {e}; nothing is explained", path.display()),
                reason: None,
            }
        } else {
            Failure::Tribo(format!("{}: {e}", path.display()))
        }
    };
    let data = tribo_explain::Prepared::new(
        record,
        opts.max_env_points,
        opts.max_force_points,
        opts.force_cutoff_hz,
    )
    .map_err(not_analysable)?;
    let (ex, _) = tribo_explain::explain_with_progress(&data, &opts, &mut |_, _, _| {})
        .map_err(not_analysable)?;
    let check = tribo::analysis::cross_check(opened.run.as_ref(), record, &ex.base_fit);
    let j = tribo::analysis::explanation_json(&ex, &check)
        .map_err(|e| Failure::Tribo(e.to_string()))?;
    if !ex.gap_final.is_finite() {
        return Err(Failure::Tribo(format!(
            "{}: the fit diverged",
            path.display()
        )));
    }
    Ok(j.to_string())
}

/// `tribo explain --json` of a path or of arrays: the JSON text.
#[pyfunction]
#[pyo3(signature = (path=None, *, base="coulomb-viscous", only=None, max_steps=3,
    force_cutoff_hz=None, longest_clean_stretch=false, t=None, x=None, v=None, ft=None, temp=None,
    ecr=None, rig=None, dimensionless=false, name=None, stated_cutoff_hz=None))]
#[allow(clippy::too_many_arguments)]
fn explain(
    py: Python<'_>,
    path: Option<PathBuf>,
    base: &str,
    only: Option<Vec<String>>,
    max_steps: usize,
    force_cutoff_hz: Option<f64>,
    longest_clean_stretch: bool,
    t: Option<PyReadonlyArray1<'_, f64>>,
    x: Option<PyReadonlyArray1<'_, f64>>,
    v: Option<PyReadonlyArray1<'_, f64>>,
    ft: Option<PyReadonlyArray1<'_, f64>>,
    temp: Option<PyReadonlyArray1<'_, f64>>,
    ecr: Option<PyReadonlyArray1<'_, f64>>,
    rig: Option<(f64, f64, f64)>,
    dimensionless: bool,
    name: Option<String>,
    stated_cutoff_hz: Option<f64>,
) -> PyResult<String> {
    let base_law: LawSpec = base
        .parse()
        .map_err(|e| PyValueError::new_err(format!("base {base:?}: {e}")))?;
    if base_law == LawSpec::LuGre {
        return Err(PyValueError::new_err(
            "the base law must be polynomial: coulomb, viscous, coulomb-viscous, quadratic, poly:N",
        ));
    }
    let mut opts = tribo_explain::ExplainOptions {
        base: base_law,
        max_steps,
        force_cutoff_hz,
        ..Default::default()
    };
    if let Some(only) = only {
        opts.candidates = only
            .iter()
            .map(|s| {
                tribo_explain::Effect::from_name(s.trim()).ok_or_else(|| {
                    PyValueError::new_err(format!(
                        "unknown effect {s:?}: use {}",
                        tribo_explain::Effect::ALL.map(|e| e.name()).join(", ")
                    ))
                })
            })
            .collect::<PyResult<_>>()?;
    }
    let src = source_of(
        path,
        t,
        x,
        v,
        ft,
        temp,
        ecr,
        rig,
        dimensionless,
        name,
        stated_cutoff_hz,
    )?;
    py.detach(|| explain_json(src, opts, holes(longest_clean_stretch)))
        .map_err(|f| f.into_py(py))
}

/// The catalog's runs (`tribo runs --json`'s fields and the rest of each row) and the damaged
/// run folders, as JSON text `{"runs": [...], "damaged": [...]}`.
#[pyfunction]
#[pyo3(signature = (store, *, status=None, load=None, temp=None, campaign=None, label=None, rig=None, since=None, until=None, reindex=false))]
#[allow(clippy::too_many_arguments)]
fn catalog_runs(
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
fn export_parquet(py: Python<'_>, source: PathBuf, output: PathBuf) -> PyResult<usize> {
    py.detach(|| {
        let t = Table::of_path(&source)?;
        t.write_parquet(&output)?;
        Ok(t.rows())
    })
    .map_err(|e: anyhow::Error| failure(e, Some(&source)).into_py(py))
}

/// Writes the catalog of a store as Parquet (`tribo export --catalog --format parquet`).
#[pyfunction]
fn export_catalog_parquet(py: Python<'_>, store: PathBuf, output: PathBuf) -> PyResult<usize> {
    py.detach(|| {
        let (rows, _) = catalog_rows(&store, &tribo_store::Filter::default(), false)?;
        catalog_table(&rows).write_parquet(&output)?;
        Ok(rows.len())
    })
    .map_err(|e: anyhow::Error| failure(e, None).into_py(py))
}

#[pymodule]
fn _tribo(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("TriboError", py.get_type::<TriboError>())?;
    m.add("NotAnalysable", py.get_type::<NotAnalysable>())?;
    m.add("IncompleteRun", py.get_type::<IncompleteRun>())?;
    m.add("RecordError", py.get_type::<RecordError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(open_run, m)?)?;
    m.add_function(wrap_pyfunction!(read_record, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(explain, m)?)?;
    m.add_function(wrap_pyfunction!(catalog_runs, m)?)?;
    m.add_function(wrap_pyfunction!(export_parquet, m)?)?;
    m.add_function(wrap_pyfunction!(export_catalog_parquet, m)?)?;
    Ok(())
}
