//! The report of a campaign: friction constants against load, oscillation count against
//! temperature, mean ± sample standard deviation over the repetitions.

use crate::html::table;
use crate::plot::{Figure, LegendPos, Panel, Series, Style};
use crate::{write_report, Report, ReportError, ReportFiles};
use std::collections::BTreeMap;
use std::path::Path;
use tribo_physics::stats::mean_sd;
use tribo_store::catalog::Bin;

/// One run of a campaign (e.g. a row of the store's catalog).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CampaignPoint {
    /// Run id (shown in the table).
    pub run: String,
    /// Normal load N (N).
    pub load_n: f64,
    /// Nominal plane temperature (°C): the setpoint, else the measured one.
    pub temp_c: Option<f64>,
    /// The heater's setpoint (°C); `None`: the heater was off. What the run is grouped by
    /// ([`Bin::temp`], the rule of `tribo table`).
    pub temp_setpoint_c: Option<f64>,
    /// Dimensionless Coulomb and viscous constants of the host fit.
    pub mu0: Option<f64>,
    /// The viscous one (μ1).
    pub mu1: Option<f64>,
    /// Their standard errors (`None` when not known): drawn as each run's bar, and the y axis
    /// never spans less than a few of them (a difference far below the ± is not drawn as a slope).
    pub mu0_se: Option<f64>,
    /// μ1's standard error.
    pub mu1_se: Option<f64>,
    /// Oscillation cycles until the stop.
    pub cycles: Option<f64>,
}

/// Page-level inputs of a campaign report.
#[derive(Debug, Clone, PartialEq)]
pub struct CampaignInputs {
    /// Page title (e.g. the campaign name).
    pub title: String,
    /// Also write PNG files.
    pub png: bool,
}

impl Default for CampaignInputs {
    fn default() -> Self {
        CampaignInputs {
            title: "Campaign report".into(),
            png: true,
        }
    }
}

/// Builds and writes a campaign report into `out_dir`.
pub fn write_campaign_report(
    points: &[CampaignPoint],
    inputs: &CampaignInputs,
    out_dir: &Path,
) -> Result<ReportFiles, ReportError> {
    write_report(&campaign_report(points, inputs)?, out_dir)
}

/// The runs of one group by x bin: `(x values, values)`.
type Cells = BTreeMap<Bin, (Vec<f64>, Vec<f64>)>;

/// One figure: `value` against `x`, one series per group bin (`group`, `None`: not recorded),
/// means over the runs of each x bin (`x_bin`) with ±sd bars, plus the single runs at their own
/// `x`. The bins are the campaign table's ([`Bin`]): a figure and `tribo table` never group the
/// same runs differently.
#[allow(clippy::too_many_arguments)]
fn grouped_figure(
    points: &[CampaignPoint],
    name: &str,
    title: &str,
    caption: &str,
    x_label: &str,
    y_label: &str,
    x: impl Fn(&CampaignPoint) -> Option<f64>,
    x_bin: impl Fn(&CampaignPoint) -> Option<Bin>,
    group: impl Fn(&CampaignPoint) -> Option<Bin>,
    value: impl Fn(&CampaignPoint) -> Option<f64>,
    value_se: impl Fn(&CampaignPoint) -> Option<f64>,
) -> Option<Figure> {
    let rows: Vec<(f64, Bin, Option<Bin>, f64)> = points
        .iter()
        .filter_map(|p| Some((x(p)?, x_bin(p)?, group(p), value(p)?)))
        .filter(|(xv, _, _, val)| xv.is_finite() && val.is_finite())
        .collect();
    // Each run's own ± (x, value, se), for its bar and the axis floor.
    let run_se: Vec<(f64, f64, f64)> = points
        .iter()
        .filter_map(|p| Some((x(p)?, value(p)?, value_se(p)?)))
        .filter(|(a, b, c)| a.is_finite() && b.is_finite() && c.is_finite() && *c > 0.0)
        .collect();
    if rows.is_empty() {
        return None;
    }
    // group bin (None: not recorded) -> x bin -> (xs, values)
    let mut groups: BTreeMap<Option<Bin>, Cells> = BTreeMap::new();
    for &(xv, xb, g, val) in &rows {
        let cell = groups.entry(g).or_default().entry(xb).or_default();
        cell.0.push(xv);
        cell.1.push(val);
    }
    let any_group = groups.keys().any(Option::is_some);
    let mut p = Panel::new(title, x_label, y_label);
    p.legend_pos = LegendPos::Auto;
    for (i, (g, cells)) in groups.iter().enumerate() {
        let label = match g {
            Some(g) => g.label(),
            None if !any_group => "all runs".to_string(),
            None => "not recorded".to_string(),
        };
        let mut means = Vec::new();
        let mut bars = Vec::new();
        let mut singles = Vec::new();
        for (xb, (xs, vals)) in cells {
            let (m, sd) = mean_sd(vals);
            // A setting's mean sits at the setting; the heater-off runs' at their mean reading.
            let xm = xb.value().unwrap_or_else(|| mean_sd(xs).0);
            means.push((xm, m));
            if vals.len() > 1 {
                bars.push((xm, m - sd, m + sd));
            }
            singles.extend(xs.iter().zip(vals).map(|(x, v)| (*x, *v)));
        }
        means.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut s = Series::line(format!("{label} (mean ± sd)"), i, means);
        s.errors = bars;
        p.series.push(s);
        p.series
            .push(Series::line("", i, singles).with_style(Style::Points(2)));
    }
    if !run_se.is_empty() {
        p.series.push(
            Series::line("each run ± its standard error", groups.len(), Vec::new())
                .with_style(Style::Points(1)),
        );
        if let Some(s) = p.series.last_mut() {
            s.errors = run_se.iter().map(|&(x, v, e)| (x, v - e, v + e)).collect();
        }
        p.y_range = y_range_with_floor(&rows, &run_se);
    }
    Some(Figure {
        name: name.into(),
        title: title.into(),
        caption: caption.into(),
        panels: vec![p],
        size: (900, 600),
    })
}

/// The value axis: the data (and the runs' bars) with a margin, but never narrower than 6 × the
/// runs' median standard error, so that a difference far below the ± is not stretched into a
/// slope.
fn y_range_with_floor(
    rows: &[(f64, Bin, Option<Bin>, f64)],
    run_se: &[(f64, f64, f64)],
) -> Option<(f64, f64)> {
    let mut ses: Vec<f64> = run_se.iter().map(|r| r.2).collect();
    ses.sort_by(f64::total_cmp);
    let se = *ses.get(ses.len() / 2)?;
    let vals = rows
        .iter()
        .map(|r| r.3)
        .chain(run_se.iter().flat_map(|r| [r.1 - r.2, r.1 + r.2]));
    let (lo, hi) = vals.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if lo > hi {
        return None;
    }
    let mid = 0.5 * (lo + hi);
    let half = (0.52 * (hi - lo)).max(3.0 * se);
    Some((mid - half, mid + half))
}

fn fmt_opt(v: Option<f64>, prec: usize) -> String {
    match v {
        Some(x) if x.is_finite() => format!("{x:.prec$}"),
        _ => "—".into(),
    }
}

/// Builds a campaign report in memory. Errors if there is no point or a point has a bad load.
pub fn campaign_report(
    points: &[CampaignPoint],
    inputs: &CampaignInputs,
) -> Result<Report, ReportError> {
    if points.is_empty() {
        return Err(ReportError::Input("the campaign has no runs".into()));
    }
    if let Some(p) = points
        .iter()
        .find(|p| !(p.load_n.is_finite() && p.load_n >= 0.0))
    {
        return Err(ReportError::Input(format!(
            "run {}: load {} N is not a finite non-negative number",
            p.run, p.load_n
        )));
    }
    let mut notes = Vec::new();
    let mut figures = Vec::new();
    let load = |p: &CampaignPoint| Bin::load(p.load_n);
    let temp = |p: &CampaignPoint| Bin::temp(p.temp_setpoint_c);
    let f = grouped_figure(
        points,
        "mu0_vs_load",
        "Coulomb constant μ0 vs normal load",
        "μ0 is a friction coefficient: for a Coulomb contact it does not depend on the load, so the \
         points of a temperature should lie on a horizontal line within the method's precision \
         (± 0.001). A trend with the load means the contact is not Coulomb (e.g. a film whose \
         thickness depends on the pressure).",
        "normal load N (N)",
        "μ0",
        |p| Some(p.load_n),
        load,
        temp,
        |p| p.mu0,
        |p| p.mu0_se,
    );
    match f {
        Some(f) => figures.push(f),
        None => notes.push("no run has a μ0: the μ0-vs-load figure is skipped".into()),
    }
    let f = grouped_figure(
        points,
        "mu1_vs_load",
        "Viscous constant μ1 vs normal load",
        "μ1 = c/(mΩ) of a viscous damper does not depend on the load; the apparatus alone gives \
         μ1 = 0.0011 ± 0.0002. A μ1 that grows as the temperature drops follows the lubricant's \
         viscosity.",
        "normal load N (N)",
        "μ1",
        |p| Some(p.load_n),
        load,
        temp,
        |p| p.mu1,
        |p| p.mu1_se,
    );
    match f {
        Some(f) => figures.push(f),
        None => notes.push("no run has a μ1: the μ1-vs-load figure is skipped".into()),
    }
    let f = grouped_figure(
        points,
        "cycles_vs_temperature",
        "Oscillation cycles vs temperature",
        "the number of cycles before the stop is the most direct reading of friction: more cycles, \
         less friction. A change with temperature at a given load shows the lubricant's \
         (or the film's) response to heating; at least 5 cycles are needed for a fit.",
        "plane temperature (°C)",
        "cycles until the stop",
        |p| p.temp_c,
        temp,
        load,
        |p| p.cycles,
        |_| None,
    );
    match f {
        Some(f) => figures.push(f),
        None => notes.push(
            "no run has both a temperature and a cycle count: the cycles-vs-temperature figure is skipped"
                .into(),
        ),
    }
    let rows: Vec<Vec<String>> = points
        .iter()
        .map(|p| {
            vec![
                p.run.clone(),
                format!("{:.3}", p.load_n),
                fmt_opt(p.temp_c, 1),
                fmt_opt(p.mu0, 5),
                fmt_opt(p.mu1, 5),
                fmt_opt(p.cycles, 1),
            ]
        })
        .collect();
    let mut summary = String::from("<h2>Runs</h2>\n");
    summary.push_str(&table(
        &["run", "load (N)", "temperature (°C)", "μ0", "μ1", "cycles"],
        &rows,
    ));
    Ok(Report {
        title: inputs.title.clone(),
        summary_html: summary,
        figures,
        notes,
        png: inputs.png,
        not_analysable: None,
    })
}
