//! How far a fitted constant can be trusted: standard errors that account for correlated residuals,
//! and the noise floor of a record.
//!
//! The residuals of an envelope fit are not independent: the Mark & Crandall envelope of a real record
//! carries a slow ripple, the simulation starts from one noisy sample (its error is the same for the
//! whole run), and any small misfit of the law is a smooth curve. The textbook covariance
//! `s² (JᵀJ)⁻¹` assumes independent residuals and then claims far more precision than the data hold.
//! Here the covariance is the heteroscedasticity-and-autocorrelation-consistent (HAC) *sandwich*
//! `(JᵀJ)⁻¹ S (JᵀJ)⁻¹`, `S = Σ_l w_l Σ_i (J_i r_i)(J_{i+l} r_{i+l})ᵀ` with Bartlett weights
//! `w_l = 1 − |l|/(L+1)` (Newey & West 1987), whose bandwidth `L` follows the residuals' own
//! correlation (Andrews 1991, AR(1) plug-in). For independent residuals it reduces to the textbook
//! formula; for correlated ones it grows by the long-run variance ratio, which is also reported as an
//! *effective sample count* `n_eff = n / (1 + 2 Σ_l w_l ρ_l)`.
//!
//! The *noise floor* is the measurement noise of a signal, estimated without any model from its
//! third differences at the full sampling rate: for white noise of standard deviation σ,
//! `Var(a_{i+2} − 3 a_{i+1} + 3 a_i − a_{i−1}) = 20 σ²`, while a smooth signal sampled 60 times per
//! cycle or more contributes `(2π/60)³ ≈ 10⁻³` of its amplitude at most. A median absolute deviation makes it robust to the velocity reversals
//! and stick events (kinks in the envelope).

/// Columns of a Jacobian: `jac[j][i] = ∂r_i/∂p_j`.
pub type Jacobian = Vec<Vec<f64>>;

/// Forward-difference Jacobian of `r` at `p` (`r0 = r(p)`), step `rel_step · max(|p_j|, scale_j)`;
/// the backward difference where the forward point cannot be evaluated. `None` if neither can.
pub fn jacobian(
    mut r: impl FnMut(&[f64]) -> Option<Vec<f64>>,
    p: &[f64],
    r0: &[f64],
    rel_step: f64,
    scales: &[f64],
) -> Option<Jacobian> {
    let mut jac = Vec::with_capacity(p.len());
    for j in 0..p.len() {
        let scale = scales.get(j).copied().unwrap_or(1e-4);
        let h = rel_step * p[j].abs().max(scale);
        let mut q = p.to_vec();
        q[j] += h;
        let col: Vec<f64> = match r(&q).filter(|v| v.len() == r0.len()) {
            Some(rq) => rq.iter().zip(r0).map(|(a, b)| (a - b) / h).collect(),
            None => {
                q[j] = p[j] - h;
                let rq = r(&q).filter(|v| v.len() == r0.len())?;
                rq.iter().zip(r0).map(|(a, b)| (b - a) / h).collect()
            }
        };
        jac.push(col);
    }
    Some(jac)
}

/// [`jacobian`] with its columns computed on several threads
/// ([`crate::identify::set_fit_threads`]); the same numbers as the serial one.
pub fn jacobian_par(
    r: impl Fn(&[f64]) -> Option<Vec<f64>> + Sync,
    p: &[f64],
    r0: &[f64],
    rel_step: f64,
    scales: &[f64],
) -> Option<Jacobian> {
    let cols: Vec<usize> = (0..p.len()).collect();
    crate::identify::par_map(&cols, |&j| {
        let scale = scales.get(j).copied().unwrap_or(1e-4);
        let h = rel_step * p[j].abs().max(scale);
        crate::identify::difference_column(&r, p, r0, j, h)
    })
    .into_iter()
    .collect()
}

/// Sample autocorrelation of `r` (about its mean) at lags `0..=max_lag` (`ρ_0 = 1`); all zeros
/// after the first for a constant series.
pub fn autocorrelation(r: &[f64], max_lag: usize) -> Vec<f64> {
    let n = r.len();
    let mean = r.iter().sum::<f64>() / n.max(1) as f64;
    let c0: f64 = r.iter().map(|v| (v - mean).powi(2)).sum();
    (0..=max_lag.min(n.saturating_sub(1)))
        .map(|l| {
            if l == 0 {
                1.0
            } else if c0 > 0.0 {
                (0..n - l)
                    .map(|i| (r[i] - mean) * (r[i + l] - mean))
                    .sum::<f64>()
                    / c0
            } else {
                0.0
            }
        })
        .collect()
}

/// Bartlett bandwidth for a series of `n` values with lag-1 autocorrelation `rho`: Andrews' AR(1)
/// plug-in `1.1447 (α n)^{1/3}`, `α = 4ρ² / ((1 − ρ)² (1 + ρ)²)`, at most `n / 4`.
pub fn bandwidth(n: usize, rho: f64) -> usize {
    let rho = rho.clamp(-0.97, 0.97);
    let alpha = 4.0 * rho * rho / ((1.0 - rho).powi(2) * (1.0 + rho).powi(2));
    let l = 1.1447 * (alpha * n as f64).cbrt();
    (l.ceil() as usize).min(n / 4)
}

/// Effective number of independent values of the series `r`: `n / (1 + 2 Σ_{l=1}^{L} w_l ρ_l)`
/// with Bartlett weights and [`bandwidth`]; at most `n` and at least 1.
pub fn effective_count(r: &[f64]) -> f64 {
    let n = r.len();
    if n < 3 {
        return n as f64;
    }
    let rho1 = autocorrelation(r, 1)[1];
    let l = bandwidth(n, rho1);
    let acf = autocorrelation(r, l);
    let lrv: f64 = 1.0
        + 2.0
            * (1..=l)
                .map(|k| (1.0 - k as f64 / (l + 1) as f64) * acf[k])
                .sum::<f64>();
    (n as f64 / lrv.max(1.0)).clamp(1.0, n as f64)
}

/// Covariance of least-squares parameters with residuals `r` and Jacobian `jac` (columns) at the
/// optimum: the HAC sandwich described in the module documentation, with the `n / (n − p)`
/// small-sample factor. `None` if `JᵀJ` is singular or there are no more residuals than parameters.
pub fn hac_covariance(jac: &Jacobian, r: &[f64]) -> Option<Vec<Vec<f64>>> {
    // One block: the whole series.
    hac_covariance_blocks(jac, r, std::slice::from_ref(&(0..r.len())))
}

/// The textbook covariance `s² (JᵀJ)⁻¹`, `s² = Σr² / (n − p)` (independent residuals).
pub fn iid_covariance(jac: &Jacobian, r: &[f64]) -> Option<Vec<Vec<f64>>> {
    let p = jac.len();
    let n = r.len();
    if p == 0 || n <= p {
        return None;
    }
    let mut jtj = vec![vec![0.0; p]; p];
    for a in 0..p {
        for b in 0..p {
            jtj[a][b] = jac[a].iter().zip(&jac[b]).map(|(x, y)| x * y).sum();
        }
    }
    let s2 = r.iter().map(|v| v * v).sum::<f64>() / (n - p) as f64;
    let mut c = invert(&jtj)?;
    c.iter_mut().flatten().for_each(|v| *v *= s2);
    Some(c)
}

/// Standard errors: square roots of the covariance's diagonal.
pub fn standard_errors(cov: &[Vec<f64>]) -> Vec<f64> {
    cov.iter()
        .enumerate()
        .map(|(i, row)| row[i].max(0.0).sqrt())
        .collect()
}

fn matmul(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (n, m, k) = (a.len(), b.first().map_or(0, Vec::len), b.len());
    (0..n)
        .map(|i| {
            (0..m)
                .map(|j| (0..k).map(|t| a[i][t] * b[t][j]).sum())
                .collect()
        })
        .collect()
}

/// Inverse of a small symmetric positive matrix, after scaling it to unit diagonal (the parameters of
/// a friction law differ by orders of magnitude). `None` if singular.
pub fn invert(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let d: Vec<f64> = (0..n).map(|i| a[i][i].abs().sqrt()).collect();
    if d.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return None;
    }
    let mut m: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| a[i][j] / (d[i] * d[j])).collect())
        .collect();
    let mut inv: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    for c in 0..n {
        let piv = (c..n).max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))?;
        if m[piv][c].abs() < 1e-13 {
            return None;
        }
        m.swap(c, piv);
        inv.swap(c, piv);
        let f = 1.0 / m[c][c];
        for k in 0..n {
            m[c][k] *= f;
            inv[c][k] *= f;
        }
        for r in 0..n {
            if r != c {
                let f = m[r][c];
                if f != 0.0 {
                    for k in 0..n {
                        m[r][k] -= f * m[c][k];
                        inv[r][k] -= f * inv[c][k];
                    }
                }
            }
        }
    }
    for (i, row) in inv.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v /= d[i] * d[j];
        }
    }
    Some(inv)
}

/// Noise standard deviation of a uniformly sampled signal from its third differences: the root
/// mean square of `Δ³a / √20`, over the differences within 8 robust standard deviations (1.4826 ×
/// their median absolute deviation) of their median, so that a few spikes or kinks do not count
/// while noise whose level changes along the record (the envelope's noise alternates between the
/// displacement's and the velocity's twice a cycle) is averaged, not under-read as a median would.
/// `None` with fewer than 8 samples.
pub fn noise_sigma(a: &[f64]) -> Option<f64> {
    if a.len() < 8 {
        return None;
    }
    let d3: Vec<f64> = a
        .windows(4)
        .map(|w| w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0])
        .collect();
    let mut tmp = d3.clone();
    let med = median(&mut tmp);
    let mut dev: Vec<f64> = d3.iter().map(|v| (v - med).abs()).collect();
    let robust = 1.4826 * median(&mut dev);
    let kept: Vec<f64> = d3
        .iter()
        .copied()
        .filter(|v| (v - med).abs() <= 8.0 * robust)
        .collect();
    if kept.is_empty() {
        return Some(0.0);
    }
    let ms = kept.iter().map(|v| v * v).sum::<f64>() / kept.len() as f64;
    Some((ms / 20.0).sqrt())
}

/// Median (reorders the slice). 0 for an empty slice.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let k = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    let m = *m;
    if v.len() % 2 == 1 {
        m
    } else {
        let lo = v[..k].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        0.5 * (lo + m)
    }
}

/// [`hac_covariance`] for residuals made of independent blocks (channels): the HAC "meat" is summed
/// block by block (each with its own bandwidth), with no correlation across blocks. `blocks` are
/// ranges of `r` (and of each Jacobian column) that cover it.
pub fn hac_covariance_blocks(
    jac: &Jacobian,
    r: &[f64],
    blocks: &[std::ops::Range<usize>],
) -> Option<Vec<Vec<f64>>> {
    let p = jac.len();
    let n = r.len();
    if p == 0 || n <= p || jac.iter().any(|c| c.len() != n) {
        return None;
    }
    let mut jtj = vec![vec![0.0; p]; p];
    for a in 0..p {
        for b in 0..p {
            jtj[a][b] = jac[a].iter().zip(&jac[b]).map(|(x, y)| x * y).sum();
        }
    }
    let bread = invert(&jtj)?;
    let mut meat = vec![vec![0.0; p]; p];
    for blk in blocks {
        let rb = &r[blk.clone()];
        let m = rb.len();
        if m == 0 {
            continue;
        }
        let g: Vec<Vec<f64>> = (0..p)
            .map(|a| {
                jac[a][blk.clone()]
                    .iter()
                    .zip(rb)
                    .map(|(j, e)| j * e)
                    .collect()
            })
            .collect();
        let rho1 = autocorrelation(rb, 1).get(1).copied().unwrap_or(0.0);
        let l = bandwidth(m, rho1);
        for lag in 0..=l.min(m - 1) {
            let w = 1.0 - lag as f64 / (l + 1) as f64;
            for a in 0..p {
                for b in 0..p {
                    let s: f64 = (0..m - lag).map(|i| g[a][i] * g[b][i + lag]).sum();
                    if lag == 0 {
                        meat[a][b] += s;
                    } else {
                        meat[a][b] += w * s;
                        meat[b][a] += w * s;
                    }
                }
            }
        }
    }
    let dof = n as f64 / (n - p) as f64;
    let mut cov = matmul(&matmul(&bread, &meat), &bread);
    cov.iter_mut().flatten().for_each(|v| *v *= dof);
    cov.iter().flatten().all(|v| v.is_finite()).then_some(cov)
}

/// Quantile of the standard normal distribution (Acklam's rational approximation, relative error
/// below 1.2e-9), for `0 < p < 1`.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e1,
        2.209460984245205e2,
        -2.759285104469687e2,
        1.38357751867269e2,
        -3.066479806614716e1,
        2.506628277459239,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e1,
        1.615858368580409e2,
        -1.556989798598866e2,
        6.680131188771972e1,
        -1.328068155288572e1,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-3,
        -3.223964580411365e-1,
        -2.400758277161838,
        -2.549732539343734,
        4.374664141464968,
        2.938163982698783,
    ];
    const D: [f64; 4] = [
        7.784695709041462e-3,
        3.224671290700398e-1,
        2.445134137142996,
        3.754408661907416,
    ];
    let p = p.clamp(1e-300, 1.0 - 1e-16);
    let lo = 0.02425;
    if p < lo {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - lo {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}

/// The value a χ² variable with `k` degrees of freedom exceeds with probability `alpha`: exact for
/// k = 1 (`z²`, z the normal quantile of `1 − α/2`) and k = 2 (`−2 ln α`), Wilson–Hilferty above.
pub fn chi2_upper_quantile(k: usize, alpha: f64) -> f64 {
    match k {
        0 => 0.0,
        1 => normal_quantile(1.0 - alpha / 2.0).powi(2),
        2 => -2.0 * alpha.ln(),
        _ => {
            let k = k as f64;
            let z = normal_quantile(1.0 - alpha);
            let c = 2.0 / (9.0 * k);
            k * (1.0 - c + z * c.sqrt()).powi(3)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor::Rng;

    #[test]
    fn noise_sigma_reads_white_noise_on_a_smooth_signal() {
        let mut rng = Rng::new(3);
        let a: Vec<f64> = (0..20_000)
            .map(|i| (i as f64 * 0.017).sin() * 2.0 + 0.01 * rng.normal())
            .collect();
        let s = noise_sigma(&a).unwrap();
        assert!((s - 0.01).abs() < 0.0005, "{s}");
        let clean: Vec<f64> = (0..20_000).map(|i| (i as f64 * 0.017).sin()).collect();
        assert!(noise_sigma(&clean).unwrap() < 1e-5);
    }

    #[test]
    fn effective_count_of_white_and_ar1_series() {
        let mut rng = Rng::new(4);
        let white: Vec<f64> = (0..4000).map(|_| rng.normal()).collect();
        let ne = effective_count(&white);
        assert!(ne > 3000.0, "{ne}");
        // AR(1) with ρ = 0.9: long-run variance ratio (1 + ρ)/(1 − ρ) = 19.
        let mut x = 0.0;
        let ar: Vec<f64> = (0..40_000)
            .map(|_| {
                x = 0.9 * x + rng.normal();
                x
            })
            .collect();
        let ne = effective_count(&ar);
        let want = 40_000.0 / 19.0;
        assert!((ne / want - 1.0).abs() < 0.35, "{ne} vs {want}");
    }

    /// A straight line through AR(1) noise: the HAC standard error of the slope matches its spread
    /// over repeats (within 25 %), where the textbook one is several times too small.
    #[test]
    fn hac_standard_error_matches_the_spread_under_correlated_noise() {
        let n = 800;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / n as f64).collect();
        let mut rng = Rng::new(9);
        let (mut slopes, mut hac, mut iid) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..300 {
            let mut x = 0.0;
            let e: Vec<f64> = (0..n)
                .map(|_| {
                    x = 0.8 * x + 0.1 * rng.normal();
                    x
                })
                .collect();
            // OLS of e on [1, t] (true intercept and slope 0).
            let jac = vec![vec![1.0; n], t.clone()];
            let mt = 0.5 * (t[0] + t[n - 1]);
            let me = e.iter().sum::<f64>() / n as f64;
            let sxx: f64 = t.iter().map(|v| (v - mt).powi(2)).sum();
            let b = t
                .iter()
                .zip(&e)
                .map(|(a, y)| (a - mt) * (y - me))
                .sum::<f64>()
                / sxx;
            let a = me - b * mt;
            let r: Vec<f64> = t.iter().zip(&e).map(|(t, y)| a + b * t - y).collect();
            slopes.push(b);
            hac.push(standard_errors(&hac_covariance(&jac, &r).unwrap())[1]);
            iid.push(standard_errors(&iid_covariance(&jac, &r).unwrap())[1]);
        }
        let sd = (slopes.iter().map(|b| b * b).sum::<f64>() / slopes.len() as f64).sqrt();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        assert!(
            (mean(&hac) / sd - 1.0).abs() < 0.25,
            "hac {} sd {sd}",
            mean(&hac)
        );
        assert!(mean(&iid) < 0.5 * sd, "iid {} sd {sd}", mean(&iid));
    }

    #[test]
    fn chi2_quantiles_match_tables() {
        // χ²₁ at 5 % is 3.841, at 0.1 % 10.83; χ²₂ at 1 % 9.210; χ²₃ at 5 % 7.815.
        assert!((chi2_upper_quantile(1, 0.05) - 3.841).abs() < 2e-3);
        assert!((chi2_upper_quantile(1, 1e-3) - 10.828).abs() < 2e-3);
        assert!((chi2_upper_quantile(2, 0.01) - 9.210).abs() < 2e-3);
        // Wilson–Hilferty: within 1 %.
        assert!((chi2_upper_quantile(3, 0.05) - 7.815).abs() < 0.08);
        assert!((normal_quantile(0.975) - 1.959964).abs() < 1e-6);
    }

    #[test]
    fn invert_handles_badly_scaled_matrices() {
        let a = vec![vec![1e-8, 2e-6], vec![2e-6, 1e-3]];
        let inv = invert(&a).unwrap();
        let p = matmul(&a, &inv);
        for (i, row) in p.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-9);
            }
        }
        assert!(invert(&[vec![1.0, 1.0], vec![1.0, 1.0]]).is_none());
    }
}
