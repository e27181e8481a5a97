//! The report of one run: its figures and result tables.

use crate::html::{esc, table};
use crate::plot::{decimate, Figure, LegendPos, Panel, Secondary, Series, Style};
use crate::regime::{classify_regime, log10_ohm, RegimeAssessment, FULL_FILM_MIN_LOG10};
use crate::{write_report, Report, ReportError, ReportFiles};
use std::fmt::Write as _;
use std::path::Path;
use tribo_physics::envelope::mark_crandall;
use tribo_physics::identify::{self, EnvelopeData, FitOptions, FitResult, LawSpec};
use tribo_physics::record::Units;
use tribo_physics::{Record, Rig};
use tribo_wire::OnboardResult;

/// The envelope is "still moving" while above this fraction of its initial value (ECR regime and
/// cycle count look only at that part of the record).
pub const SLIDING_FRACTION: f64 = 0.05;

/// The motion counts as stopped (for the time axes shown) below this fraction of the initial
/// envelope.
pub const STOP_FRACTION: f64 = 0.01;

mod figures;
mod summary;
use figures::*;
use summary::*;

/// How the report is made.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportOptions {
    /// Laws to fit when [`ReportInputs::fits`] has no result for them.
    pub laws: Vec<LawSpec>,
    /// Options of those fits.
    pub fit: FitOptions,
    /// Also write PNG files (SVG is always written).
    pub png: bool,
    /// Points per curve kept in the figures (min/max decimation keeps the peaks).
    pub plot_bins: usize,
    /// Amplitude windows of the windowed Coulomb–viscous fits (thesis Tables 6–7); < 2 = none.
    pub windows: usize,
}

impl Default for ReportOptions {
    fn default() -> Self {
        ReportOptions {
            laws: vec![
                LawSpec::Coulomb,
                LawSpec::Viscous,
                LawSpec::CoulombViscous,
                LawSpec::Quadratic,
            ],
            fit: FitOptions {
                max_points: 800,
                ..FitOptions::default()
            },
            png: true,
            plot_bins: 700,
            windows: 4,
        }
    }
}

/// What is known about a run besides its samples.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ReportInputs {
    /// Page title (e.g. the run id); empty = "Run report".
    pub title: String,
    /// Free key/value lines for the run table (label, sample, lubricant, created, firmware…).
    pub meta: Vec<(String, String)>,
    /// The rig's own analysis, compared with the host fits.
    pub onboard: Option<OnboardResult>,
    /// Host fits already made (e.g. by `tribo fit` or the store); laws of
    /// [`ReportOptions::laws`] missing here are fitted by the report.
    pub fits: Vec<FitResult>,
    /// What to draw (laws, PNG).
    pub options: ReportOptions,
}

/// Builds and writes the report of one run: `<fig>.svg`, `<fig>.png` and `report.html` in
/// `out_dir`.
pub fn write_record_report(
    rec: &Record,
    inputs: &ReportInputs,
    out_dir: &Path,
) -> Result<ReportFiles, ReportError> {
    let report = record_report(rec, inputs)?;
    write_report(&report, out_dir)
}

/// Dimensionless view of a record and the numbers every figure needs.
struct View<'a> {
    rec: &'a Record,
    rig: Rig,
    si: bool,
    tau: Vec<f64>,
    y: Vec<f64>,
    ydot: Vec<f64>,
    /// Mark & Crandall envelope (dimensionless).
    a: Vec<f64>,
    /// Index one past the last sample where the pin still moves.
    sliding_end: usize,
    /// Index of the last sample shown on time axes: the stop plus 15 % (a long rest tail would
    /// squeeze the motion into a corner).
    show_end: usize,
}

impl View<'_> {
    /// Sample `i` of the time axis in display units (s or τ).
    fn t(&self, i: usize) -> f64 {
        self.rec.t[i]
    }
    /// Time range shown, stretched by `factor` past the stop.
    fn t_range(&self, factor: f64) -> (f64, f64) {
        let n = self.rec.len();
        let last = ((self.show_end as f64 * factor) as usize).clamp(1, n - 1);
        (self.rec.t[0], self.rec.t[last])
    }
    fn t_label(&self) -> &'static str {
        if self.si {
            "t (s)"
        } else {
            "τ = Ωt"
        }
    }
}

/// Builds the report of one run in memory. Errors only for unusable input (empty, NaN, too short,
/// no rig constants); missing channels and failed fits become notes.
pub fn record_report(rec: &Record, inputs: &ReportInputs) -> Result<Report, ReportError> {
    if rec.is_empty() {
        return Err(ReportError::Input("the record has no samples".into()));
    }
    rec.validate().map_err(ReportError::Record)?;
    let rig = rec.rig().map_err(ReportError::Record)?;
    let (tau, y, ydot) = rec.dimensionless().map_err(ReportError::Record)?;
    let a = mark_crandall(&y, &ydot);
    let a0 = a[0];
    if a0 <= 0.0 {
        return Err(ReportError::Input(
            "the record starts at rest at the origin: there is no oscillation to report".into(),
        ));
    }
    let sliding_end = a
        .iter()
        .position(|&v| v < SLIDING_FRACTION * a0)
        .unwrap_or(a.len());
    let stop = a
        .iter()
        .position(|&v| v < STOP_FRACTION * a0)
        .unwrap_or(a.len());
    let show_end = ((stop as f64 * 1.15) as usize).min(a.len() - 1);
    let view = View {
        rec,
        rig,
        si: rec.units == Units::Si,
        tau,
        y,
        ydot,
        a,
        sliding_end,
        show_end,
    };
    let opts = &inputs.options;
    let mut notes = Vec::new();

    // A record that cannot be analysed gets its motion drawn, and no fitted constant.
    let not_analysable = identify::screen(&view.tau, &view.y, &view.ydot)
        .err()
        .map(|e| e.to_string());
    if let Some(why) = &not_analysable {
        notes.push(format!("not analysable: {why}; no law is fitted"));
    }
    // Fits: the ones given, then the missing laws.
    let mut fits: Vec<FitResult> = if not_analysable.is_some() {
        Vec::new()
    } else {
        inputs.fits.clone()
    };
    for spec in opts.laws.iter().filter(|_| not_analysable.is_none()) {
        if fits.iter().any(|f| f.law == *spec) {
            continue;
        }
        match identify::fit(rec, *spec, &opts.fit) {
            Ok(f) => fits.push(f),
            Err(e) => notes.push(format!("{} law: {e}", spec.name())),
        }
    }

    let mut figures = vec![motion_figure(&view, opts.plot_bins)];
    figures.push(envelope_figure(
        &view,
        &fits,
        &opts.fit,
        opts.plot_bins,
        &mut notes,
    )?);
    figures.push(law_figure(&view, &fits, inputs.onboard.as_ref()));
    if opts.windows >= 2 && not_analysable.is_none() {
        match windows_figure(&view, opts) {
            Ok(f) => figures.push(f),
            Err(e) => notes.push(format!("windowed fits skipped: {e}")),
        }
    }
    match &rec.ft {
        Some(ft) => {
            let (fv, fx) = force_figures(&view, ft, &fits, opts.plot_bins);
            figures.push(fv);
            figures.push(fx);
        }
        None => notes.push(
            "no force channel in this run: the force–velocity and force–displacement loops are skipped"
                .into(),
        ),
    }
    let mut regime = None;
    match &rec.ecr {
        Some(ecr) => {
            let (fig, r) = ecr_figure(&view, ecr)?;
            figures.push(fig);
            match r {
                Ok(r) => regime = Some(r),
                Err(e) => notes.push(e.to_string()),
            }
        }
        None => notes.push("no ECR channel in this run: the lubrication regime is unknown".into()),
    }
    if let Some(temp) = &rec.temp {
        figures.push(temperature_figure(&view, temp, opts.plot_bins));
    }

    let title = if inputs.title.is_empty() {
        "Run report".to_string()
    } else {
        inputs.title.clone()
    };
    let summary_html = summary(&view, inputs, &fits, regime.as_ref());
    Ok(Report {
        title,
        summary_html,
        figures,
        notes,
        png: opts.png,
        not_analysable,
    })
}

/// Oscillation cycles of the motion: half-cycles / 2. A half-cycle ends at each velocity reversal
/// whose displacement differs from the previous reversal (or the release) by more than 1 % of the
/// initial amplitude, so noise at rest or around a slow turning point is not counted.
pub fn count_cycles(y: &[f64], ydot: &[f64]) -> f64 {
    let n = y.len().min(ydot.len());
    if n < 2 {
        return 0.0;
    }
    let a0 = y[0].hypot(ydot[0]);
    let thr = 0.01 * a0;
    let mut last = y[0];
    let mut half = 0usize;
    for i in 1..n {
        let (a, b) = (ydot[i - 1], ydot[i]);
        if (a > 0.0 && b <= 0.0) || (a < 0.0 && b >= 0.0) {
            let j = if a.abs() < b.abs() { i - 1 } else { i };
            if (y[j] - last).abs() > thr {
                half += 1;
                last = y[j];
            } else if y[j].abs() > last.abs() {
                // A noisy turning point: keep the outermost value as the extremum.
                last = y[j];
            }
        }
    }
    half as f64 / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_physics::sensor::Rng;

    #[test]
    fn cycles_of_a_decaying_cosine_then_noisy_rest() {
        // 10 cycles of a Coulomb-like decay (amplitude 2 → 0.5), then 400 samples at rest at
        // y = 0.01 with velocity noise that reverses sign at every sample.
        let mut rng = Rng::new(7);
        let dt = 0.01;
        let n_move = (20.0 * std::f64::consts::PI / dt) as usize;
        let (mut y, mut ydot) = (Vec::new(), Vec::new());
        for i in 0..n_move {
            let t = i as f64 * dt;
            let amp = 2.0 - 1.5 * t / (20.0 * std::f64::consts::PI);
            y.push(amp * t.cos() + 1e-4 * rng.normal());
            ydot.push(-amp * t.sin() + 1e-4 * rng.normal());
        }
        for _ in 0..400 {
            y.push(0.45 + 1e-4 * rng.normal());
            ydot.push(1e-3 * rng.normal());
        }
        assert_eq!(count_cycles(&y, &ydot), 10.0);
        // Half of it: 5 cycles.
        assert_eq!(
            count_cycles(&y[..n_move / 2 + 10], &ydot[..n_move / 2 + 10]),
            5.0
        );
    }
}
