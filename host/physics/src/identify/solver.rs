//! Least squares: the normal equations and Levenberg–Marquardt.

/// Linear least squares by normal equations (small problems).
pub fn least_squares(rows: &[Vec<f64>], rhs: &[f64]) -> Option<Vec<f64>> {
    let p = rows.first()?.len();
    let mut a = vec![vec![0.0; p]; p];
    let mut b = vec![0.0; p];
    for (r, &y) in rows.iter().zip(rhs) {
        for i in 0..p {
            b[i] += r[i] * y;
            for j in 0..p {
                a[i][j] += r[i] * r[j];
            }
        }
    }
    solve(a, b)
}

/// Solves a small dense system by Gaussian elimination with partial pivoting.
#[allow(clippy::needless_range_loop)]
pub fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Option<Vec<f64>> {
    let n = b.len();
    for c in 0..n {
        let piv = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[piv][c].abs() < 1e-300 || !a[piv][c].is_finite() {
            return None;
        }
        a.swap(c, piv);
        b.swap(c, piv);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| a[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Outcome of [`levenberg_marquardt`].
#[derive(Debug, Clone, PartialEq)]
pub struct LmResult {
    /// Parameters at the minimum.
    pub p: Vec<f64>,
    /// Cost ½ Σ r².
    pub cost: f64,
    /// Iterations.
    pub iterations: usize,
    /// Tolerance met.
    pub converged: bool,
    /// The residuals `r(p)` at `p` (what the last accepted evaluation returned).
    pub residuals: Vec<f64>,
}

/// How [`levenberg_marquardt_with`] differentiates and when it stops.
#[derive(Debug, Clone, PartialEq)]
pub struct LmOptions {
    /// Iteration limit.
    pub max_iter: usize,
    /// Convergence: relative cost decrease (and relative parameter step below `√tol / 100`).
    pub tol: f64,
    /// Finite-difference step of parameter `j`: `rel_step · max(|p_j|, scale_j)`.
    pub rel_step: f64,
    /// Typical magnitude of each parameter, used for the step when `p_j` is near 0 (missing
    /// entries: 1e-4).
    pub scales: Vec<f64>,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iter: 60,
            tol: 1e-12,
            rel_step: 1e-7,
            scales: Vec::new(),
        }
    }
}

/// Levenberg–Marquardt on residuals `r(p)` (`None` = could not evaluate: treated as a rejected
/// step), forward-difference Jacobian, Marquardt diagonal scaling. `None` if `r(p0)` fails.
pub fn levenberg_marquardt(
    r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    p0: &[f64],
    max_iter: usize,
    tol: f64,
) -> Option<LmResult> {
    levenberg_marquardt_with(
        r,
        p0,
        &LmOptions {
            max_iter,
            tol,
            ..LmOptions::default()
        },
    )
}

/// [`levenberg_marquardt`] with the difference step chosen per parameter. A coarser step than the
/// default 1e-7 is needed when the residuals are only piecewise smooth at fine scales (an adaptive
/// integrator's steps, the stick events of Coulomb friction on long records). Where the forward
/// point cannot be evaluated the backward difference is used.
pub fn levenberg_marquardt_with(
    r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    p0: &[f64],
    opts: &LmOptions,
) -> Option<LmResult> {
    let r = std::cell::RefCell::new(r);
    lm_core(
        |q| (r.borrow_mut())(q),
        |p, res| {
            (0..p.len())
                .map(|j| {
                    difference_column(
                        &|q: &[f64]| (r.borrow_mut())(q),
                        p,
                        res,
                        j,
                        step(opts, p, j),
                    )
                })
                .collect()
        },
        p0,
        opts,
    )
}

/// [`levenberg_marquardt_with`] for residuals that can be evaluated on several threads at once:
/// the Jacobian's columns are computed in parallel ([`set_fit_threads`]), each exactly as the
/// serial version computes it, so the result is the same to the last bit.
pub fn levenberg_marquardt_par(
    r: impl Fn(&[f64]) -> Option<Vec<f64>> + Sync,
    p0: &[f64],
    opts: &LmOptions,
) -> Option<LmResult> {
    lm_core(
        &r,
        |p, res| {
            let cols: Vec<usize> = (0..p.len()).collect();
            par_map(&cols, |&j| {
                difference_column(&r, p, res, j, step(opts, p, j))
            })
            .into_iter()
            .collect()
        },
        p0,
        opts,
    )
}

/// The difference step of parameter `j` at `p`.
fn step(opts: &LmOptions, p: &[f64], j: usize) -> f64 {
    let scale = opts.scales.get(j).copied().unwrap_or(1e-4);
    opts.rel_step * p[j].abs().max(scale)
}

/// Levenberg–Marquardt with residuals `r` and their Jacobian `jac_of(p, r(p))`.
fn lm_core(
    mut r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    mut jac_of: impl FnMut(&[f64], &[f64]) -> Option<Vec<Vec<f64>>>,
    p0: &[f64],
    opts: &LmOptions,
) -> Option<LmResult> {
    let (max_iter, tol) = (opts.max_iter, opts.tol);
    let n = p0.len();
    let mut p = p0.to_vec();
    let mut res = r(&p)?;
    let cost = |v: &[f64]| 0.5 * v.iter().map(|x| x * x).sum::<f64>();
    let mut c = cost(&res);
    let mut lambda = 1e-3;
    let mut converged = false;
    let mut it = 0;
    while it < max_iter {
        it += 1;
        let jac = jac_of(&p, &res)?;
        let mut jtj = vec![vec![0.0; n]; n];
        let mut jtr = vec![0.0; n];
        for i in 0..n {
            jtr[i] = jac[i].iter().zip(&res).map(|(a, b)| a * b).sum();
            for k in 0..n {
                jtj[i][k] = jac[i].iter().zip(&jac[k]).map(|(a, b)| a * b).sum();
            }
        }
        let mut improved = false;
        for _ in 0..20 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[i][i] += lambda * jtj[i][i].max(1e-30);
            }
            let Some(step) = solve(a, jtr.iter().map(|v| -v).collect()) else {
                lambda *= 10.0;
                continue;
            };
            let q: Vec<f64> = p.iter().zip(&step).map(|(a, b)| a + b).collect();
            if let Some(rq) = r(&q) {
                let cq = cost(&rq);
                if cq.is_finite() && cq < c {
                    let rel_step = step
                        .iter()
                        .zip(&q)
                        .map(|(s, v)| s.abs() / v.abs().max(1e-6))
                        .fold(0.0, f64::max);
                    let rel_cost = (c - cq) / c.max(1e-300);
                    p = q;
                    res = rq;
                    c = cq;
                    lambda = (lambda * 0.2).max(1e-12);
                    improved = true;
                    if rel_step < tol.sqrt() * 1e-2 || rel_cost < tol || c < 1e-28 {
                        converged = true;
                    }
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved {
            // No downhill step at any damping: a (numerical) minimum.
            converged = true;
            break;
        }
        if converged {
            break;
        }
    }
    Some(LmResult {
        p,
        cost: c,
        iterations: it,
        converged,
        residuals: res,
    })
}

thread_local! {
    /// Threads [`par_map`] may use on this thread (0 = every core).
    static INNER_THREADS: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Sets how many threads the fits run on this thread may use for their own simulations (the
/// Jacobian's columns): 1 keeps them on this thread (a caller that already fits several records on
/// every core), 0 = every core (the default). Results do not depend on it.
pub fn set_fit_threads(n: usize) {
    INNER_THREADS.with(|c| c.set(n));
}

/// Threads [`par_map`] uses on this thread.
pub(crate) fn fit_threads() -> usize {
    match INNER_THREADS.with(|c| c.get()) {
        0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
        n => n,
    }
}

/// `items.map(f)` on every core, for many independent fits (records, stored runs): workers take
/// the next item as they finish one, each fitting on its own thread ([`set_fit_threads`]`(1)`
/// while it runs `f`); the results in input order. `done` is called (on the worker) after each
/// item, e.g. to move a progress bar. Each result is what `f` gives serially.
pub fn map_on_every_core<T: Sync, U: Send>(
    items: &[T],
    f: impl Fn(&T) -> U + Sync,
    done: impl Fn() + Sync,
) -> Vec<U> {
    let cores = std::thread::available_parallelism().map_or(1, |c| c.get());
    take_in_turn(items, cores, |it| {
        let u = {
            let _one = OneFitThread::new();
            f(it)
        };
        done();
        u
    })
}

/// [`set_fit_threads`]`(1)` on this thread while it lives; the setting before it back when it
/// drops (also when `f` panics, so a caller that catches the panic keeps its own setting).
struct OneFitThread(usize);

impl OneFitThread {
    fn new() -> Self {
        OneFitThread(INNER_THREADS.with(|c| c.replace(1)))
    }
}

impl Drop for OneFitThread {
    fn drop(&mut self) {
        INNER_THREADS.with(|c| c.set(self.0));
    }
}

/// `items.map(f)` in order, spread over up to [`fit_threads`] threads: items of unequal cost (the
/// drift search's filters, the Jacobian's columns) keep every thread busy to the end. Each item
/// is computed exactly as it would be serially.
pub(crate) fn par_map<T: Sync, U: Send>(items: &[T], f: impl Fn(&T) -> U + Sync) -> Vec<U> {
    take_in_turn(items, fit_threads(), f)
}

/// The one runner behind [`map_on_every_core`] and [`par_map`]: `items.map(f)` in input order on
/// up to `threads` scoped threads, the calling thread one of them, each taking the next item as it
/// finishes one. A panic in `f` is passed on to the caller.
fn take_in_turn<T: Sync, U: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> U + Sync,
) -> Vec<U> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let threads = threads.min(items.len());
    if threads <= 1 {
        return items.iter().map(f).collect();
    }
    let next = AtomicUsize::new(0);
    let work = || {
        let mut mine: Vec<(usize, U)> = Vec::new();
        loop {
            let i = next.fetch_add(1, Ordering::Relaxed);
            let Some(it) = items.get(i) else {
                return mine;
            };
            mine.push((i, f(it)));
        }
    };
    let mut all: Vec<(usize, U)> = std::thread::scope(|s| {
        let handles: Vec<_> = (1..threads).map(|_| s.spawn(work)).collect();
        let mut all = work();
        for h in handles {
            match h.join() {
                Ok(v) => all.extend(v),
                Err(e) => std::panic::resume_unwind(e),
            }
        }
        all
    });
    all.sort_unstable_by_key(|(i, _)| *i);
    all.into_iter().map(|(_, u)| u).collect()
}

/// One forward-difference column of a Jacobian at `p` (`res = r(p)`), step `h`; the backward
/// difference where the forward point cannot be evaluated; `None` if neither can (or a residual
/// vector of another length comes back).
pub(crate) fn difference_column(
    r: &(impl Fn(&[f64]) -> Option<Vec<f64>> + ?Sized),
    p: &[f64],
    res: &[f64],
    j: usize,
    h: f64,
) -> Option<Vec<f64>> {
    let mut q = p.to_vec();
    q[j] += h;
    match r(&q).filter(|v| v.len() == res.len()) {
        Some(rq) => Some(rq.iter().zip(res).map(|(a, b)| (a - b) / h).collect()),
        None => {
            q[j] = p[j] - h;
            let rq = r(&q).filter(|v| v.len() == res.len())?;
            Some(rq.iter().zip(res).map(|(a, b)| (b - a) / h).collect())
        }
    }
}
