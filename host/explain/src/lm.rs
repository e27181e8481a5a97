//! Levenberg–Marquardt with per-parameter finite-difference steps.
//!
//! tribo-physics' `levenberg_marquardt` differentiates with a relative step of 1e-7, which is
//! below the resolution of the adaptive integrator and of its stick events on long records with
//! Coulomb friction (a 1e-9 change of μ0 may move the final stop by a half cycle); here the step is
//! `rel_step · max(|p_j|, scale_j)`.

use tribo_physics::identify::solve;

/// Outcome of [`lm`].
#[derive(Debug, Clone, PartialEq)]
pub struct LmOutcome {
    /// Parameters at the minimum.
    pub p: Vec<f64>,
    /// Cost ½ Σ r².
    pub cost: f64,
    /// Iterations.
    pub iterations: usize,
}

/// Minimises ½ Σ r(p)² from `p0`. `scales[j]` is a typical magnitude of parameter `j` (used for
/// the difference step when `p_j` is near 0). `None` if `r(p0)` cannot be evaluated.
pub fn lm(
    mut r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    p0: &[f64],
    scales: &[f64],
    rel_step: f64,
    max_iter: usize,
) -> Option<LmOutcome> {
    let n = p0.len();
    let mut p = p0.to_vec();
    let mut res = r(&p)?;
    let cost = |v: &[f64]| 0.5 * v.iter().map(|x| x * x).sum::<f64>();
    let mut c = cost(&res);
    let mut lambda = 1e-3;
    let mut it = 0;
    while it < max_iter {
        it += 1;
        let mut jac: Vec<Vec<f64>> = Vec::with_capacity(n);
        for j in 0..n {
            let h = rel_step * p[j].abs().max(scales.get(j).copied().unwrap_or(1e-3));
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
            for k in i..n {
                let v: f64 = jac[i].iter().zip(&jac[k]).map(|(a, b)| a * b).sum();
                jtj[i][k] = v;
                jtj[k][i] = v;
            }
        }
        let mut improved = false;
        let mut small = false;
        for _ in 0..12 {
            let mut a = jtj.clone();
            for (i, row) in a.iter_mut().enumerate() {
                row[i] += lambda * jtj[i][i].max(1e-30);
            }
            let Some(step) = solve(a, jtr.iter().map(|v| -v).collect()) else {
                lambda *= 10.0;
                continue;
            };
            let q: Vec<f64> = p.iter().zip(&step).map(|(a, b)| a + b).collect();
            if let Some(rq) = r(&q) {
                let cq = cost(&rq);
                if cq.is_finite() && cq < c {
                    small = (c - cq) < 1e-5 * c;
                    p = q;
                    res = rq;
                    c = cq;
                    lambda = (lambda * 0.2).max(1e-9);
                    improved = true;
                    break;
                }
            }
            lambda *= 10.0;
        }
        if !improved || small {
            break;
        }
    }
    Some(LmOutcome {
        p,
        cost: c,
        iterations: it,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_an_exponential_decay_exactly() {
        let t: Vec<f64> = (0..50).map(|i| i as f64 * 0.1).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.5 * (-0.7 * t).exp()).collect();
        let r = lm(
            |p| {
                Some(
                    t.iter()
                        .zip(&y)
                        .map(|(t, y)| p[0] * (-p[1] * t).exp() - y)
                        .collect(),
                )
            },
            &[1.0, 0.2],
            &[1.0, 0.1],
            1e-6,
            100,
        )
        .unwrap();
        assert!(
            (r.p[0] - 2.5).abs() < 1e-6 && (r.p[1] - 0.7).abs() < 1e-6,
            "{:?}",
            r.p
        );
        assert!(r.cost < 1e-12);
        // An unevaluable start is reported, not a panic.
        assert!(lm(|_| None, &[1.0], &[1.0], 1e-6, 10).is_none());
    }
}
