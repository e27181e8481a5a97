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
//!
//! The (filter, memory, delay) grid is searched, not swept: every delay (the rss is one grid point
//! wide in it) at every other memory and then at the best one's neighbours, on the whole span or,
//! when the span is longer than [`SEARCH_SAMPLES`], on four blocks spread over it (each with its
//! filters settled first); the chosen point's regression and ± are then those of every selected
//! sample. `tests/drift_search.rs` checks it against the exhaustive sweep
//! ([`mu0_trend_exhaustive`]) on ten records (drift or not, filter stated or not, sensor lags,
//! 2 and 6 s): the same trend and ± to the last digit. (On a light contact at the default force
//! noise, where the friction force is below the noise, the blocks chose another filter and the
//! trend moved by 0.1–0.3 of its ±.) The 40 s record's check: 48 s swept, 1.6 s searched.

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

/// A block of the span a search regresses on: its first sample (where its filters start), its
/// end, its selected samples.
type Block = (usize, usize, Vec<usize>);

/// How the (filter, memory, delay) grid is searched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Search {
    /// Every pair of the grid, every selected sample (the reference).
    Exhaustive,
    /// Coarse to fine over the grid, on at most [`SEARCH_SAMPLES`] samples of the span (a few
    /// blocks spread over it, each with its filters settled first); the chosen point's regression
    /// then on every selected sample.
    Fast,
}

/// Samples of the span the fast search regresses on (the span itself when it is not much longer).
const SEARCH_SAMPLES: usize = 16_000;
/// Blocks the fast search's samples are spread over.
const SEARCH_BLOCKS: usize = 4;
/// Time (rad of τ) each block's filters run before its samples are used: the slowest memory of
/// the grid (1 rad) has decayed by e⁻⁴⁰ by then, the 100 Hz low-pass far more.
const SETTLE_TAU: f64 = 40.0;
/// The step of the coarse memory grid (in grid points).
const COARSE: usize = 2;
/// How near the best rss (relative to the fitted samples' `f'f`) a pair's rss from sums must be
/// for it to be fitted on its design: far above what the normal equations lose (measured in the
/// module's tests: at most about 1e-13 of `f'f` on the test records).
const SUMS_MARGIN: f64 = 1e-8;

/// What every filter's search shares: the selected samples, the regressors before any filter,
/// the grid.
struct Prepared {
    start: usize,
    end: usize,
    /// Selected samples per half cycle (the clusters), and all of them in order.
    sel: Vec<Vec<usize>>,
    rows: Vec<usize>,
    /// The regressors over `start..end` before the channel's filter.
    base: Vec<Vec<f64>>,
    trend_col: usize,
    dtau: f64,
    /// Delays and memories (rad of τ).
    grid: Vec<f64>,
}

impl Prepared {
    fn new(
        tau: &[f64],
        ydot: &[f64],
        f: &[f64],
        mu: &[f64],
        range: std::ops::Range<usize>,
    ) -> Option<Prepared> {
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
        // Regressors over the span, as the force channel would show them: the Coulomb level
        // sgn y', each velocity term of the law |y'|^j sgn y', a Coulomb level changing in time
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
        // A delay of the channel (a sensor lag) or a memory of the contact (a frictional lag:
        // the force relaxing towards the steady law, a first-order low-pass of it) leaves a
        // transient after each reversal that the gain would partly take up, and with it the law's
        // decaying viscous part (a 3 ms sensor lag read as a 4 % drift, a 2 ms memory as 1–4 %):
        // both are profiled on a grid (0 to 1 rad of τ each, about 6 ms on the real rig, in steps
        // of 0.05 rad or a sample), the pair that fits best kept.
        let dtau = (tau[end - 1] - tau[start]) / (end - start - 1) as f64;
        let grid: Vec<f64> = {
            let h = 0.05f64.max(dtau);
            (0..)
                .map(|i| i as f64 * h)
                .take_while(|&x| x <= 1.0 + 1e-9)
                .collect()
        };
        let rows: Vec<usize> = sel.iter().flatten().copied().collect();
        Some(Prepared {
            start,
            end,
            sel,
            rows,
            base,
            trend_col,
            dtau,
            grid,
        })
    }

    /// The blocks a search regresses on: `(first sample, end, selected samples)`; the first
    /// sample is where the block's filters start.
    fn blocks(&self, search: Search) -> Vec<Block> {
        let n = self.end - self.start;
        let settle = (SETTLE_TAU / self.dtau).ceil() as usize;
        let core = SEARCH_SAMPLES / SEARCH_BLOCKS;
        if search == Search::Exhaustive || n <= SEARCH_SAMPLES + SEARCH_BLOCKS * settle {
            return vec![(self.start, self.end, self.rows.clone())];
        }
        (0..SEARCH_BLOCKS)
            .map(|b| {
                let c0 = self.start + settle + b * (n - settle - core) / (SEARCH_BLOCKS - 1);
                let rows = self
                    .rows
                    .iter()
                    .copied()
                    .filter(|&i| i >= c0 && i < c0 + core)
                    .collect();
                (c0 - settle, c0 + core, rows)
            })
            .collect()
    }

    /// The best (memory, delay) pair through `filter`: its grid indices and the residual sum of
    /// squares on the blocks' samples.
    fn search(
        &self,
        filter: &dyn Fn(&[f64]) -> Vec<f64>,
        blocks: &[Block],
        f: &[f64],
        search: Search,
    ) -> Option<(f64, usize, usize)> {
        let k = self.base.len() + 1;
        let filtered: Vec<Vec<Vec<f64>>> = blocks
            .iter()
            .map(|(o, e, _)| {
                self.base
                    .iter()
                    .map(|c| filter(&c[o - self.start..e - self.start]))
                    .collect()
            })
            .collect();
        let rows: Vec<usize> = blocks
            .iter()
            .flat_map(|(_, _, r)| r.iter().copied())
            .collect();
        let g = self.grid.len();
        let mut x = vec![0.0; rows.len() * k];
        // The rss of (memory, delay) on every sample of the blocks, from the regression's design
        // itself: the reference, and what the fast search's rss from sums is checked against.
        let mut exact = |im: usize, ids: &[usize]| -> Vec<Option<f64>> {
            let relaxed: Vec<Vec<Vec<f64>>> = filtered
                .iter()
                .map(|cols| {
                    cols.iter()
                        .map(|c| first_order(c, self.grid[im], self.dtau))
                        .collect()
                })
                .collect();
            ids.iter()
                .map(|&id| {
                    let mut at = 0;
                    for ((o, _, r), cols) in blocks.iter().zip(&relaxed) {
                        design(
                            &mut x[at * k..(at + r.len()) * k],
                            cols,
                            self.grid[id] / self.dtau,
                            r,
                            *o,
                        );
                        at += r.len();
                    }
                    least_squares_rss(&x, k, &rows, f).map(|(_, rss)| rss)
                })
                .collect()
        };
        // The fast search's rss of (memory, delay): the normal equations from per-run prefix
        // sums of the column products (O(runs) a delay, not O(rows)), the rss from them
        // (`f'f − 2β'X'f + β'X'Xβ`). It loses what the normal equations lose (about 1e-16 of
        // `f'f` times the design's conditioning): every pair whose rss from sums is within
        // [`SUMS_MARGIN`] of `f'f` of the best is then fitted on its design ([`exact`]), so the
        // pair chosen is the one the design's rss chooses.
        let runs: Vec<Vec<(usize, usize)>> =
            blocks.iter().map(|(o, _, r)| row_runs(r, *o)).collect();
        let ff: f64 = rows.iter().map(|&i| f[i] * f[i]).sum();
        let f_sums: Vec<f64> = blocks
            .iter()
            .map(|(_, _, r)| r.iter().map(|&i| f[i]).sum::<f64>())
            .collect();
        let max_shift = self
            .grid
            .last()
            .map_or(0, |&d| (d / self.dtau).floor() as usize);
        let from_sums = |im: usize, ids: &[usize]| -> Vec<Option<f64>> {
            let sums: Vec<Sums> = filtered
                .iter()
                .zip(&runs)
                .map(|(cols, rr)| {
                    let relaxed = first_order_cols(cols, self.grid[im], self.dtau);
                    // The earliest sample a delay of the grid reads (the held ones read only the
                    // first), less one for the sums one sample apart.
                    let first = rr.first().map_or(0, |r| r.0);
                    Sums::new(relaxed, first.saturating_sub(max_shift + 1))
                })
                .collect();
            ids.iter()
                .map(|&id| {
                    let d = self.grid[id] / self.dtau;
                    let mut gram = vec![vec![0.0; k]; k];
                    let mut xty = vec![0.0; k];
                    for ((((o, _, r), s), rr), &fs) in
                        blocks.iter().zip(&sums).zip(&runs).zip(&f_sums)
                    {
                        s.add_gram(&mut gram, d, rr);
                        s.add_xty(&mut xty, d, r, *o, f, fs);
                    }
                    rss_of_normal_equations(&gram, &xty, ff)
                })
                .collect()
        };
        // rss of every pair fitted so far, by (memory, delay), and whether it is the design's
        // (else from sums).
        let mut done: Vec<Option<(Option<f64>, bool)>> = vec![None; g * g];
        let margin = SUMS_MARGIN * ff;
        let mut fit_pairs =
            |pairs: &[(usize, usize)], done: &mut Vec<Option<(Option<f64>, bool)>>| {
                let mut by_memory: Vec<Vec<usize>> = vec![Vec::new(); g];
                for &(im, id) in pairs {
                    if done[im * g + id].is_none() && !by_memory[im].contains(&id) {
                        by_memory[im].push(id);
                    }
                }
                for (im, ids) in by_memory.iter().enumerate().filter(|(_, v)| !v.is_empty()) {
                    let rss = if search == Search::Exhaustive {
                        exact(im, ids)
                    } else {
                        from_sums(im, ids)
                    };
                    #[cfg(test)]
                    if tests::CHECK_SUMS.load(std::sync::atomic::Ordering::Relaxed) {
                        tests::record_sums_error(&rss, &exact(im, ids), ff);
                    }
                    for (id, rss) in ids.iter().zip(rss) {
                        done[im * g + id] = Some((rss, search == Search::Exhaustive));
                    }
                }
                // The pairs from sums near the best (or singular there) fitted on their design,
                // until the best and all within the margin of it are the design's.
                loop {
                    let best = done
                        .iter()
                        .filter_map(|v| v.and_then(|(r, _)| r))
                        .fold(f64::INFINITY, f64::min);
                    let mut todo: Vec<Vec<usize>> = vec![Vec::new(); g];
                    for (at, v) in done.iter().enumerate() {
                        if let Some((r, false)) = v {
                            if r.is_none_or(|r| r <= best + margin) {
                                todo[at / g].push(at % g);
                            }
                        }
                    }
                    if todo.iter().all(|v| v.is_empty()) {
                        break;
                    }
                    for (im, ids) in todo.iter().enumerate().filter(|(_, v)| !v.is_empty()) {
                        for (id, rss) in ids.iter().zip(exact(im, ids)) {
                            done[im * g + id] = Some((rss, true));
                        }
                    }
                }
            };
        // Best so far, ties to the lowest (memory, delay) as the exhaustive order has it.
        let best_of = |done: &[Option<(Option<f64>, bool)>]| -> Option<(f64, usize, usize)> {
            let mut best: Option<(f64, usize, usize)> = None;
            for (at, v) in done.iter().enumerate() {
                if let Some((Some(rss), _)) = v {
                    if best.is_none_or(|b| *rss < b.0) {
                        best = Some((*rss, at / g, at % g));
                    }
                }
            }
            best
        };
        let all: Vec<usize> = (0..g).collect();
        if search == Search::Exhaustive || g <= 2 * COARSE {
            let pairs: Vec<(usize, usize)> = all
                .iter()
                .flat_map(|&im| all.iter().map(move |&id| (im, id)))
                .collect();
            fit_pairs(&pairs, &mut done);
            return best_of(&done);
        }
        // Every delay (the rss is sharp in the delay: a 3 ms sensor lag's minimum is one grid
        // point wide, with other local minima beside it) at every COARSE-th memory and the last;
        // then every delay at the memories beside the best one.
        let coarse: Vec<usize> = (0..g).filter(|&i| i % COARSE == 0 || i == g - 1).collect();
        let pairs: Vec<(usize, usize)> = coarse
            .iter()
            .flat_map(|&im| all.iter().map(move |&id| (im, id)))
            .collect();
        fit_pairs(&pairs, &mut done);
        loop {
            let (_, im, _) = best_of(&done)?;
            let pairs: Vec<(usize, usize)> = (im.saturating_sub(COARSE - 1)..(im + COARSE).min(g))
                .filter(|&a| done[a * g].is_none())
                .flat_map(|a| all.iter().map(move |&b| (a, b)))
                .collect();
            if pairs.is_empty() {
                return best_of(&done);
            }
            fit_pairs(&pairs, &mut done);
        }
    }

    /// The trend of the regression through `filter` at memory `grid[im]`, delay `grid[id]`, on
    /// every selected sample of the span, with its cluster-robust ± and residual sum of squares.
    fn trend_at(
        &self,
        filter: &dyn Fn(&[f64]) -> Vec<f64>,
        im: usize,
        id: usize,
        f: &[f64],
        tau: &[f64],
        time_per_tau: f64,
    ) -> Option<(Mu0Trend, f64)> {
        let k = self.base.len() + 1;
        let relaxed: Vec<Vec<f64>> = self
            .base
            .iter()
            .map(|c| first_order(&filter(c), self.grid[im], self.dtau))
            .collect();
        let mut x = vec![0.0; self.rows.len() * k];
        design(
            &mut x,
            &relaxed,
            self.grid[id] / self.dtau,
            &self.rows,
            self.start,
        );
        let (beta, rss) = least_squares_rss(&x, k, &self.rows, f)?;
        let var_b = cluster_variance(&x, k, self.trend_col, &beta, &self.sel, f)?;
        let b = beta[self.trend_col];
        let se_b = var_b.max(0.0).sqrt();
        // μ0 as the channel reads it (its gain included, which cancels in the relative change).
        let level = beta[0];
        let span = tau[self.end - 1] - tau[self.start];
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
                half_cycles: self.sel.len(),
                z,
                significant: z > DRIFT_Z && (b * span / level).abs() > DRIFT_MIN,
            },
            rss,
        ))
    }
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
    let prep = Prepared::new(tau, ydot, f, mu, range)?;
    let blocks = prep.blocks(Search::Fast);
    let (_, im, id) = prep.search(filter, &blocks, f, Search::Fast)?;
    prep.trend_at(filter, im, id, f, tau, time_per_tau)
}

/// The maximal runs of consecutive samples among `rows` (sorted), as `[first, end)` indices from
/// `start`.
fn row_runs(rows: &[usize], start: usize) -> Vec<(usize, usize)> {
    let mut runs: Vec<(usize, usize)> = Vec::new();
    for &i in rows {
        let li = i - start;
        match runs.last_mut() {
            Some((_, e)) if *e == li => *e = li + 1,
            _ => runs.push((li, li + 1)),
        }
    }
    runs
}

/// Prefix sums of a block's regressors and of their products (same sample, and one sample apart
/// both ways): the Gram matrix of the delayed design over any run of samples from a few
/// differences. Row `u − off` of `data` holds, for the samples `off ≤ u' < u`, `Σ c_a` by column,
/// then `Σ c_a c_b` and `Σ (c_a[u'−1] c_b[u'] + c_b[u'−1] c_a[u'])` by `a ≤ b`.
struct Sums {
    cols: Vec<Vec<f64>>,
    off: usize,
    width: usize,
    data: Vec<f64>,
}

// The Gram matrix's entries are indexed by two columns at once.
#[allow(clippy::needless_range_loop)]
impl Sums {
    /// The sums of `cols` from sample `off`.
    fn new(cols: Vec<Vec<f64>>, off: usize) -> Sums {
        let kk = cols.len();
        let n = cols.first().map_or(0, Vec::len);
        let off = off.min(n);
        let width = kk + kk * (kk + 1);
        let data = match kk {
            2 => Self::table::<2, 8>(&cols, off),
            3 => Self::table::<3, 15>(&cols, off),
            4 => Self::table::<4, 24>(&cols, off),
            5 => Self::table::<5, 35>(&cols, off),
            6 => Self::table::<6, 48>(&cols, off),
            _ => Self::table_any(&cols, off),
        };
        Sums {
            cols,
            off,
            width,
            data,
        }
    }

    /// The prefix sums' table (`data`) of any number of columns from sample `off`.
    fn table_any(cols: &[Vec<f64>], off: usize) -> Vec<f64> {
        let kk = cols.len();
        let n = cols.first().map_or(0, Vec::len);
        let tri = kk * (kk + 1) / 2;
        let width = kk + 2 * tri;
        // Row 0 (no sample yet) is zeros; each sample's row is appended (no zeroing first).
        let mut data = Vec::with_capacity((n - off + 1) * width);
        data.resize(width, 0.0);
        let mut acc = vec![0.0; width];
        let mut cur = vec![0.0; kk];
        let mut prev = vec![0.0; kk];
        for u in off..n {
            for a in 0..kk {
                cur[a] = cols[a][u];
                prev[a] = if u == 0 { 0.0 } else { cols[a][u - 1] };
            }
            let mut t = 0;
            for a in 0..kk {
                acc[a] += cur[a];
                for b in a..kk {
                    acc[kk + t] += cur[a] * cur[b];
                    acc[kk + tri + t] += prev[a] * cur[b] + prev[b] * cur[a];
                    t += 1;
                }
            }
            data.extend_from_slice(&acc);
        }
        data
    }

    /// [`Sums::table_any`] for `K` columns (`W = K + K(K+1)` numbers a row): the same numbers, the
    /// row's length known to the compiler.
    fn table<const K: usize, const W: usize>(cols: &[Vec<f64>], off: usize) -> Vec<f64> {
        debug_assert_eq!(W, K + K * (K + 1));
        let n = cols[0].len();
        let tri = K * (K + 1) / 2;
        let src: [&[f64]; K] = std::array::from_fn(|a| cols[a].as_slice());
        let mut data = Vec::with_capacity((n - off + 1) * W);
        data.resize(W, 0.0);
        let mut acc = [0.0; W];
        for u in off..n {
            let cur: [f64; K] = std::array::from_fn(|a| src[a][u]);
            let prev: [f64; K] = std::array::from_fn(|a| if u == 0 { 0.0 } else { src[a][u - 1] });
            let mut t = 0;
            for a in 0..K {
                acc[a] += cur[a];
                for b in a..K {
                    acc[K + t] += cur[a] * cur[b];
                    acc[K + tri + t] += prev[a] * cur[b] + prev[b] * cur[a];
                    t += 1;
                }
            }
            data.extend_from_slice(&acc);
        }
        data
    }

    /// Where a delay of `d` samples reads: `(m, φ)`, the value at sample `u` being
    /// `φ c[u−m−1] + (1−φ) c[u−m]` for `u > m` and `c[0]` for `u ≤ m` (as [`design`] has it).
    fn split(d: f64) -> (usize, f64) {
        if d <= 0.0 {
            return (0, 0.0);
        }
        let m = d.floor();
        (m as usize, d - m)
    }

    /// Adds the Gram matrix (`k` = columns + the constant) of the design delayed by `d` samples
    /// over the runs `runs`.
    fn add_gram(&self, gram: &mut [Vec<f64>], d: f64, runs: &[(usize, usize)]) {
        let kk = self.cols.len();
        let (m, phi) = Self::split(d);
        let (w11, w10, w00) = (phi * phi, phi * (1.0 - phi), (1.0 - phi) * (1.0 - phi));
        for &(r0, r1) in runs {
            // Samples that read the first value.
            let held = r1.min(m + 1).saturating_sub(r0);
            if held > 0 {
                let h = held as f64;
                for a in 0..kk {
                    let ca = self.cols[a][0];
                    gram[a][kk] += h * ca;
                    for b in a..kk {
                        gram[a][b] += h * ca * self.cols[b][0];
                    }
                }
                gram[kk][kk] += h;
            }
            let s0 = r0.max(m + 1);
            if s0 >= r1 {
                continue;
            }
            // The sums over u = sample − m in [u0, u1) (u0 − 1 ≥ off: see `Sums::new`'s caller).
            let (u0, u1) = (s0 - m, r1 - m);
            let w = self.width;
            let tri = kk * (kk + 1) / 2;
            let row = |u: usize| &self.data[(u - self.off) * w..(u - self.off + 1) * w];
            let (hi0, lo0, hi1, lo1) = (row(u1), row(u0), row(u1 - 1), row(u0 - 1));
            let diff0 = |j: usize| hi0[j] - lo0[j];
            let diff1 = |j: usize| hi1[j] - lo1[j];
            let mut t = 0;
            for a in 0..kk {
                gram[a][kk] += phi * diff1(a) + (1.0 - phi) * diff0(a);
                for b in a..kk {
                    let mut v = w00 * diff0(kk + t);
                    if phi != 0.0 {
                        v += w11 * diff1(kk + t) + w10 * diff0(kk + tri + t);
                    }
                    gram[a][b] += v;
                    t += 1;
                }
            }
            gram[kk][kk] += (r1 - s0) as f64;
        }
    }

    /// Adds `X'f` of the design delayed by `d` samples at the samples `rows` (block from `start`);
    /// `f_sum`: `Σ f` over `rows` (the constant's entry, the same at every delay).
    fn add_xty(
        &self,
        xty: &mut [f64],
        d: f64,
        rows: &[usize],
        start: usize,
        f: &[f64],
        f_sum: f64,
    ) {
        let kk = self.cols.len();
        match kk {
            2 => self.add_xty_k::<2>(xty, d, rows, start, f),
            3 => self.add_xty_k::<3>(xty, d, rows, start, f),
            4 => self.add_xty_k::<4>(xty, d, rows, start, f),
            5 => self.add_xty_k::<5>(xty, d, rows, start, f),
            6 => self.add_xty_k::<6>(xty, d, rows, start, f),
            _ => {
                let (m, phi) = Self::split(d);
                for (a, c) in self.cols.iter().enumerate() {
                    let mut acc = 0.0;
                    for &i in rows {
                        acc += Self::delayed(c, i - start, m, phi) * f[i];
                    }
                    xty[a] += acc;
                }
            }
        }
        xty[kk] += f_sum;
    }

    /// Column `c` delayed by `(m, φ)` ([`Sums::split`]) at sample `li` of the block.
    #[inline(always)]
    fn delayed(c: &[f64], li: usize, m: usize, phi: f64) -> f64 {
        if li <= m {
            c[0]
        } else if phi == 0.0 {
            c[li - m]
        } else {
            phi * c[li - m - 1] + (1.0 - phi) * c[li - m]
        }
    }

    /// [`Sums::add_xty`]'s columns for `K` of them: every column's sum over the rows in the rows'
    /// order, as the general loop adds them (the same numbers), the columns side by side.
    fn add_xty_k<const K: usize>(
        &self,
        xty: &mut [f64],
        d: f64,
        rows: &[usize],
        start: usize,
        f: &[f64],
    ) {
        let (m, phi) = Self::split(d);
        let cols: [&[f64]; K] = std::array::from_fn(|a| self.cols[a].as_slice());
        let mut acc = [0.0; K];
        for &i in rows {
            let li = i - start;
            let fi = f[i];
            for a in 0..K {
                acc[a] += Self::delayed(cols[a], li, m, phi) * fi;
            }
        }
        for a in 0..K {
            xty[a] += acc[a];
        }
    }
}

/// The residual sum of squares of the least squares whose normal equations are `gram` (upper
/// triangle filled) and `xty`, `ff` the data's sum of squares (`f'f − 2β'X'f + β'X'Xβ`).
#[allow(clippy::needless_range_loop)]
fn rss_of_normal_equations(gram: &[Vec<f64>], xty: &[f64], ff: f64) -> Option<f64> {
    let k = xty.len();
    let mut full = gram.to_vec();
    for a in 0..k {
        for b in 0..a {
            full[a][b] = full[b][a];
        }
    }
    let inv = invert(&full)?;
    let beta: Vec<f64> = (0..k)
        .map(|a| (0..k).map(|b| inv[a][b] * xty[b]).sum())
        .collect();
    let mut rss = ff;
    for a in 0..k {
        rss -= 2.0 * beta[a] * xty[a];
        for b in 0..k {
            rss += beta[a] * full[a][b] * beta[b];
        }
    }
    Some(rss)
}

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

/// [`first_order`] of every column of `cols`, the columns side by side (each column's numbers
/// are what [`first_order`] gives it).
fn first_order_cols(cols: &[Vec<f64>], t: f64, h: f64) -> Vec<Vec<f64>> {
    let n = cols.first().map_or(0, Vec::len);
    if t <= 0.0 || n == 0 || cols.iter().any(|c| c.len() != n) {
        return cols.iter().map(|c| first_order(c, t, h)).collect();
    }
    match cols.len() {
        2 => first_order_k::<2>(cols, t, h),
        3 => first_order_k::<3>(cols, t, h),
        4 => first_order_k::<4>(cols, t, h),
        5 => first_order_k::<5>(cols, t, h),
        6 => first_order_k::<6>(cols, t, h),
        _ => cols.iter().map(|c| first_order(c, t, h)).collect(),
    }
}

/// [`first_order_cols`] of `K` columns of equal, non-zero length.
// Sample `u` of every column at once.
#[allow(clippy::needless_range_loop)]
fn first_order_k<const K: usize>(cols: &[Vec<f64>], t: f64, h: f64) -> Vec<Vec<f64>> {
    let n = cols[0].len();
    let a = 1.0 - (-h / t).exp();
    let src: [&[f64]; K] = std::array::from_fn(|i| &cols[i][..n]);
    let mut y: [f64; K] = std::array::from_fn(|i| src[i][0]);
    let mut out: [Vec<f64>; K] = std::array::from_fn(|_| Vec::with_capacity(n));
    for u in 0..n {
        for i in 0..K {
            y[i] += a * (src[i][u] - y[i]);
            out[i].push(y[i]);
        }
    }
    out.into_iter().collect()
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
    mu0_trend_for(rec, fit.law, &fit.mu, fit.span.range())
}

/// [`mu0_trend`] of a fit of `law` whose constants are `mu` over `range`: of `mu`, only its length
/// and which of them are zero count.
pub(crate) fn mu0_trend_for(
    rec: &Record,
    law: LawSpec,
    mu: &[f64],
    range: std::ops::Range<usize>,
) -> Option<Mu0Trend> {
    let TrendInputs {
        rig,
        tau,
        ydot,
        f,
        rate,
    } = TrendInputs::of(rec, law)?;
    if let Some(fc) = rec.force_cutoff_hz {
        return mu0_trend_of(
            &tau,
            &ydot,
            &f,
            mu,
            range,
            Some((fc, rate)),
            1.0 / rig.omega(),
        );
    }
    mu0_trend_unstated(rec, mu, range, &tau, &ydot, &f, rate, Search::Fast)
}

/// [`mu0_trend`] with the grid searched exhaustively (every filter, memory and delay on every
/// selected sample): the reference the fast search is checked against (`tests/drift_search.rs`).
#[doc(hidden)]
pub fn mu0_trend_exhaustive(rec: &Record, fit: &FitResult) -> Option<Mu0Trend> {
    let TrendInputs {
        rig,
        tau,
        ydot,
        f,
        rate,
    } = TrendInputs::of(rec, fit.law)?;
    if let Some(fc) = rec.force_cutoff_hz {
        let prep = Prepared::new(&tau, &ydot, &f, &fit.mu, fit.span.range())?;
        let through = butterworth_or_none(Some((fc, rate)));
        let blocks = prep.blocks(Search::Exhaustive);
        let (_, im, id) = prep.search(&through, &blocks, &f, Search::Exhaustive)?;
        return prep
            .trend_at(&through, im, id, &f, &tau, 1.0 / rig.omega())
            .map(|(t, _)| t);
    }
    mu0_trend_unstated(
        rec,
        &fit.mu,
        fit.span.range(),
        &tau,
        &ydot,
        &f,
        rate,
        Search::Exhaustive,
    )
}

/// What both searches of [`mu0_trend`] read from a record: the rig, the dimensionless time and
/// velocity, the friction channel over the load, the sample rate (`None` when there is nothing to
/// trend: no force channel, an apparatus run, a law without a Coulomb level, a dimensionless
/// record).
struct TrendInputs {
    rig: crate::rig::Rig,
    tau: Vec<f64>,
    ydot: Vec<f64>,
    f: Vec<f64>,
    rate: f64,
}

impl TrendInputs {
    fn of(rec: &Record, law: LawSpec) -> Option<Self> {
        let ft = rec.ft.as_ref()?;
        if rec.apparatus || !law.powers().contains(&0) || rec.units != crate::record::Units::Si {
            return None;
        }
        let rig = rec.rig().ok()?;
        let (tau, _, ydot) = rec.dimensionless().ok()?;
        let f: Vec<f64> = ft.iter().map(|v| v / rig.load_n).collect();
        let rate = 1.0 / rec.dt();
        Some(Self {
            rig,
            tau,
            ydot,
            f,
            rate,
        })
    }
}

/// The trend through the filter, of those a bench's channel may have, that fits best.
#[allow(clippy::too_many_arguments)]
fn mu0_trend_unstated(
    rec: &Record,
    mu: &[f64],
    range: std::ops::Range<usize>,
    tau: &[f64],
    ydot: &[f64],
    f: &[f64],
    rate: f64,
    search: Search,
) -> Option<Mu0Trend> {
    let rig = rec.rig().ok()?;
    let prep = Prepared::new(tau, ydot, f, mu, range)?;
    prep.trend_unstated(f, tau, rate, None, search, 1.0 / rig.omega())
}

/// A force channel's low-pass as a function of a regressor (every sample of the span).
pub type LowPass<'a> = dyn Fn(&[f64]) -> Vec<f64> + Sync + 'a;

/// [`mu0_trend_of`] for a force channel whose low-pass the record does not state: the trend
/// through whichever fits the force best (the smallest residual sum of squares of the
/// regression) of none, a bench's 2-pole low-pass at 100–1000 Hz (below 0.45 of `rate_hz`) and
/// `fitted`, a low-pass estimated elsewhere (e.g. `tribo explain`'s, fitted with its model).
/// A filter fitted on a model is a candidate, not the answer: on a viscous-dominated record
/// without a filter (grid #433 of `explain_lhs`, μ0 0.0016, μ1 0.0039) explain's model fitted
/// 577 Hz, and the regressors through it read μ0 falling by 108 ± 6.6 % (16σ) where the
/// record's own regression, through none, reads −13 ± 12 %.
#[allow(clippy::too_many_arguments)]
pub fn mu0_trend_profiled(
    tau: &[f64],
    ydot: &[f64],
    f: &[f64],
    mu: &[f64],
    range: std::ops::Range<usize>,
    rate_hz: f64,
    fitted: Option<&LowPass<'_>>,
    time_per_tau: f64,
) -> Option<Mu0Trend> {
    let prep = Prepared::new(tau, ydot, f, mu, range)?;
    prep.trend_unstated(f, tau, rate_hz, fitted, Search::Fast, time_per_tau)
}

impl Prepared {
    /// The trend through the best-fitting filter of none, the bench's 2-pole cut-offs and
    /// `fitted` (ties to the first in that order).
    fn trend_unstated(
        &self,
        f: &[f64],
        tau: &[f64],
        rate: f64,
        fitted: Option<&LowPass<'_>>,
        search: Search,
        time_per_tau: f64,
    ) -> Option<Mu0Trend> {
        // A filter the record does not state is profiled, never guessed: none, or a 2-pole
        // low-pass anywhere in the range a bench's charge amplifier has (the delay and
        // first-order memory grids inside already stand for a 1-pole one). Without it, a `tribo
        // sim` record with its 300 Hz line removed read as a −4.4 % drift at 9.5σ.
        let cutoffs: Vec<Option<f64>> = [
            None,
            Some(100.0),
            Some(150.0),
            Some(200.0),
            Some(300.0),
            Some(450.0),
            Some(700.0),
            Some(1000.0),
        ]
        .into_iter()
        .filter(|fc| !fc.is_some_and(|c: f64| c >= 0.45 * rate))
        .collect();
        let mut candidates: Vec<Box<LowPass<'_>>> = cutoffs
            .iter()
            .map(|fc| Box::new(butterworth_or_none(fc.map(|fc| (fc, rate)))) as Box<LowPass<'_>>)
            .collect();
        if let Some(fit) = fitted {
            candidates.push(Box::new(fit));
        }
        let blocks = self.blocks(search);
        // Each filter searched on its own thread ([`super::par_map`]); the best kept in the order
        // above (ties to the first).
        let found = super::par_map(&candidates, |through| {
            self.search(through.as_ref(), &blocks, f, search)
        });
        let mut best: Option<(f64, usize, usize, usize)> = None;
        for (c, r) in found.into_iter().enumerate() {
            if let Some((rss, im, id)) = r {
                if best.is_none_or(|b| rss < b.0) {
                    best = Some((rss, im, id, c));
                }
            }
        }
        let (_, im, id, c) = best?;
        self.trend_at(candidates[c].as_ref(), im, id, f, tau, time_per_tau)
            .map(|(t, _)| t)
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::Method;
    use crate::sensor::{generate, RecordSpec, SensorModel};
    use crate::{FrictionLaw, Model, Rig};
    use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

    /// Whether the fast search also fits every pair on its design and records how far its rss
    /// from sums was ([`SUMS_ERROR`]: the largest `|from sums − design| / f'f`, as f64 bits).
    pub(super) static CHECK_SUMS: AtomicBool = AtomicBool::new(false);
    static SUMS_ERROR: AtomicU64 = AtomicU64::new(0);
    static SUMS_PAIRS: AtomicU64 = AtomicU64::new(0);

    pub(super) fn record_sums_error(sums: &[Option<f64>], design: &[Option<f64>], ff: f64) {
        for (a, b) in sums.iter().zip(design) {
            let e = match (a, b) {
                (Some(a), Some(b)) => (a - b).abs() / ff,
                (None, None) => 0.0,
                // One singular and not the other: as far as it can be.
                _ => f64::INFINITY,
            };
            SUMS_PAIRS.fetch_add(1, Ordering::Relaxed);
            let _ = SUMS_ERROR.fetch_update(Ordering::Relaxed, Ordering::Relaxed, |v| {
                Some(f64::from_bits(v).max(e).to_bits())
            });
        }
    }

    /// The rss from sums stays far inside [`SUMS_MARGIN`] of the design's on records at the
    /// edges of what the search sees: a noiseless light contact (its rss near 0, where the
    /// normal equations lose most), a noisy one, blocks and one span, a sensor lag (the rss
    /// sharp in the delay), the filter stated and not.
    #[test]
    fn the_rss_from_sums_is_the_designs() {
        CHECK_SUMS.store(true, Ordering::Relaxed);
        for (secs, light, noise, lag_s, stated) in [
            (2.0, false, true, 0.003, false),
            (2.0, false, false, 0.0, true),
            (8.0, true, false, 0.0, false),
            (8.0, true, true, 0.001, true),
        ] {
            let rig = Rig {
                load_n: if light { 0.05 } else { 0.3 },
                ..Rig::REAL
            };
            let spec = RecordSpec {
                rig,
                x0_m: 667e-6,
                v0_m_s: 0.0,
                duration_s: secs,
                rate_hz: 10_000.0,
            };
            let law = if light {
                FrictionLaw::quadratic(0.0008, 0.0011, 0.0005)
            } else {
                FrictionLaw::quadratic(0.01, 0.01, 0.002)
            };
            let sensor = SensorModel {
                force_lag_s: lag_s,
                force_noise_n: if light { 1e-5 } else { 2e-4 },
                ..SensorModel::default()
            };
            let mut rec = generate(
                &spec,
                &Model::new(law),
                Method::default(),
                noise.then_some(&sensor),
            )
            .unwrap();
            if !stated {
                rec.force_cutoff_hz = None;
            }
            SUMS_ERROR.store(0, Ordering::Relaxed);
            SUMS_PAIRS.store(0, Ordering::Relaxed);
            let r = crate::identify::fit(
                &rec,
                crate::identify::LawSpec::Quadratic,
                &crate::identify::FitOptions::default(),
            )
            .unwrap();
            assert!(r.mu0_trend.is_some(), "{secs} s: a trend");
            let e = f64::from_bits(SUMS_ERROR.load(Ordering::Relaxed));
            let n = SUMS_PAIRS.load(Ordering::Relaxed);
            eprintln!(
                "{secs} s light {light} noise {noise} lag {lag_s}: {n} pairs, error {e:.2e} of f'f"
            );
            assert!(n > 100, "{n} pairs compared");
            assert!(e < 1e-3 * SUMS_MARGIN, "rss from sums off by {e:e} of f'f");
        }
    }
}

#[cfg(test)]
mod fitted_filter_tests {
    use super::*;
    use crate::integrate::Method;
    use crate::sensor::{generate, RecordSpec, SensorModel};
    use crate::{FrictionLaw, Model, Rig};

    /// At the edge of the contacts a bench shows, a light viscous-dominated one (μ0 0.0016 beside
    /// μ1 0.0039, 0.053 N, grid #433's) whose force channel has no filter: its regressors through
    /// a 2-pole low-pass fitted elsewhere (577 Hz, what `tribo explain` fitted on #433) read μ0
    /// falling by most of itself at many σ, which no drift did. The profiled trend keeps the
    /// filter that fits the force best (none), reads no drift, and is `tribo fit`'s own.
    #[test]
    fn a_fitted_filter_the_channel_does_not_have_is_no_drift() {
        let rig = Rig {
            mass_kg: 0.0325,
            stiffness_n_per_m: 1404.0,
            load_n: 0.053,
        };
        let rate = 7_700.0;
        let spec = RecordSpec {
            rig,
            x0_m: 772e-6,
            v0_m_s: 0.0,
            duration_s: 6.0,
            rate_hz: rate,
        };
        let law = FrictionLaw::quadratic(0.0016, 0.0039, 0.0);
        let sensor = SensorModel {
            force_cutoff_hz: None,
            seed: 433,
            ..SensorModel::default()
        };
        let rec = generate(&spec, &Model::new(law), Method::default(), Some(&sensor)).unwrap();
        assert_eq!(rec.force_cutoff_hz, None);
        let r = crate::identify::fit(&rec, LawSpec::CoulombViscous, &Default::default()).unwrap();
        let (tau, _, ydot) = rec.dimensionless().unwrap();
        let f: Vec<f64> = rec
            .ft
            .as_ref()
            .unwrap()
            .iter()
            .map(|v| v / rig.load_n)
            .collect();
        let fitted = |c: &[f64]| crate::sensor::butterworth2(c, 577.0, rate);
        let pct = |t: &Mu0Trend| {
            format!(
                "{:+.1} ± {:.1} % ({:.1}σ)",
                100.0 * t.relative_change,
                100.0 * t.relative_change_se,
                t.z
            )
        };
        let per_tau = 1.0 / rig.omega();
        let forced =
            mu0_trend_through(&tau, &ydot, &f, &r.mu, r.span.range(), &fitted, per_tau).unwrap();
        let profiled = mu0_trend_profiled(
            &tau,
            &ydot,
            &f,
            &r.mu,
            r.span.range(),
            rate,
            Some(&fitted),
            per_tau,
        )
        .unwrap();
        let own = r.mu0_trend.clone().unwrap();
        eprintln!(
            "mu {:?}: through 577 Hz {}, profiled {}, tribo fit's {}",
            r.mu,
            pct(&forced),
            pct(&profiled),
            pct(&own)
        );
        // The edge: the filter the channel does not have reads as a drift.
        assert!(forced.significant, "through 577 Hz: {}", pct(&forced));
        assert!(
            !profiled.significant && profiled.z < DRIFT_Z,
            "profiled: {}",
            pct(&profiled)
        );
        assert_eq!(profiled, own, "the profiled trend is tribo fit's");
    }
}

#[cfg(test)]
mod side_by_side_tests {
    use super::*;

    /// Columns of pseudo-random numbers (a fixed sequence).
    fn columns(k: usize, n: usize) -> Vec<Vec<f64>> {
        let mut z: u64 = 0x2545_f491_4f6c_dd1d;
        (0..k)
            .map(|_| {
                (0..n)
                    .map(|_| {
                        z = z
                            .wrapping_mul(6364136223846793005)
                            .wrapping_add(1442695040888963407);
                        (z >> 11) as f64 / (1u64 << 53) as f64 - 0.3
                    })
                    .collect()
            })
            .collect()
    }

    /// `X'f` as one loop a column (the form before the columns were summed side by side).
    fn xty_by_column(s: &Sums, d: f64, rows: &[usize], start: usize, f: &[f64]) -> Vec<f64> {
        let kk = s.cols.len();
        let (m, phi) = Sums::split(d);
        let mut xty = vec![0.0; kk + 1];
        for (a, c) in s.cols.iter().enumerate() {
            let mut acc = 0.0;
            for &i in rows {
                let li = i - start;
                let x = if li <= m {
                    c[0]
                } else if phi == 0.0 {
                    c[li - m]
                } else {
                    phi * c[li - m - 1] + (1.0 - phi) * c[li - m]
                };
                acc += x * f[i];
            }
            xty[a] += acc;
        }
        xty[kk] += rows.iter().map(|&i| f[i]).sum::<f64>();
        xty
    }

    #[test]
    fn the_side_by_side_loops_are_the_column_loops_to_the_bit() {
        // first_order_cols, Sums::new's table and add_xty for 1 to 8 columns.
        let n = 3000;
        let f = columns(1, n + 40).remove(0);
        let start = 40;
        // Rows in runs, as the selected samples are (every third block of 50 left out).
        let rows: Vec<usize> = (start..start + n).filter(|i| (i / 50) % 3 != 0).collect();
        let f_sum: f64 = rows.iter().map(|&i| f[i]).sum();
        for k in 1..=8 {
            let cols = columns(k, n);
            for t in [0.0, 0.05, 0.37, 1.0] {
                let side = first_order_cols(&cols, t, 0.017);
                for (a, c) in cols.iter().enumerate() {
                    let one: Vec<u64> = first_order(c, t, 0.017)
                        .iter()
                        .map(|v| v.to_bits())
                        .collect();
                    let two: Vec<u64> = side[a].iter().map(|v| v.to_bits()).collect();
                    assert_eq!(one, two, "first_order, {k} columns, t {t}");
                }
            }
            for off in [0, 1, 37] {
                let s = Sums::new(cols.clone(), off);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
                let any = Sums::table_any(&cols, off);
                assert_eq!(
                    bits(&s.data),
                    bits(&any),
                    "prefix sums, {k} columns, from {off}"
                );
            }
            let s = Sums::new(cols, 0);
            for d in [0.0, 1.0, 2.9411, 17.0, 58.8, 120.5] {
                let mut xty = vec![0.0; k + 1];
                s.add_xty(&mut xty, d, &rows, start, &f, f_sum);
                let want = xty_by_column(&s, d, &rows, start, &f);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<u64>>();
                assert_eq!(bits(&xty), bits(&want), "X'f, {k} columns, delay {d}");
            }
        }
    }
}
