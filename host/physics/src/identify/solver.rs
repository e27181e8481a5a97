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
    mut r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
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
        // Jacobian.
        let mut jac: Vec<Vec<f64>> = Vec::with_capacity(n);
        for j in 0..n {
            let scale = opts.scales.get(j).copied().unwrap_or(1e-4);
            let h = opts.rel_step * p[j].abs().max(scale);
            let mut q = p.clone();
            q[j] += h;
            let col = match r(&q) {
                Some(rq) => rq.iter().zip(&res).map(|(a, b)| (a - b) / h).collect(),
                None => {
                    q[j] = p[j] - h;
                    let rq = r(&q)?;
                    rq.iter().zip(&res).map(|(a, b)| (b - a) / h).collect()
                }
            };
            jac.push(col);
        }
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
    })
}
