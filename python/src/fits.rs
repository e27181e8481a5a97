//! Fits and explanations: `tribo fit --json`'s and `tribo explain --json`'s objects, made by the
//! functions the commands call (the Python side wraps them in `Fit` and `Explanation`).

use crate::errors::{failure, record_failure, Failure, Res};
use numpy::PyReadonlyArray1;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::path::PathBuf;
use tribo::analysis::RigFlags;
use tribo_physics::identify::LawSpec;
use tribo_physics::record::Units;
use tribo_physics::{Record, Rig};

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
                let o = tribo::analysis::open_analysable(&p, holes)
                    .map_err(|e| failure(e.into(), Some(&p)))?;
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

#[derive(Clone, Copy)]
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
        .map_err(|e| failure(e.into(), Some(&path)))?
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
pub(crate) fn fit(
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

/// [`fit`] of each source of a list (dicts of [`fit`]'s record arguments: `path`, or `t`, `x`,
/// `v`, `ft`, `temp`, `ecr`, `rig`, `dimensionless`, `name`, `stated_cutoff_hz`) with the same
/// law and flags, on every core with the GIL released (the pool of
/// `tribo_physics::identify::fit_many`: each fit on one thread, the results in input order):
/// for each, its JSON text or the exception [`fit`] raises for it alone.
#[pyfunction]
#[pyo3(signature = (sources, *, law="coulomb-viscous", mass_kg=None, stiffness=None, load_n=None,
    apparatus_mu1=0.0, windows=0, longest_clean_stretch=false))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit_many(
    py: Python<'_>,
    sources: Vec<Bound<'_, pyo3::types::PyDict>>,
    law: &str,
    mass_kg: Option<f64>,
    stiffness: Option<f64>,
    load_n: Option<f64>,
    apparatus_mu1: f64,
    windows: usize,
    longest_clean_stretch: bool,
) -> PyResult<Vec<Py<PyAny>>> {
    let law: LawSpec = law
        .parse()
        .map_err(|e| PyValueError::new_err(format!("law {law:?}: {e}")))?;
    let mut items: Vec<std::sync::Mutex<Option<Source>>> = Vec::with_capacity(sources.len());
    for (i, d) in sources.iter().enumerate() {
        let get = |k: &str| -> PyResult<Option<Bound<'_, PyAny>>> {
            Ok(d.get_item(k)?.filter(|o| !o.is_none()))
        };
        let arr = |k: &str| -> PyResult<Option<PyReadonlyArray1<'_, f64>>> {
            get(k)?
                .map(|o| {
                    use numpy::PyArrayMethods;
                    o.cast_into::<numpy::PyArray1<f64>>().map(|a| a.readonly())
                })
                .transpose()
                .map_err(|e| PyValueError::new_err(format!("record {i}: {k}: {e}")))
        };
        let src = source_of(
            get("path")?.map(|o| o.extract()).transpose()?,
            arr("t")?,
            arr("x")?,
            arr("v")?,
            arr("ft")?,
            arr("temp")?,
            arr("ecr")?,
            get("rig")?.map(|o| o.extract()).transpose()?,
            get("dimensionless")?
                .map(|o| o.extract())
                .transpose()?
                .unwrap_or(false),
            get("name")?.map(|o| o.extract()).transpose()?,
            get("stated_cutoff_hz")?.map(|o| o.extract()).transpose()?,
        )
        .map_err(|e| PyValueError::new_err(format!("record {i}: {e}")))?;
        items.push(std::sync::Mutex::new(Some(src)));
    }
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
    let out = py.detach(|| {
        tribo_physics::identify::map_on_every_core(
            &items,
            |m| {
                let src = m
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .take()
                    .ok_or_else(|| Failure::Tribo("a record was fitted twice".into()))?;
                fit_json(src, a)
            },
            || {},
        )
    });
    Ok(out
        .into_iter()
        .map(|r| match r {
            Ok(j) => pyo3::types::PyString::new(py, &j).into_any().unbind(),
            Err(f) => f.into_py(py).into_value(py).into_any(),
        })
        .collect())
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
pub(crate) fn explain(
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
