//! The analysis both the command line and the Python package give: the on-board cross-check of a
//! host fit, an apparatus record's damping, and the JSON of a fit and of an explanation.

use crate::crosscheck::{CrossCheck, OnboardSource};
use tribo_physics::identify::{FitResult, LawSpec};
use tribo_physics::Record;

/// The on-board cross-check of a Coulomb–viscous host fit: the rig's stored result for a run
/// folder, else the firmware's pipeline over the record's samples. `Ok(None)` for other laws (the
/// rig fits only Coulomb–viscous); `Err(why)` when there is no on-board result to compare with.
pub fn cross_check(
    path: &std::path::Path,
    rec: &Record,
    r: &FitResult,
) -> std::result::Result<Option<CrossCheck>, String> {
    if r.law != LawSpec::CoulombViscous {
        return Ok(None);
    }
    let stored = path
        .is_dir()
        .then(|| tribo_store::Run::open(path).ok())
        .flatten()
        .and_then(|run| run.result().copied());
    let (ob, source) = match stored {
        Some(ob) => (ob, OnboardSource::Rig),
        None => (
            crate::onboard::analyse(rec)
                .map_err(|e| format!("the on-board pipeline cannot take the record: {e:#}"))?,
            OnboardSource::Record,
        ),
    };
    CrossCheck::of(r, &ob, source).map(Some).ok_or_else(|| {
        format!(
            "the on-board analysis gave no estimate ({})",
            ob.verdict.name()
        )
    })
}

/// The cross-check's line for the terminal, or why there is none.
pub fn cross_check_text(c: &std::result::Result<Option<CrossCheck>, String>) -> Option<String> {
    match c {
        Ok(Some(c)) => Some(c.text()),
        Ok(None) => None,
        Err(why) => Some(format!("on-board   no cross-check: {why}")),
    }
}

/// The cross-check as JSON: the object, `null` for a law the rig does not fit, or
/// `{"unavailable": why}`.
pub fn cross_check_json(
    c: &std::result::Result<Option<CrossCheck>, String>,
) -> serde_json::Result<serde_json::Value> {
    match c {
        Ok(c) => serde_json::to_value(c),
        Err(why) => Ok(serde_json::json!({ "unavailable": why })),
    }
}

/// An apparatus record's damping: `(μ_a, its standard error, c = μ_a·m·Ω in N·s/m)`.
pub fn apparatus_damping(rec: &Record, r: &FitResult) -> Option<(f64, f64, f64)> {
    let rig = rec.rig.filter(|_| rec.apparatus)?;
    let (mu_a, se) = (*r.mu.get(1)?, *r.mu_se.get(1)?);
    Some((mu_a, se, mu_a * rig.mass_kg * rig.omega()))
}
