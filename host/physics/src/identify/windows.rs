//! Fits over windows of a record (how the friction coefficients drift along a run).

use super::*;

/// A fit restricted to an amplitude window (thesis Tables 6–7).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WindowFit {
    /// Amplitude at the window start.
    pub a_start: f64,
    /// Amplitude at the window end.
    pub a_end: f64,
    /// τ of the window start (in the record).
    pub tau_start: f64,
    /// τ of the window end.
    pub tau_end: f64,
    /// The fit on that window.
    pub fit: FitResult,
}

impl WindowFit {
    /// One JSON object: `{"a_start", "a_end", "tau_start", "tau_end", "fit": {…}}` (amplitudes and
    /// times dimensionless; `fit` as [`FitResult::to_json`]).
    pub fn to_json(&self) -> Result<String, serde_json::Error> {
        serde_json::to_string(self)
    }
}

/// [`windowed_fits`] on a record (SI or dimensionless; each window's `p_si` filled in).
pub fn fit_windows(
    rec: &Record,
    spec: LawSpec,
    windows: usize,
    opts: &FitOptions,
) -> Result<Vec<WindowFit>, FitError> {
    rec.validate()?;
    let rig = rec.rig()?;
    let (tau, y, ydot) = rec.dimensionless()?;
    let mut w = windowed_fits(&tau, &y, &ydot, spec, windows, opts)?;
    for x in &mut w {
        x.fit.p_si = rig.p_of_mu(&x.fit.mu);
        x.fit.p_si_se = rig.p_of_mu(&x.fit.mu_se);
    }
    Ok(w)
}

/// Splits the motion (from the release, [`motion_span`], until the envelope falls below 2 % of its
/// start) into `windows` parts of equal amplitude drop and fits `spec` on each. Each window's
/// simulation starts from the window's first sample as measured (thesis Tables 6–7); that sample
/// is as noisy as any other, and its noise, which moves every constant of the window together, is
/// in their ± ([`fit_envelope`]). Constants that drift from window to window beyond their ± mean
/// the law misses something. The motion is [`screen`]ed first; the windows are not (each may hold only
/// a few half cycles).
pub fn windowed_fits(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    spec: LawSpec,
    windows: usize,
    opts: &FitOptions,
) -> Result<Vec<WindowFit>, FitError> {
    if windows == 0 {
        return Err(FitError::failed("need at least one window"));
    }
    let n = tau.len().min(y.len()).min(ydot.len());
    check_finite(&tau[..n], &y[..n], &ydot[..n])?;
    let span = motion_span(&tau[..n], &y[..n], &ydot[..n]);
    let r = span.range();
    let (tau, y, ydot) = (&tau[r.clone()], &y[r.clone()], &ydot[r]);
    screen(tau, y, ydot)?;
    let a = mark_crandall(y, ydot);
    let a0 = *a.first().ok_or_else(|| FitError::failed("empty record"))?;
    let a_min = a
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min)
        .max(0.02 * a0);
    let opts = &FitOptions {
        fit_initial_amplitude: false,
        ..opts.clone()
    };
    let mut out = Vec::new();
    let mut start = 0usize;
    for w in 1..=windows {
        let level = a0 - (a0 - a_min) * w as f64 / windows as f64;
        let end = a.iter().position(|&v| v <= level).unwrap_or(a.len() - 1);
        if end <= start + 8 {
            continue;
        }
        let r = fit_unscreened(
            &tau[start..=end],
            &y[start..=end],
            &ydot[start..=end],
            spec,
            opts,
        )?;
        out.push(WindowFit {
            a_start: a[start],
            a_end: a[end],
            tau_start: tau[start],
            tau_end: tau[end],
            fit: r,
        });
        start = end;
    }
    Ok(out)
}
