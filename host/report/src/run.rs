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
    rec.validate().map_err(|e| ReportError::Input(e.0))?;
    let rig = rec.rig().map_err(|e| ReportError::Input(e.0))?;
    let (tau, y, ydot) = rec.dimensionless().map_err(|e| ReportError::Input(e.0))?;
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
        if fits.iter().any(|f| f.law == spec.name()) {
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

fn pts(xs: impl Iterator<Item = f64>, ys: impl Iterator<Item = f64>) -> Vec<(f64, f64)> {
    xs.zip(ys).collect()
}

/// Displacement and velocity with their envelopes.
fn motion_figure(v: &View, bins: usize) -> Figure {
    let n = v.rec.len();
    let lx = v.rig.length_scale_m();
    let omega = v.rig.omega();
    // Display units: µm and mm/s for SI records.
    let (xs, vs, x_lab, v_lab) = if v.si {
        (1e6, 1e3, "x (µm)", "v (mm/s)")
    } else {
        (1.0, 1.0, "y = kx/N", "y′ = dy/dτ")
    };
    let t = |i: usize| v.t(i);
    let env_x: Vec<f64> = v.a.iter().map(|a| a * lx * xs).collect();
    let env_v: Vec<f64> = v.a.iter().map(|a| a * lx * omega * vs).collect();
    let mut p1 = Panel::new("Displacement", v.t_label(), x_lab);
    p1.x_range = Some(v.t_range(1.0));
    p1.series.push(
        Series::line(
            "displacement",
            0,
            decimate(&pts((0..n).map(t), v.rec.x.iter().map(|x| x * xs)), bins),
        )
        .with_style(Style::Line(1)),
    );
    p1.series.push(Series::line(
        "± envelope √(x² + (v/Ω)²)",
        1,
        decimate(&pts((0..n).map(t), env_x.iter().copied()), bins),
    ));
    p1.series.push(Series::line(
        "",
        1,
        decimate(&pts((0..n).map(t), env_x.iter().map(|e| -e)), bins),
    ));
    let mut p2 = Panel::new("Velocity", v.t_label(), v_lab);
    p2.x_range = Some(v.t_range(1.0));
    p2.series.push(
        Series::line(
            "velocity",
            2,
            decimate(&pts((0..n).map(t), v.rec.v.iter().map(|x| x * vs)), bins),
        )
        .with_style(Style::Line(1)),
    );
    p2.series.push(Series::line(
        "± envelope Ω·A",
        1,
        decimate(&pts((0..n).map(t), env_v.iter().copied()), bins),
    ));
    p2.series.push(Series::line(
        "",
        1,
        decimate(&pts((0..n).map(t), env_v.iter().map(|e| -e)), bins),
    ));
    Figure {
        name: "motion".into(),
        title: "Displacement and velocity with their envelopes".into(),
        caption: "the envelope (Mark & Crandall amplitude A = √(x² + (v/Ω)²)) must touch every \
                  displacement peak and every velocity peak; if it overshoots the peaks the rig \
                  constants (Ω = √(k/m)) are wrong. A linear decay means Coulomb friction, an \
                  exponential one viscous friction; the motion stops when the amplitude falls \
                  below the static friction level."
            .into(),
        panels: vec![p1, p2],
        size: (1000, 750),
    }
}

/// Measured envelope and the envelope of each fitted law.
fn envelope_figure(
    v: &View,
    fits: &[FitResult],
    fit_opts: &FitOptions,
    bins: usize,
    notes: &mut Vec<String>,
) -> Result<Figure, ReportError> {
    let mut p = Panel::new("Envelope decay", "τ = Ωt", "A (dimensionless, y = kx/N)");
    if v.si {
        p.secondary = Some(Secondary {
            x_label: Some("t (s)".into()),
            x_scale: 1.0 / v.rig.omega(),
            y_label: Some("A (µm)".into()),
            y_scale: v.rig.length_scale_m() * 1e6,
        });
    }
    let tau0 = v.tau[0];
    p.x_range = Some((0.0, v.tau[v.show_end.max(1)] - tau0));
    let measured = pts(v.tau.iter().map(|t| t - tau0), v.a.iter().copied());
    p.series
        .push(Series::line("measured", 7, decimate(&measured, bins)).with_style(Style::Line(3)));
    let data = EnvelopeData::new(&v.tau, &v.y, &v.ydot, bins.max(50))
        .map_err(|e| ReportError::Input(e.to_string()))?;
    for (i, f) in fits.iter().enumerate() {
        match identify::simulated_envelope(&data, f.friction_law(), fit_opts) {
            Ok(env) => p.series.push(
                Series::line(
                    format!("{} (gap {:.2} %)", f.law, 100.0 * f.gap),
                    i,
                    pts(data.tau.iter().copied(), env.into_iter()),
                )
                .with_style(Style::Dashed(2)),
            ),
            Err(e) => notes.push(format!("{} law: cannot simulate its envelope: {e}", f.law)),
        }
    }
    Ok(Figure {
        name: "envelopes".into(),
        title: "Envelope and fitted envelopes per law".into(),
        caption: "the law whose envelope stays on the measured one (smallest gap) describes the \
                  contact. A straight decay ⇒ Coulomb (μ0); a convex one (exponential-like) ⇒ \
                  viscous part (μ1); a concave part or a change of curvature (mixed) ⇒ a law of \
                  order ≥ 2 (quadratic μ2). A systematic departure at small amplitudes means the \
                  law misses something (try windowed fits)."
            .into(),
        panels: vec![p],
        size: (1000, 600),
    })
}

/// The fitted friction laws f(y') (= F/N) against the dimensionless velocity.
fn law_figure(v: &View, fits: &[FitResult], onboard: Option<&OnboardResult>) -> Figure {
    let vmax = v.ydot.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-9);
    let m = 200;
    // An even number of points symmetric about 0 never samples v = 0 itself, so the Coulomb
    // jump shows as a vertical segment.
    let grid: Vec<f64> = (0..m)
        .map(|i| -vmax + 2.0 * vmax * (i as f64 + 0.5) / m as f64)
        .collect();
    let mut p = Panel::new(
        "Friction law",
        "y′ = kv/(NΩ) (dimensionless velocity)",
        "f = F/N (friction coefficient)",
    );
    p.legend_pos = LegendPos::LowerRight;
    if v.si {
        p.secondary = Some(Secondary {
            x_label: Some("v (m/s)".into()),
            x_scale: v.rig.length_scale_m() * v.rig.omega(),
            y_label: Some("F (mN)".into()),
            y_scale: v.rig.load_n * 1e3,
        });
    }
    if let (Some(ft), true) = (&v.rec.ft, v.si) {
        let stride = (v.rec.len() / 1500).max(1);
        let data: Vec<(f64, f64)> = (0..v.sliding_end)
            .step_by(stride)
            .map(|i| (v.ydot[i], ft[i] / v.rig.load_n))
            .collect();
        p.series
            .push(Series::line("measured F/N", 7, data).with_style(Style::Points(1)));
    }
    for (i, f) in fits.iter().enumerate() {
        let law = f.friction_law();
        p.series.push(Series::line(
            f.law.clone(),
            i,
            grid.iter().map(|&x| (x, law.steady_force(x))).collect(),
        ));
    }
    if let Some(o) = onboard {
        let (m0, m1) = (o.best.mu0 as f64, o.best.mu1 as f64);
        if m0.is_finite() && m1.is_finite() {
            p.series.push(
                Series::line(
                    "on-board μ0 sgn y′ + μ1 y′",
                    6,
                    grid.iter()
                        .map(|&x| (x, m0 * x.signum() + m1 * x))
                        .collect(),
                )
                .with_style(Style::Dashed(2)),
            );
        }
    }
    Figure {
        name: "law".into(),
        title: "Fitted friction law".into(),
        caption:
            "the jump at y′ = 0 is the Coulomb level μ0 and the slope the viscous constant μ1; \
                  curvature is μ2. Laws that agree on the envelope but differ here are not told \
                  apart by this run. Measured F/N points (if the force channel exists) scatter \
                  around the law and loop because of the force channel's lag; they show the \
                  contact alone, while the fitted μ1 also holds the apparatus damping (blades, \
                  air: μ1 ≈ 0.0011), so the fitted slope is the steeper one."
                .into(),
        panels: vec![p],
        size: (1000, 600),
    }
}

/// Coulomb–viscous constants fitted on successive amplitude windows (thesis Tables 6–7).
fn windows_figure(v: &View, opts: &ReportOptions) -> Result<Figure, ReportError> {
    let w = identify::windowed_fits(
        &v.tau,
        &v.y,
        &v.ydot,
        LawSpec::CoulombViscous,
        opts.windows,
        &opts.fit,
    )
    .map_err(|e| ReportError::Input(e.to_string()))?;
    if w.len() < 2 {
        return Err(ReportError::Input(format!(
            "only {} amplitude window(s) long enough to fit",
            w.len()
        )));
    }
    let mid = |f: &identify::WindowFit| 0.5 * (f.a_start + f.a_end);
    // The method's stated precision (thesis): μ0 ± 0.001, μ1 ± 0.0002. The axes span at least
    // mean ± 1.5 × precision so that scatter within the precision looks flat, as it is.
    let panel = |j: usize, prec: f64| {
        let name = format!("μ{j}");
        let pts: Vec<(f64, f64)> = w
            .iter()
            .map(|f| (mid(f), f.fit.mu.get(j).copied().unwrap_or(f64::NAN)))
            .filter(|p| p.1.is_finite())
            .collect();
        let mut p = Panel::new(
            format!("{name} per amplitude window"),
            "window mid amplitude A (dimensionless)",
            name.clone(),
        );
        p.legend_pos = LegendPos::Auto;
        if !pts.is_empty() {
            let m = pts.iter().map(|p| p.1).sum::<f64>() / pts.len() as f64;
            let lo = pts.iter().fold(m - 1.5 * prec, |a, p| a.min(p.1));
            let hi = pts.iter().fold(m + 1.5 * prec, |a, p| a.max(p.1));
            let pad = 0.05 * (hi - lo);
            p.y_range = Some((lo - pad, hi + pad));
            p.hlines
                .push((m + prec, format!("mean ± precision ({prec})")));
            p.hlines.push((m - prec, String::new()));
        }
        p.series
            .push(Series::line(name, j, pts.clone()).with_style(Style::Line(2)));
        p.series
            .push(Series::line("", j, pts).with_style(Style::Points(4)));
        p
    };
    let (p0, p1) = (panel(0, 0.001), panel(1, 0.0002));
    Ok(Figure {
        name: "windows".into(),
        title: "Coulomb–viscous constants per amplitude window".into(),
        caption: "the Coulomb–viscous law fitted separately on windows of equal amplitude drop \
                  (large amplitudes on the right). Constants that stay flat within the method's \
                  precision (μ0 ± 0.001, μ1 ± 0.0002) mean the law holds at all amplitudes; \
                  constants that drift mean it misses something (a μ2 term, a velocity-dependent \
                  film)."
            .into(),
        panels: vec![p0, p1],
        size: (900, 650),
    })
}

/// Force–velocity and force–displacement loops.
fn force_figures(v: &View, ft: &[f64], fits: &[FitResult], bins: usize) -> (Figure, Figure) {
    let n = v.sliding_end.max(2).min(v.rec.len());
    let (fs, f_lab) = if v.si {
        (1e3, "F (mN)")
    } else {
        (1.0, "f = F/N")
    };
    let (vs, v_lab, xs, x_lab) = if v.si {
        (1.0, "v (m/s)", 1e6, "x (µm)")
    } else {
        (1.0, "y′", 1.0, "y")
    };
    // Time order matters for a loop: keep every k-th sample rather than min/max bins.
    let stride = (n / (4 * bins).max(1)).max(1);
    let idx: Vec<usize> = (0..n).step_by(stride).collect();
    let mut pv = Panel::new("Force vs velocity", v_lab, f_lab);
    pv.legend_pos = LegendPos::LowerRight;
    pv.series.push(
        Series::line(
            "measured",
            0,
            idx.iter().map(|&i| (v.rec.v[i] * vs, ft[i] * fs)).collect(),
        )
        .with_style(Style::Line(1)),
    );
    // The best-fitting law as a steady curve F = N f(y'(v)).
    if let Some(best) = fits
        .iter()
        .filter(|f| f.gap.is_finite())
        .min_by(|a, b| a.gap.total_cmp(&b.gap))
    {
        let law = best.friction_law();
        let vmax = v.rec.v[..n].iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let m = 200;
        let curve = (0..m)
            .map(|i| {
                let vv = -vmax + 2.0 * vmax * (i as f64 + 0.5) / m as f64;
                let f = law.steady_force(v.rig.ydot_of_v(vv)) * v.rig.load_n;
                (vv * vs, f * fs)
            })
            .collect();
        pv.series.push(
            Series::line(format!("fitted {} (steady)", best.law), 1, curve)
                .with_style(Style::Line(2)),
        );
    }
    let mut px = Panel::new("Force vs displacement", x_lab, f_lab);
    px.legend_pos = LegendPos::LowerRight;
    px.series.push(
        Series::line(
            "measured",
            0,
            idx.iter().map(|&i| (v.rec.x[i] * xs, ft[i] * fs)).collect(),
        )
        .with_style(Style::Line(1)),
    );
    let fv = Figure {
        name: "force_velocity".into(),
        title: "Force–velocity loop".into(),
        caption: "a memoryless law is a single curve through the loop; an open loop (hysteresis) \
                  means friction with memory (LuGre, Dahl) or a lag of the force channel (≈ 3 ms \
                  on the rig, charge amplifier at 300 Hz). The jump at v = 0 is the Coulomb level."
            .into(),
        panels: vec![pv],
        size: (900, 600),
    };
    let fx = Figure {
        name: "force_displacement".into(),
        title: "Force–displacement loops".into(),
        caption: "each loop's area is the energy dissipated in one cycle; a Coulomb contact gives \
                  rectangular loops of constant height ±μ0 N, a viscous one ellipses whose height \
                  shrinks with the amplitude."
            .into(),
        panels: vec![px],
        size: (900, 600),
    };
    (fv, fx)
}

/// log10 ECR against time with the lubrication regime of the sliding part.
fn ecr_figure(
    v: &View,
    ecr: &[f64],
) -> Result<(Figure, Result<RegimeAssessment, ReportError>), ReportError> {
    let l = log10_ohm(ecr)?;
    let end = v.sliding_end.min(l.len());
    let regime = classify_regime(&l[..end]);
    let title = match &regime {
        Ok(r) => format!(
            "Regime while sliding: {} (median log10 R = {:.2}, spread {:.2} decades)",
            r.regime.name(),
            r.median_log10,
            r.spread_decades
        ),
        Err(_) => "Regime: too few samples while sliding".to_string(),
    };
    let mut p = Panel::new(title, v.t_label(), "log10(R / Ω)");
    p.legend_pos = LegendPos::LowerLeft;
    let (lo, hi) = l
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    p.y_range = Some(((lo - 0.3).min(-0.2), (hi + 0.3).max(8.5)));
    p.x_range = Some(v.t_range(1.5));
    p.hlines.push((7.0, "full film ≈ 7".into()));
    p.hlines.push((
        FULL_FILM_MIN_LOG10,
        format!("full-film threshold ({FULL_FILM_MIN_LOG10})"),
    ));
    if end > 0 {
        p.span = Some((v.t(0), v.t(end - 1), "sliding (classified)".into()));
    }
    let data: Vec<(f64, f64)> = (0..l.len()).map(|i| (v.t(i), l[i])).collect();
    let stride = (data.len() / 3000).max(1);
    p.series.push(
        Series::line("log10 ECR", 0, data.into_iter().step_by(stride).collect())
            .with_style(Style::Line(2)),
    );
    let fig = Figure {
        name: "ecr".into(),
        title: "Electrical contact resistance and lubrication regime".into(),
        caption: "a constant, high log10 R (≈ 7) while sliding means a full film (EHL); a \
                  fluctuating one means mixed lubrication (asperities touch through the film); a \
                  low steady one metallic (boundary) contact. The value at rest after the stop is \
                  not zero (insulating products) and is not used."
            .into(),
        panels: vec![p],
        size: (1000, 500),
    };
    Ok((fig, regime))
}

fn temperature_figure(v: &View, temp: &[f64], bins: usize) -> Figure {
    let mut p = Panel::new("Plane temperature", v.t_label(), "T (°C)");
    p.series.push(Series::line(
        "thermocouple",
        1,
        decimate(
            &(0..temp.len())
                .map(|i| (v.t(i), temp[i]))
                .collect::<Vec<_>>(),
            bins,
        ),
    ));
    Figure {
        name: "temperature".into(),
        title: "Plane temperature".into(),
        caption: "the temperature should stay within a degree of the setpoint during the run; a \
                  drift changes the lubricant's viscosity and hence μ1."
            .into(),
        panels: vec![p],
        size: (1000, 400),
    }
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

/// Four significant digits, scientific outside 1e-3 … 1e5.
/// `value ± se`, the value rounded to the standard error's second significant digit.
fn pm(v: f64, se: f64) -> String {
    if !(se.is_finite() && se > 0.0) {
        return format!("{} ± ?", num(v));
    }
    let digits = (1 - se.log10().floor() as i32).max(0) as usize;
    if digits > 8 || !v.is_finite() {
        format!("{} ± {se:.1e}", num(v))
    } else {
        format!("{v:.digits$} ± {se:.digits$}")
    }
}

fn num(x: f64) -> String {
    if !x.is_finite() {
        "—".into()
    } else if x == 0.0 {
        "0".into()
    } else if x.abs() >= 1e-3 && x.abs() < 1e5 {
        let digits = (3 - x.abs().log10().floor() as i32).max(0) as usize;
        format!("{x:.digits$}")
    } else {
        format!("{x:.3e}")
    }
}

fn summary(
    v: &View,
    inputs: &ReportInputs,
    fits: &[FitResult],
    regime: Option<&RegimeAssessment>,
) -> String {
    let mut s = String::new();
    let rig = v.rig;
    let mut rows: Vec<Vec<String>> = inputs
        .meta
        .iter()
        .map(|(k, val)| vec![k.clone(), val.clone()])
        .collect();
    let dur = v.rec.t[v.rec.len() - 1] - v.rec.t[0];
    if v.si {
        rows.push(vec!["mass m".into(), format!("{} kg", num(rig.mass_kg))]);
        rows.push(vec![
            "stiffness k".into(),
            format!("{} N/m", num(rig.stiffness_n_per_m)),
        ]);
        rows.push(vec![
            "normal load N".into(),
            format!("{} N", num(rig.load_n)),
        ]);
        rows.push(vec![
            "Ω = √(k/m)".into(),
            format!(
                "{} rad/s ({} Hz)",
                num(rig.omega()),
                num(rig.omega() / std::f64::consts::TAU)
            ),
        ]);
        rows.push(vec![
            "length scale N/k".into(),
            format!("{} µm", num(rig.length_scale_m() * 1e6)),
        ]);
        rows.push(vec![
            "initial amplitude".into(),
            format!(
                "{} µm (Y0 = {})",
                num(v.a[0] * rig.length_scale_m() * 1e6),
                num(v.a[0])
            ),
        ]);
        rows.push(vec![
            "samples".into(),
            format!(
                "{} over {} s ({} Hz)",
                v.rec.len(),
                num(dur),
                num(1.0 / v.rec.dt())
            ),
        ]);
    } else {
        rows.push(vec!["units".into(), "dimensionless (τ, y, y′)".into()]);
        rows.push(vec!["initial amplitude Y0".into(), num(v.a[0])]);
        rows.push(vec![
            "samples".into(),
            format!("{} over τ = {}", v.rec.len(), num(dur)),
        ]);
    }
    let channels: Vec<&str> = [
        ("force", v.rec.ft.is_some()),
        ("temperature", v.rec.temp.is_some()),
        ("ECR", v.rec.ecr.is_some()),
    ]
    .iter()
    .filter(|c| c.1)
    .map(|c| c.0)
    .collect();
    rows.push(vec![
        "extra channels".into(),
        if channels.is_empty() {
            "none".into()
        } else {
            channels.join(", ")
        },
    ]);
    let cycles = count_cycles(&v.y, &v.ydot);
    rows.push(vec![
        "oscillation cycles until the stop".into(),
        match &inputs.onboard {
            Some(o) => format!("{cycles:.1} (host count); {} (on-board)", o.cycles),
            None => format!("{cycles:.1} (host count)"),
        },
    ]);
    if let Some(r) = regime {
        rows.push(vec![
            "lubrication regime (ECR)".into(),
            format!(
                "{} — median log10 R {:.2}, spread {:.2} decades, {:.0} % excursions > 1 decade",
                r.regime.name(),
                r.median_log10,
                r.spread_decades,
                100.0 * r.excursions
            ),
        ]);
    }
    s.push_str("<h2>Run and rig</h2>\n");
    s.push_str(&table(&["quantity", "value"], &rows));

    s.push_str("<h2>Friction constants</h2>\n");
    let mut res: Vec<Vec<String>> = fits
        .iter()
        .map(|f| {
            let fitted: Vec<usize> = f
                .law
                .parse::<LawSpec>()
                .map(|s| s.powers())
                .unwrap_or_else(|_| (0..f.mu.len()).collect());
            let mu = |j: usize| match f.mu.get(j) {
                Some(&m) if fitted.contains(&j) => {
                    pm(m, f.mu_se.get(j).copied().unwrap_or(f64::NAN))
                }
                _ => "—".to_string(),
            };
            vec![
                format!("host fit: {}", f.law),
                mu(0),
                mu(1),
                mu(2),
                format!(
                    "{:.3} % ({:.2} × noise floor)",
                    100.0 * f.gap,
                    f.gap_ratio()
                ),
                f.shape.name().into(),
                format!("{} ({} it.)", f.verdict.name(), f.iterations),
            ]
        })
        .collect();
    if let Some(o) = &inputs.onboard {
        for (name, e) in [
            ("on-board: shown (best)", o.best),
            ("on-board: averaging", o.averaging),
            ("on-board: decrement", o.decrement),
        ] {
            res.push(vec![
                format!("{name} — {}", o.verdict.name()),
                format!("{} ± {}", num(e.mu0 as f64), num(e.mu0_se as f64)),
                format!("{} ± {}", num(e.mu1 as f64), num(e.mu1_se as f64)),
                "—".into(),
                "—".into(),
                o.shape.name().into(),
                "—".into(),
            ]);
        }
    }
    s.push_str(&table(
        &["estimate", "μ0", "μ1", "μ2", "gap", "shape", "verdict"],
        &res,
    ));
    if let (Some(o), Some(cv)) = (
        &inputs.onboard,
        fits.iter().find(|f| f.law == "coulomb-viscous"),
    ) {
        let d0 = o.best.mu0 as f64 - cv.mu.first().copied().unwrap_or(f64::NAN);
        let d1 = o.best.mu1 as f64 - cv.mu.get(1).copied().unwrap_or(f64::NAN);
        let _ = writeln!(
            s,
            "<p>On-board minus host (coulomb-viscous): Δμ0 = {}, Δμ1 = {} (the method's stated \
             precision: μ0 ± 0.001, μ1 ± 0.0002).</p>",
            esc(&num(d0)),
            esc(&num(d1))
        );
    }
    s.push_str(
        "<p>μ_j are the dimensionless constants of f(y′) = Σ μ_j |y′|^j sgn(y′) (thesis eq. 10–13, \
         y = kx/N, τ = Ωt), ± one standard error; gap = RMS(measured − fitted envelope) / initial \
         amplitude, and the noise floor the envelope's measurement noise on the same scale. \
         Verdicts: adequate (gap ≤ 1.5 × noise floor), inadequate (the law misses something: \
         <code>tribo explain</code>), not-converged.</p>\n",
    );
    s
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
