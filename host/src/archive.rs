//! What the host does with a run once it is in the store: fit it, export it, catalog it, and find
//! it again by the rig's serial number and run id.

use std::path::{Path, PathBuf};
use tribo_store::{HostFit, Results, Run, RunCatalog, RunMeta};

/// The stored run taken on rig `serial` as its run `run_id`, if any (newest first).
pub fn find_run(store: &Path, serial: &str, run_id: u32) -> anyhow::Result<Option<PathBuf>> {
    Ok(runs_of_rig(store, serial)?
        .into_iter()
        .rev()
        .find(|r| r.1 == run_id)
        .map(|r| r.0))
}

/// The highest run number of rig `serial` in the store (what [`HostMsg::RunFloor`] tells the
/// rig), `None` when the store holds none of its runs.
///
/// [`HostMsg::RunFloor`]: tribo_wire::HostMsg::RunFloor
pub fn highest_run(store: &Path, serial: &str) -> anyhow::Result<Option<u32>> {
    Ok(runs_of_rig(store, serial)?.into_iter().map(|r| r.1).max())
}

/// The run folders of rig `serial` in the store with the rig's number of each, oldest first (a
/// folder whose metadata cannot be read is left out).
fn runs_of_rig(store: &Path, serial: &str) -> anyhow::Result<Vec<(PathBuf, u32)>> {
    if !store.is_dir() {
        return Ok(Vec::new());
    }
    Ok(tribo_store::run::list_run_dirs(store)?
        .into_iter()
        .filter_map(|d| {
            let text = std::fs::read_to_string(d.join(tribo_store::run::META_FILE)).ok()?;
            let m = toml::from_str::<RunMeta>(&text).ok()?;
            let id = m.device_run_id?;
            m.device
                .as_ref()
                .is_some_and(|x| x.serial == serial)
                .then_some((d, id))
        })
        .collect())
}

/// Why the host did not fit a stored run.
#[derive(Debug, thiserror::Error)]
pub enum HostFitError {
    /// The rig lost samples: a fit across the gaps would be wrong.
    #[error(
        "the rig lost {lost} samples in {gaps} acquisition gap(s): not fitted across them; \
         `tribo fit {flag} {}` fits the longest stretch without one",
        dir.display(),
        flag = crate::LONGEST_CLEAN_STRETCH_FLAG
    )]
    Gaps {
        /// Samples the rig lost.
        lost: u64,
        /// Acquisition gaps they were lost in.
        gaps: usize,
        /// The run folder.
        dir: PathBuf,
    },
    /// The run's samples could not be read as a record.
    #[error("the run's samples")]
    Samples(#[source] tribo_store::StoreError),
    /// The samples are not a record the fit can take.
    #[error("the run's record")]
    Record(#[source] tribo_physics::record::RecordError),
    /// The fit failed.
    #[error("the Coulomb–viscous fit")]
    Fit(#[source] tribo_physics::identify::FitError),
}

/// The host's Coulomb–viscous fit of a run (Levenberg–Marquardt on the envelope).
pub fn host_fit(run: &Run) -> Result<HostFit, HostFitError> {
    use tribo_physics::identify::{fit, FitOptions};
    if run.gaps().next().is_some() {
        return Err(HostFitError::Gaps {
            lost: run.lost_samples(),
            gaps: run.gaps().count(),
            dir: run.dir().to_path_buf(),
        });
    }
    let rec = run.record().map_err(HostFitError::Samples)?;
    rec.validate().map_err(HostFitError::Record)?;
    // The apparatus alone (load 0): its damping μ_a (viscous; stored as μ1), no Coulomb level.
    let spec = tribo_physics::identify::law_for(&rec, tribo_physics::LawSpec::CoulombViscous);
    let r = fit(&rec, spec, &FitOptions::default()).map_err(HostFitError::Fit)?;
    let fitted = |j: usize| spec.powers().contains(&j);
    let mu = |v: &[f64], j: usize| {
        if fitted(j) {
            v.get(j).copied().unwrap_or(f64::NAN)
        } else {
            f64::NAN
        }
    };
    Ok(HostFit {
        law: r.law,
        mu0: mu(&r.mu, 0),
        mu1: mu(&r.mu, 1),
        gap: r.gap,
        converged: r.converged,
        mu0_se: mu(&r.mu_se, 0),
        mu1_se: mu(&r.mu_se, 1),
        verdict: Some(r.verdict.name().into()),
    })
}

/// Fits the run on the host, saves the results and the CSV export, and catalogs it.
pub fn analyse_and_catalog(run: &mut Run, store: &Path) -> anyhow::Result<()> {
    let mut results = Results {
        onboard: run.result().copied(),
        host: None,
        host_error: None,
    };
    if run.block_count() > 0 {
        match host_fit(run) {
            Ok(f) => results.host = Some(f),
            // Kept in the run's results as a sentence, with its causes.
            Err(e) => results.host_error = Some(crate::exit::chain_text(&e)),
        }
        // A record the physics cannot take (an unloaded run has no rig constants for it) has no
        // CSV export; the run itself is stored all the same.
        if let Err(e) = run.export_csv(&run.dir().join(tribo_store::run::CSV_FILE)) {
            results
                .host_error
                .get_or_insert_with(|| format!("no CSV export: {e}"));
        }
    }
    run.save_results(results)?;
    RunCatalog::open(store)?.upsert(run)?;
    Ok(())
}

/// A run of the store that a table or a campaign report leaves out (its log is damaged, or it is
/// not stored whole), with why and how to repair it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LeftOut {
    /// The run folder left out.
    pub dir: PathBuf,
    /// `damaged: …; `tribo pull --salvage DIR` keeps …` or `incomplete: …; `tribo pull DIR` …`.
    pub why: String,
}

/// The runs of `store` matching `filter` (its campaign, label and rig; a damaged run by its
/// metadata) that are not whole: a frame log that cannot be read (damaged), or a run not stored
/// whole (incomplete, aborted runs aside). Read from the store's catalog (brought up to date) and,
/// for the folders it cannot index, from their metadata: no run is left out without a word.
pub fn left_out(store: &Path, filter: &tribo_store::Filter) -> anyhow::Result<Vec<LeftOut>> {
    use tribo_store::run::{list_run_dirs, META_FILE};
    if !store.is_dir() {
        return Ok(Vec::new());
    }
    let cat = RunCatalog::open(store)?;
    cat.refresh(false)?;
    let mut out = Vec::new();
    for r in cat.list(filter)? {
        if r.status == "incomplete" || r.status == "recording" {
            out.push(LeftOut {
                why: format!(
                    "{}: {}; `tribo pull {}` fetches the rest while the rig holds it",
                    r.status,
                    r.completeness,
                    r.path.display()
                ),
                dir: r.path,
            });
        }
    }
    let known: std::collections::BTreeSet<String> = cat
        .list(&tribo_store::Filter::default())?
        .into_iter()
        .map(|r| r.id)
        .collect();
    let matches = |m: &RunMeta| {
        filter
            .campaign
            .as_ref()
            .is_none_or(|c| m.campaign.as_ref() == Some(c))
            && filter
                .label
                .as_ref()
                .is_none_or(|l| m.label.as_ref().is_some_and(|x| x.contains(l.as_str())))
            && filter
                .rig
                .as_ref()
                .is_none_or(|s| m.device.as_ref().is_some_and(|d| d.serial == *s))
    };
    for d in list_run_dirs(store)? {
        let id = d
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        if known.contains(&id) {
            continue;
        }
        let meta = std::fs::read_to_string(d.join(META_FILE))
            .ok()
            .and_then(|t| toml::from_str::<RunMeta>(&t).ok());
        if meta.as_ref().is_some_and(|m| !matches(m)) {
            continue;
        }
        let why = match tribo_store::Run::open(&d) {
            Err(e) => format!(
                "damaged, its frame log cannot be read ({}); `tribo pull --salvage {}` keeps every \
                 intact record and fetches the rest while the rig holds it",
                e.msg,
                d.display()
            ),
            Ok(run) => format!("not in the catalog ({})", run.completeness().summary()),
        };
        out.push(LeftOut { dir: d, why });
    }
    Ok(out)
}

/// Says on standard error which runs a table or report left out, and returns the status-3 error
/// that ends the command (`None` when none was).
pub fn report_left_out(what: &str, left: &[LeftOut]) -> Option<crate::exit::Incomplete> {
    if left.is_empty() {
        return None;
    }
    for l in left {
        crate::errln!("left out of the {what}: {}: {}", l.dir.display(), l.why);
    }
    Some(crate::exit::Incomplete(format!(
        "the {what} leaves out {} run{} that {} not whole (listed above, each with how to repair it)",
        left.len(),
        if left.len() == 1 { "" } else { "s" },
        if left.len() == 1 { "is" } else { "are" }
    )))
}
