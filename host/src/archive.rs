//! What the host does with a run once it is in the store: fit it, export it, catalog it, and find
//! it again by the rig's serial number and run id.

use std::path::{Path, PathBuf};
use tribo_store::{Catalog, HostFit, Results, Run, RunMeta};

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
        lost: u64,
        gaps: usize,
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
    Catalog::open(store)?.upsert(run)?;
    Ok(())
}
