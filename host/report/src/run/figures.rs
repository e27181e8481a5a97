//! The figures of a record's report: motion, envelope, friction law, windows, force, ECR,
//! temperature.

use super::*;

pub(super) fn pts(xs: impl Iterator<Item = f64>, ys: impl Iterator<Item = f64>) -> Vec<(f64, f64)> {
    xs.zip(ys).collect()
}

/// Displacement and velocity with their envelopes.
pub(super) fn motion_figure(v: &View, bins: usize) -> Figure {
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
pub(super) fn envelope_figure(
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
    let data = EnvelopeData::new(&v.tau, &v.y, &v.ydot, bins.max(50)).map_err(|e| {
        ReportError::Analysis {
            what: "the envelope",
            source: Box::new(e),
        }
    })?;
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
pub(super) fn law_figure(v: &View, fits: &[FitResult], onboard: Option<&OnboardResult>) -> Figure {
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
            f.law.to_string(),
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
pub(super) fn windows_figure(v: &View, opts: &ReportOptions) -> Result<Figure, ReportError> {
    let w = identify::windowed_fits(
        &v.tau,
        &v.y,
        &v.ydot,
        LawSpec::CoulombViscous,
        opts.windows,
        &opts.fit,
    )
    .map_err(|e| ReportError::Analysis {
        what: "the amplitude windows",
        source: Box::new(e),
    })?;
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
pub(super) fn force_figures(
    v: &View,
    ft: &[f64],
    fits: &[FitResult],
    bins: usize,
) -> (Figure, Figure) {
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
pub(super) fn ecr_figure(
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

pub(super) fn temperature_figure(v: &View, temp: &[f64], bins: usize) -> Figure {
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
