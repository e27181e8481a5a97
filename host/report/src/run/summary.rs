//! The summary table of a record's report: fits with their ±, verdicts, the on-board result.

use super::*;

/// Four significant digits, scientific outside 1e-3 … 1e5.
/// `value ± se`, the value rounded to the standard error's second significant digit.
pub(super) fn pm(v: f64, se: f64) -> String {
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

pub(super) fn num(x: f64) -> String {
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

pub(super) fn summary(
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
            let fitted: Vec<usize> = f.law.powers();
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
        fits.iter().find(|f| f.law == LawSpec::CoulombViscous),
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
