//! Whether μ0 drifts over the motion, read from the force channel: the envelope alone cannot
//! always tell (a Coulomb level that grows in time bends the envelope's decay by less than its
//! noise long before the force channel stops showing it).
//!
//! The friction force while sliding, away from the reversals (|y'| above half the half cycle's
//! peak), is regressed on what the force channel would show of a Coulomb level `sgn y'`, of each
//! velocity term of the law `|y'|^j sgn y'`, of a Coulomb level changing in time
//! `(t − t_mid) sgn y'`, and on a constant (the channel's zero): each regressor passed through the
//! channel's low-pass when the record states it. The velocity terms are told from a trend in
//! time by how the force follows the speed *within* each half cycle, the trend by how the level
//! moves *between* them. A delay of the channel (sensor lag) and a memory of the contact
//! (frictional lag) leave a transient after each reversal that would leak into the trend through
//! the velocity terms (a 3 ms sensor lag read as a 4 % drift at 20σ): both are profiled on a grid
//! and applied to every regressor. The law's constants from the envelope are not used: the
//! envelope's fit bends its viscous term to a drift (a 12 % rise then read as −1.6 %). The
//! trend's ± is cluster-robust, one cluster per half cycle (the channel's filtered noise and any
//! misfit are correlated within a half cycle, nearly independent between them). The channel's
//! gain cancels in the relative change.
//!
//! Measured (`tests/fit_drift.rs` in tribo-explain): a 12 % change of μ0 over 2 s (μ0 0.01,
//! 0.3 N) is found at ×1 and ×3 the default noise; at ×10 its ± (4–5 %) is too large to call it.
//! A sensor lag of 1 or 3 ms or a frictional lag of 2 ms alone gives no drift; a 1 ms sensor lag
//! *with* a 2 ms frictional lag does (+16 % at 12σ): the profile of the two together is not yet
//! right.

use super::*;

/// The force channel's trend of μ0 over the motion.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Mu0Trend {
    /// Change of μ0 over the compared motion relative to its mean level (+ = rising).
    pub relative_change: f64,
    /// Its standard error.
    pub relative_change_se: f64,
    /// Rate of change of μ0 (per second of record time; per unit τ for a dimensionless record).
    pub rate_per_s: f64,
    /// Its standard error.
    pub rate_per_s_se: f64,
    /// Duration of the compared motion (s, or τ).
    pub span_s: f64,
    /// Half cycles used.
    pub half_cycles: usize,
    /// |trend| / its standard error.
    pub z: f64,
    /// Whether the trend is significant ([`DRIFT_Z`]).
    pub significant: bool,
}

/// A trend of μ0 this many standard errors from 0 is a drift (a false alarm rate of about 6e-5
/// per record for a normal statistic).
pub const DRIFT_Z: f64 = 4.0;

/// Smallest relative change of μ0 over the motion called a drift, however well measured (a
/// noiseless record measures a numerical trend of 1e-6 to many σ).
pub const DRIFT_MIN: f64 = 0.01;

/// Fewest half cycles over which a trend is read.
const MIN_HALF_CYCLES: usize = 8;

impl Mu0Trend {
    /// One line of text.
    pub fn text(&self) -> String {
        format!(
            "μ0 {} by {:+.1} ± {:.1} % over the {:.2} s of motion (the force channel's trend, \
             {:.1}σ{})",
            if self.relative_change >= 0.0 {
                "rises"
            } else {
                "falls"
            },
            100.0 * self.relative_change,
            100.0 * self.relative_change_se,
            self.span_s,
            self.z,
            if self.significant {
                ": a drift (running-in or thermal), unless the law misses how the force follows \
                 the speed"
            } else {
                ", within the noise"
            }
        )
    }
}

/// The trend of μ0 in the force channel `f` (`F/N`, every sample) over `range` of the samples
/// `(tau, ydot)` (dimensionless), against the fitted law `mu` (`μ_j`, the contact's: the force
/// channel does not see the apparatus damping). `filter`: the force channel's stated low-pass
/// `(cut-off, sampling rate)` (Hz), applied to the regressors. `time_per_tau` converts τ to the
/// reported time unit. `None` when there are too few half cycles or the regression is singular.
pub fn mu0_trend_of(
    tau: &[f64],
    ydot: &[f64],
    f: &[f64],
    mu: &[f64],
    range: std::ops::Range<usize>,
    filter: Option<(f64, f64)>,
    time_per_tau: f64,
) -> Option<Mu0Trend> {
    let through = butterworth_or_none(filter);
    mu0_trend_through(tau, ydot, f, mu, range, &through, time_per_tau)
}

/// The force channel's 2-pole low-pass `(cut-off, sampling rate)` (Hz) as a function of a
/// regressor; `None`: the identity.
fn butterworth_or_none(filter: Option<(f64, f64)>) -> impl Fn(&[f64]) -> Vec<f64> {
    move |c: &[f64]| match filter {
        Some((fc, rate)) => crate::sensor::butterworth2(c, fc, rate),
        None => c.to_vec(),
    }
}

/// [`mu0_trend_of`] with the force channel's low-pass given as a function of a regressor (every
/// sample of `range`): for a filter that is not a stated 2-pole cut-off, e.g. one fitted with its
/// order (`tribo explain`).
pub fn mu0_trend_through(
    tau: &[f64],
    ydot: &[f64],
    f: &[f64],
    mu: &[f64],
    range: std::ops::Range<usize>,
    filter: &dyn Fn(&[f64]) -> Vec<f64>,
    time_per_tau: f64,
) -> Option<Mu0Trend> {
    trend_and_rss(tau, ydot, f, mu, range, filter, time_per_tau).map(|(t, _)| t)
}

/// [`mu0_trend_through`] with the residual sum of squares of its best regression (what tells
/// two filters apart).
fn trend_and_rss(
    tau: &[f64],
    ydot: &[f64],
    f: &[f64],
    mu: &[f64],
    range: std::ops::Range<usize>,
    filter: &dyn Fn(&[f64]) -> Vec<f64>,
    time_per_tau: f64,
) -> Option<(Mu0Trend, f64)> {
    let end = range.end.min(tau.len()).min(ydot.len()).min(f.len());
    let start = range.start.min(end);
    let mu0 = mu.first().copied().unwrap_or(0.0);
    if end < start + 16 || mu0 == 0.0 {
        return None;
    }
    // Half cycles: runs of one velocity sign.
    let mut cycles: Vec<(usize, usize)> = Vec::new();
    let mut s = start;
    for i in start + 1..end {
        if ydot[i].signum() != ydot[i - 1].signum() || ydot[i] == 0.0 {
            if i - s >= 4 {
                cycles.push((s, i));
            }
            s = i;
        }
    }
    // The last run may be cut by the end of the span: dropped.
    let t_mid = 0.5 * (tau[start] + tau[end - 1]);
    // Regressors over the span, as the force channel would show them: the Coulomb level sgn y',
    // each velocity term of the law |y'|^j sgn y', a Coulomb level changing in time
    // (τ − τ_mid) sgn y' (and the channel's zero, a constant, in [`least_squares_rss`]).
    let sg: Vec<f64> = (start..end).map(|i| ydot[i].signum()).collect();
    let mut base: Vec<Vec<f64>> = vec![sg.clone()];
    for j in (1..mu.len()).filter(|&j| mu[j] != 0.0) {
        base.push(
            (start..end)
                .map(|i| ydot[i].abs().powi(j as i32) * sg[i - start])
                .collect(),
        );
    }
    base.push(
        (start..end)
            .map(|i| (tau[i] - t_mid) * sg[i - start])
            .collect(),
    );
    let trend_col = base.len() - 1;
    let filtered: Vec<Vec<f64>> = base.iter().map(|c| filter(c)).collect();
    let mut sel: Vec<Vec<usize>> = Vec::new();
    for &(a, b) in &cycles {
        let vmax = ydot[a..b].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let idx: Vec<usize> = (a..b)
            .filter(|&i| ydot[i].abs() > 0.5 * vmax && f[i].is_finite())
            .collect();
        if idx.len() >= 3 {
            sel.push(idx);
        }
    }
    if sel.len() < MIN_HALF_CYCLES {
        return None;
    }
    // A delay of the channel (a sensor lag) or a memory of the contact (a frictional lag: the
    // force relaxing towards the steady law, a first-order low-pass of it) leaves a transient
    // after each reversal that the gain would partly take up, and with it the law's decaying
    // viscous part (a 3 ms sensor lag read as a 4 % drift, a 2 ms memory as 1–4 %): both are
    // profiled on a grid (0 to 1 rad of τ each, about 6 ms on the real rig, in steps of 0.05 rad or
    // a sample), the pair that fits best kept.
    let dtau = (tau[end - 1] - tau[start]) / (end - start - 1) as f64;
    let grid: Vec<f64> = {
        let h = 0.05f64.max(dtau);
        (0..)
            .map(|i| i as f64 * h)
            .take_while(|&x| x <= 1.0 + 1e-9)
            .collect()
    };
    // Every pair of the grid is fitted (each memory on its own thread, [`super::par_map`]); only
    // the selected samples of each column are formed, and the best pair's ± is computed once.
    let rows: Vec<usize> = sel.iter().flatten().copied().collect();
    let k = filtered.len() + 1;
    let fits: Vec<Vec<Option<PairFit>>> = super::par_map(&grid, |&memory| {
        let relaxed: Vec<Vec<f64>> = filtered
            .iter()
            .map(|c| first_order(c, memory, dtau))
            .collect();
        let mut x = vec![0.0; rows.len() * k];
        grid.iter()
            .map(|&d| {
                design(&mut x, &relaxed, d / dtau, &rows, start);
                least_squares_rss(&x, k, &rows, f)
            })
            .collect()
    });
    let mut best: Option<(f64, Vec<f64>, usize, usize)> = None;
    for (im, row) in fits.into_iter().enumerate() {
        for (id, fit) in row.into_iter().enumerate() {
            if let Some((beta, rss)) = fit {
                if best.as_ref().is_none_or(|b| rss < b.0) {
                    best = Some((rss, beta, im, id));
                }
            }
        }
    }
    let (rss, beta, var_b) = {
        let (rss, beta, im, id) = best?;
        let relaxed: Vec<Vec<f64>> = filtered
            .iter()
            .map(|c| first_order(c, grid[im], dtau))
            .collect();
        let mut x = vec![0.0; rows.len() * k];
        design(&mut x, &relaxed, grid[id] / dtau, &rows, start);
        let var_b = cluster_variance(&x, k, trend_col, &beta, &sel, f)?;
        (rss, beta, var_b)
    };
    let b = beta[trend_col];
    let se_b = var_b.max(0.0).sqrt();
    // μ0 as the channel reads it (its gain included, which cancels in the relative change).
    let level = beta[0];
    let span = tau[end - 1] - tau[start];
    if !(b.is_finite() && se_b.is_finite() && se_b > 0.0 && level.abs() > 0.0) {
        return None;
    }
    let z = b.abs() / se_b;
    Some((
        Mu0Trend {
            relative_change: b * span / level,
            relative_change_se: se_b * span / level.abs(),
            rate_per_s: b / time_per_tau,
            rate_per_s_se: se_b / time_per_tau,
            span_s: span * time_per_tau,
            half_cycles: sel.len(),
            z,
            significant: z > DRIFT_Z && (b * span / level).abs() > DRIFT_MIN,
        },
        rss,
    ))
}

/// One (memory, delay) pair's least squares: its coefficients and residual sum of squares.
type PairFit = (Vec<f64>, f64);

/// A first-order lag of time constant `t` (τ units; 0 = none) of a signal sampled every `h`,
/// settled at its first value.
fn first_order(x: &[f64], t: f64, h: f64) -> Vec<f64> {
    if t <= 0.0 || x.is_empty() {
        return x.to_vec();
    }
    let a = 1.0 - (-h / t).exp();
    let mut y = x[0];
    x.iter()
        .map(|&v| {
            y += a * (v - y);
            y
        })
        .collect()
}

/// The design matrix (row-major, `k` = columns + the constant) at the samples `rows` of `cols`
/// (indexed from `start`), each column delayed by `d` samples (linear interpolation, first value
/// held: [`crate::sensor::delay`] at those samples only).
fn design(x: &mut [f64], cols: &[Vec<f64>], d: f64, rows: &[usize], start: usize) {
    let k = cols.len() + 1;
    for (out, &i) in x.chunks_exact_mut(k).zip(rows) {
        let li = i - start;
        // Where the delayed sample falls: the same for every column.
        let p = li as f64 - d;
        let at = if d <= 0.0 {
            None
        } else if p <= 0.0 {
            Some((0, 0.0, true))
        } else {
            let j = p.floor() as usize;
            Some((j, p - j as f64, false))
        };
        for (o, c) in out.iter_mut().zip(cols) {
            *o = match at {
                None => c[li],
                Some((_, _, true)) => c[0],
                Some((j, fr, false)) => {
                    if j + 1 < c.len() {
                        c[j] * (1.0 - fr) + c[j + 1] * fr
                    } else {
                        c[c.len() - 1]
                    }
                }
            };
        }
        out[k - 1] = 1.0;
    }
}

/// Least squares of `f` (at `rows`) on the design `x` (row-major, `k` columns, the last the
/// constant): the coefficients and the residual sum of squares.
fn least_squares_rss(x: &[f64], k: usize, rows: &[usize], f: &[f64]) -> Option<(Vec<f64>, f64)> {
    let mut xtx = vec![vec![0.0; k]; k];
    let mut xty = vec![0.0; k];
    // Row-major accumulators, each summed over the rows in order; the upper triangle only (x_a x_b
    // and x_b x_a are the same number).
    let mut acc = vec![0.0; k * k];
    for (xr, &i) in x.chunks_exact(k).zip(rows) {
        let fi = f[i];
        for (a, (&xa, ty)) in xr.iter().zip(xty.iter_mut()).enumerate() {
            *ty += xa * fi;
            for (t, &xb) in acc[a * k + a..(a + 1) * k].iter_mut().zip(&xr[a..]) {
                *t += xa * xb;
            }
        }
    }
    for a in 0..k {
        for b in a..k {
            xtx[a][b] = acc[a * k + b];
            xtx[b][a] = acc[a * k + b];
        }
    }
    let inv = invert(&xtx)?;
    let beta: Vec<f64> = (0..k)
        .map(|a| (0..k).map(|b| inv[a][b] * xty[b]).sum())
        .collect();
    let mut rss = 0.0;
    for (xr, &i) in x.chunks_exact(k).zip(rows) {
        let res = f[i] - xr.iter().zip(&beta).map(|(x, b)| x * b).sum::<f64>();
        rss += res * res;
    }
    Some((beta, rss))
}

/// Cluster-robust variance of coefficient `t` of the least squares `beta` of `f` on the design
/// `x` (rows in the order of `sel`, one cluster per entry of `sel`).
fn cluster_variance(
    x: &[f64],
    k: usize,
    t: usize,
    beta: &[f64],
    sel: &[Vec<usize>],
    f: &[f64],
) -> Option<f64> {
    let mut xtx = vec![vec![0.0; k]; k];
    let mut meat = vec![vec![0.0; k]; k];
    let mut r = 0;
    for idx in sel {
        let mut g = vec![0.0; k];
        for &i in idx {
            let xr = &x[r * k..(r + 1) * k];
            r += 1;
            let res = f[i] - (0..k).map(|a| xr[a] * beta[a]).sum::<f64>();
            for a in 0..k {
                g[a] += xr[a] * res;
                for b in a..k {
                    xtx[a][b] += xr[a] * xr[b];
                }
            }
        }
        for a in 0..k {
            for b in 0..k {
                meat[a][b] += g[a] * g[b];
            }
        }
    }
    let upper = xtx.clone();
    for (a, row) in xtx.iter_mut().enumerate() {
        for (b, v) in row.iter_mut().enumerate().take(a) {
            *v = upper[b][a];
        }
    }
    let inv = invert(&xtx)?;
    let m = sel.len() as f64;
    // Small-sample correction of the cluster-robust estimator.
    let corr = m / (m - 1.0);
    Some(
        (0..k)
            .map(|a| {
                (0..k)
                    .map(|b| inv[t][a] * meat[a][b] * inv[b][t])
                    .sum::<f64>()
            })
            .sum::<f64>()
            * corr,
    )
}

/// The trend of μ0 of a record with a force channel, over the motion `fit` compared, for a law
/// with a Coulomb level (`None` otherwise: nothing to trend, or no channel to read it from).
pub fn mu0_trend(rec: &Record, fit: &FitResult) -> Option<Mu0Trend> {
    let ft = rec.ft.as_ref()?;
    if rec.apparatus || !fit.law.powers().contains(&0) || rec.units != crate::record::Units::Si {
        return None;
    }
    let rig = rec.rig().ok()?;
    let (tau, _, ydot) = rec.dimensionless().ok()?;
    let f: Vec<f64> = ft.iter().map(|v| v / rig.load_n).collect();
    let rate = 1.0 / rec.dt();
    if let Some(fc) = rec.force_cutoff_hz {
        return mu0_trend_of(
            &tau,
            &ydot,
            &f,
            &fit.mu,
            fit.span.range(),
            Some((fc, rate)),
            1.0 / rig.omega(),
        );
    }
    // A filter the record does not state is profiled, never guessed: none, or a 2-pole low-pass
    // anywhere in the range a bench's charge amplifier has (the delay and first-order memory
    // grids inside already stand for a 1-pole one). Without it, a `tribo sim` record with its
    // 300 Hz line removed read as a −4.4 % drift at 9.5σ.
    let mut best: Option<(Mu0Trend, f64)> = None;
    let cutoffs = [
        None,
        Some(100.0),
        Some(150.0),
        Some(200.0),
        Some(300.0),
        Some(450.0),
        Some(700.0),
        Some(1000.0),
    ];
    for fc in cutoffs {
        if fc.is_some_and(|c: f64| c >= 0.45 * rate) {
            continue;
        }
        let through = butterworth_or_none(fc.map(|fc| (fc, rate)));
        if let Some((t, rss)) = trend_and_rss(
            &tau,
            &ydot,
            &f,
            &fit.mu,
            fit.span.range(),
            &through,
            1.0 / rig.omega(),
        ) {
            if best.as_ref().is_none_or(|b| rss < b.1) {
                best = Some((t, rss));
            }
        }
    }
    best.map(|(t, _)| t)
}

/// Inverse of a small symmetric positive definite matrix (Gauss–Jordan with partial pivoting).
fn invert(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let mut m: Vec<Vec<f64>> = a
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let mut row = r.clone();
            row.extend((0..n).map(|j| f64::from(u8::from(i == j))));
            row
        })
        .collect();
    for c in 0..n {
        let p = (c..n).max_by(|&x, &y| m[x][c].abs().total_cmp(&m[y][c].abs()))?;
        if m[p][c].abs() < 1e-300 {
            return None;
        }
        m.swap(c, p);
        let d = m[c][c];
        m[c].iter_mut().for_each(|v| *v /= d);
        let pivot = m[c].clone();
        for (r, row) in m.iter_mut().enumerate() {
            if r != c {
                let fac = row[c];
                if fac != 0.0 {
                    for (x, p) in row.iter_mut().zip(&pivot) {
                        *x -= fac * p;
                    }
                }
            }
        }
    }
    Some(m.into_iter().map(|r| r[n..].to_vec()).collect())
}
