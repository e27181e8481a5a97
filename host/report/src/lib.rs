//! Figures and a self-contained HTML report of oscillating-tribometer runs and campaigns
//! (`tribo report`).
//!
//! Entry points (names are stable; `tribo demo` and `tribo report` call them):
//!
//! - [`write_record_report`]`(rec: &Record, inputs: &ReportInputs, out_dir: &Path)
//!   -> Result<ReportFiles, ReportError>`: one run. Writes `<fig>.svg` (+ `<fig>.png`) per figure
//!   and `report.html` into `out_dir` (created if missing).
//! - [`write_campaign_report`]`(points: &[CampaignPoint], inputs: &CampaignInputs, out_dir: &Path)
//!   -> Result<ReportFiles, ReportError>`: a set of runs (μ0 vs load, cycles vs temperature),
//!   grouped by the campaign table's bins ([`tribo_store::catalog::Bin`]; feature `store`).
//! - [`record_report`] / [`campaign_report`] build the same figures and tables in memory
//!   ([`Report`]) without writing anything; [`write_report`] writes a [`Report`].
//! - [`store::write_run_report`]`(run: &tribo_store::Run, out_dir: &Path)
//!   -> Result<ReportFiles, ReportError>`: a stored run folder ([`store::run_inputs`] gives its
//!   [`ReportInputs`]); [`store::write_catalog_report`]`(rows: &[CatalogRow], title, out_dir)`:
//!   catalogued runs (a campaign). Behind the default feature `store` (the only part that needs
//!   the SQLite catalogue); without it the crate draws from plain data.
//! - [`regime::classify_regime`]: lubrication regime from `log10` ECR.
//!
//! Figures of a run (file stems): `motion` (x and v with their Mark & Crandall envelopes),
//! `envelopes` (measured envelope and the envelope of each fitted law, dimensionless with SI
//! secondary axes), `law` (the fitted friction laws f(y'), on-board estimate, measured F/N if any),
//! `windows` (Coulomb–viscous constants fitted per amplitude window, thesis Tables 6–7),
//! `force_velocity` and `force_displacement` (loops, only with a force channel), `ecr` (log10 R and
//! the lubrication regime, only with an ECR channel), `temperature` (only with a thermocouple).
//! A missing channel skips its figures with a note on the page, never an error.
//!
//! Figures of a campaign: `mu0_vs_load`, `mu1_vs_load`, `cycles_vs_temperature`.
//!
//! Rendering uses `plotters`: SVG needs no font; PNG uses the embedded DejaVu Sans
//! (`assets/`, Bitstream Vera licence).

#![warn(missing_docs)]

#[cfg(feature = "store")]
/// The report of a campaign (constants against load and temperature).
pub mod campaign;
/// The on-board result beside the host fit.
pub mod crosscheck;
mod html;
/// Figures as panels of series, rendered to SVG and PNG.
pub mod plot;
/// The lubrication regime from the contact resistance.
pub mod regime;
/// The report of one run or record.
pub mod run;
#[cfg(feature = "store")]
/// From the run store to a report (run inputs, campaign points).
pub mod store;

#[cfg(feature = "store")]
pub use campaign::{campaign_report, write_campaign_report, CampaignInputs, CampaignPoint};
pub use plot::Figure;
pub use regime::{classify_regime, Regime, RegimeAssessment};
pub use run::{record_report, write_record_report, ReportInputs, ReportOptions};

use std::path::{Path, PathBuf};

/// Why a report could not be made: what, and, as the source, the error underneath.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The data given cannot be reported (empty, too few amplitude windows…).
    #[error("cannot report: {0}")]
    Input(String),
    /// The record given cannot be reported (no rig constants, inconsistent columns…).
    #[error("cannot report the record")]
    Record(#[source] tribo_physics::record::RecordError),
    /// An analysis a figure needs failed (the envelope, the windowed fits).
    #[error("cannot report: {what}")]
    Analysis {
        /// The analysis that failed.
        what: &'static str,
        /// Its error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Writing a file failed.
    #[error("cannot write {}", path.display())]
    Io {
        /// The file not written.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A figure could not be drawn.
    #[error("cannot draw the figure {figure}")]
    Plot {
        /// The figure's name.
        figure: String,
        /// The renderer's error.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// A figure with nothing to draw (no panel, no finite data).
    #[error("nothing to draw in the figure {figure}: {why}")]
    Empty {
        /// The figure's name.
        figure: String,
        /// What is missing.
        why: String,
    },
}

/// A report in memory: figures, the HTML tables and notes.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Page title.
    pub title: String,
    /// HTML fragment (tables) shown above the figures; already escaped.
    pub summary_html: String,
    /// The figures, in page order.
    pub figures: Vec<Figure>,
    /// Figures skipped or fits failed, one sentence each (shown on the page).
    pub notes: Vec<String>,
    /// Also write PNG files.
    pub png: bool,
    /// Why the record cannot be analysed (no oscillation, too few half cycles, a saturated
    /// channel…), if so: the report then shows the motion but no fitted constant.
    pub not_analysable: Option<String>,
}

/// One written figure.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FigureFile {
    /// File stem of the figure (`motion`).
    pub name: String,
    /// Its heading on the page.
    pub title: String,
    /// The SVG file written.
    pub svg: PathBuf,
    /// The PNG file written, when PNG was asked for.
    pub png: Option<PathBuf>,
}

/// What [`write_report`] wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReportFiles {
    /// `report.html`.
    pub html: PathBuf,
    /// The figures written.
    pub figures: Vec<FigureFile>,
    /// Same as [`Report::notes`].
    pub notes: Vec<String>,
    /// Same as [`Report::not_analysable`].
    pub not_analysable: Option<String>,
}

fn io_err(path: &Path, source: std::io::Error) -> ReportError {
    ReportError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes every figure (SVG, and PNG if asked) and `report.html` into `out_dir`.
pub fn write_report(report: &Report, out_dir: &Path) -> Result<ReportFiles, ReportError> {
    std::fs::create_dir_all(out_dir).map_err(|e| io_err(out_dir, e))?;
    let mut files = Vec::new();
    let mut svgs = Vec::new();
    for fig in &report.figures {
        let svg = plot::to_svg(fig)?;
        let svg_path = out_dir.join(format!("{}.svg", fig.name));
        std::fs::write(&svg_path, &svg).map_err(|e| io_err(&svg_path, e))?;
        let png = if report.png {
            let p = out_dir.join(format!("{}.png", fig.name));
            plot::to_png(fig, &p)?;
            Some(p)
        } else {
            None
        };
        svgs.push(svg);
        files.push(FigureFile {
            name: fig.name.clone(),
            title: fig.title.clone(),
            svg: svg_path,
            png,
        });
    }
    let page = html::page(report, &svgs);
    let html_path = out_dir.join("report.html");
    std::fs::write(&html_path, page).map_err(|e| io_err(&html_path, e))?;
    Ok(ReportFiles {
        html: html_path,
        figures: files,
        notes: report.notes.clone(),
        not_analysable: report.not_analysable.clone(),
    })
}
