//! The analysis both the command line and the Python package give: the on-board cross-check of a
//! host fit, an apparatus record's damping, and the JSON of a fit and of an explanation; and the
//! checks between opening a record and analysing it (`plausible.rs`); whether the velocity column is
//! the displacement's derivative (`identity.rs`: swapped input cables). Every refusal is an
//! [`AnalysisError`]; `cmd::exit` maps it to an exit status, the Python package to an exception.

pub mod identity;
mod plausible;

pub use plausible::{
    apply_rig_flags, load_analysable_for_fit, load_for_analysis, open_analysable,
    plausible_apparatus_mu1, plausible_record, RigFlags, RigUsed, Source, MAX_APPARATUS_MU1,
};

use crate::crosscheck::{CrossCheck, OnboardSource};
use crate::load::LoadError;
use tribo_physics::identify::{FitResult, LawSpec};
use tribo_physics::Record;

/// The on-board cross-check of a Coulomb–viscous host fit: the rig's stored result for a run
/// (the one [`crate::load::open`] opened), else the firmware's pipeline over the record's samples. `Ok(None)` for other laws (the
/// rig fits only Coulomb–viscous); `Err(why)` when there is no on-board result to compare with.
pub fn cross_check(
    run: Option<&tribo_store::Run>,
    rec: &Record,
    r: &FitResult,
) -> std::result::Result<Option<CrossCheck>, String> {
    if r.law != LawSpec::CoulombViscous {
        return Ok(None);
    }
    let stored = run.and_then(|run| run.result().copied());
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

/// Why a record was not analysed: the loader's error, or a check or a fit that refused it. Its
/// variants say what kind of refusal it is (a usage error, a record that cannot be analysed as
/// written, an error); `cmd::exit` decides the statuses, the Python package the exceptions.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// The record could not be opened ([`crate::load::open`]).
    #[error(transparent)]
    Load(#[from] LoadError),
    /// The record was read but has a sample that is not finite: nothing can be analysed.
    #[error("not analysable: {}", crate::exit::chain_text(.0))]
    NonFinite(LoadError),
    /// The record cannot be analysed as written (a rig constant in its header or a motion beyond
    /// what the rig can have, most likely another unit than its header says); the message names it.
    #[error("{0}")]
    NotAnalysable(String),
    /// A value given (a flag, an option) outside what the rig or its blades can have; the
    /// message names the likely slip.
    #[error("{0}")]
    Usage(String),
    /// A request the record cannot take (rig flags for a dimensionless record, no rig constants
    /// given at all); the message says what to add.
    #[error("{0}")]
    Request(String),
    /// Rig constants the physics refuses.
    #[error(transparent)]
    Rig(#[from] tribo_physics::InvalidParameter),
    /// The fit failed.
    #[error(transparent)]
    Fit(#[from] tribo_physics::identify::FitError),
    /// One of the above, of the record named (its path or name).
    #[error("{name}")]
    Of {
        /// The record's path or name.
        name: String,
        /// What refused it.
        #[source]
        source: Box<AnalysisError>,
    },
}

impl AnalysisError {
    /// This error, of the record `name` (`name: error` on one line).
    pub fn of(self, name: String) -> AnalysisError {
        AnalysisError::Of {
            name,
            source: Box::new(self),
        }
    }

    /// The refusal itself, under the names of [`AnalysisError::Of`].
    pub fn innermost(&self) -> &AnalysisError {
        match self {
            AnalysisError::Of { source, .. } => source.innermost(),
            e => e,
        }
    }
}

/// What to fit: `tribo fit`'s options (the Python package's `fit`).
#[derive(Debug, Clone, PartialEq)]
pub struct FitRequest {
    /// The law asked for (an apparatus record, load 0, gets its damping instead: [`Fitted::spec`]).
    pub law: LawSpec,
    /// Rig constants given instead of the record's.
    pub flags: RigFlags,
    /// The blades' damping μ_a held fixed in the fit (0 to [`MAX_APPARATUS_MU1`]).
    pub apparatus_mu1: f64,
    /// Independent fits over this many windows of the record (0: none).
    pub windows: usize,
}

/// The on-board cross-check: the comparison, `None` for a law the rig does not fit, or why there
/// is none.
pub type Check = Result<Option<CrossCheck>, String>;

/// A law fitted to a record: the one estimator of `tribo fit` and the Python package.
#[derive(Debug)]
pub struct Fitted {
    /// The law fitted: the one asked for, or the apparatus's damping for a record at load 0.
    pub spec: LawSpec,
    /// The rig constants used and where each came from.
    pub rig: RigUsed,
    /// The options the fit ran with.
    pub options: tribo_physics::identify::FitOptions,
    /// The fitted constants with their ± and the fit's diagnostics.
    pub result: FitResult,
    /// The check of the fit against the record (residuals, agreement).
    pub check: Check,
    /// One fit per window, when asked for.
    pub windows: Option<Vec<tribo_physics::identify::WindowFit>>,
}

/// What a fit gave: constants, or a record no constant can be fitted to.
#[derive(Debug)]
pub enum FitOutcome {
    /// Constants were fitted.
    Fitted(Box<Fitted>),
    /// Too few half cycles, no motion…: no constant is fitted (status 3).
    NotAnalysable {
        /// The rig constants the analysis used.
        rig: RigUsed,
        /// Why the record cannot be analysed.
        why: tribo_physics::identify::NotAnalysable,
    },
}

/// Fits `req.law` to a record [`crate::load::open`] opened (its rig constants replaced by the
/// flags' first), with the on-board cross-check against its `run`'s result. A flag or μ_a out of
/// range is an [`AnalysisError::Usage`]; a fit that fails otherwise is an error
/// ([`AnalysisError::Of`] the record's `name`).
pub fn fit_law(
    name: &str,
    rec: &mut Record,
    defaults: &[String],
    run: Option<&tribo_store::Run>,
    req: &FitRequest,
) -> Result<FitOutcome, AnalysisError> {
    use tribo_physics::identify::{fit, fit_windows, FitError, FitOptions};
    plausible_apparatus_mu1(req.apparatus_mu1)?;
    let rig = apply_rig_flags(rec, req.flags, defaults)?;
    let options = FitOptions {
        apparatus_mu1: req.apparatus_mu1,
        ..FitOptions::default()
    };
    // The apparatus alone (load 0): no friction law, only the blades' damping μ_a (viscous).
    let spec = tribo_physics::identify::law_for(rec, req.law);
    let result = match fit(rec, spec, &options) {
        Ok(r) => r,
        Err(FitError::NotAnalysable(why)) => return Ok(FitOutcome::NotAnalysable { rig, why }),
        Err(e) => return Err(AnalysisError::Fit(e).of(name.to_string())),
    };
    // `Ok(None)` for a law the rig does not fit (the apparatus run's viscous one included).
    let check = cross_check(run, rec, &result);
    let windows = if req.windows > 0 {
        Some(fit_windows(rec, spec, req.windows, &options)?)
    } else {
        None
    };
    Ok(FitOutcome::Fitted(Box::new(Fitted {
        spec,
        rig,
        options,
        result,
        check,
        windows,
    })))
}

impl Fitted {
    /// `tribo fit --json`'s object (the Python package's `Fit`): the fit, `record` (its name),
    /// `rig`, `defaults`, `cross_check`, an apparatus record's `mu_a`, and `windows` when asked.
    pub fn json(&self, record: &str, rec: &Record) -> serde_json::Result<serde_json::Value> {
        let mut j = serde_json::to_value(&self.result)?;
        j["record"] = record.into();
        j["rig"] = serde_json::to_value(self.rig)?;
        j["defaults"] = serde_json::to_value(self.rig.defaults())?;
        j["cross_check"] = cross_check_json(&self.check)?;
        if let Some((mu_a, se, c)) = apparatus_damping(rec, &self.result) {
            j["apparatus"] = true.into();
            j["mu_a"] = mu_a.into();
            j["mu_a_se"] = serde_json::to_value(se)?;
            j["c_n_s_per_m"] = c.into();
        }
        if let Some(w) = &self.windows {
            j["windows"] = serde_json::to_value(w)?;
        }
        // The velocity column against the displacement's derivative (`null`: too little motion).
        j["channels"] = serde_json::to_value(identity::record_velocity_check(rec))?;
        Ok(j)
    }
}

/// `tribo fit --json`'s object for a record no constant can be fitted to.
pub fn not_analysable_json(
    record: &str,
    rig: &RigUsed,
    why: &tribo_physics::identify::NotAnalysable,
) -> serde_json::Value {
    serde_json::json!({
        "record": record,
        "verdict": "not-analysable",
        "reason": why.name(),
        "message": why.to_string(),
        "rig": rig,
        "defaults": rig.defaults(),
    })
}

/// `tribo explain --json`'s object (the Python package's `Explanation`): the explanation and its
/// `cross_check`.
pub fn explanation_json(
    ex: &tribo_explain::Explanation,
    check: &Check,
) -> serde_json::Result<serde_json::Value> {
    let mut j = serde_json::to_value(ex)?;
    j["cross_check"] = cross_check_json(check)?;
    Ok(j)
}
