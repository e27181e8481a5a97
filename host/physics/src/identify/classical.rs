//! The classical estimates of the thesis: half-cycle peaks, the decrement method and the averaging
//! method (also the fit's start point).

use super::*;

/// Starting parameters for `spec` from the fast estimators.
pub fn start_point(tau: &[f64], y: &[f64], ydot: &[f64], spec: LawSpec) -> Vec<f64> {
    let pw = spec.powers();
    let mu = estimate_averaging(tau, y, ydot, &pw).unwrap_or_else(|| vec![0.01; pw.len()]);
    match spec {
        LawSpec::LuGre => vec![mu[0].abs().max(1e-3), mu[0].abs().max(1e-3) * 1.2, mu[1]],
        _ => mu,
    }
}

/// Half-cycle peak magnitudes `(τ, |y|)` of dimensionless samples (velocity sign changes at least
/// 1 rad apart).
pub fn half_cycle_peaks(tau: &[f64], y: &[f64], ydot: &[f64]) -> Vec<(f64, f64)> {
    peaks(tau, y, ydot, 1.0)
}

/// Exact half-cycle decrement regression for Coulomb + viscous friction:
/// `X_{n+1} = D X_n − μ0 (1 + D)`, `D = exp(−π ζ / √(1 − ζ²))`, `μ1 = 2ζ`.
/// Returns `(μ0, μ1)`, or `None` with fewer than 3 half cycles.
pub fn estimate_decrement(tau: &[f64], y: &[f64], ydot: &[f64]) -> Option<(f64, f64)> {
    let pk = half_cycle_peaks(tau, y, ydot);
    decrement_from_peaks(&pk.iter().map(|p| p.1).collect::<Vec<_>>())
}

/// [`estimate_decrement`] from successive half-cycle peak magnitudes.
pub fn decrement_from_peaks(x: &[f64]) -> Option<(f64, f64)> {
    if x.len() < 3 {
        return None;
    }
    let (xs, ys) = (&x[..x.len() - 1], &x[1..]);
    let (slope, icpt) = linreg(xs, ys)?;
    let d = slope;
    if !(d > 0.0 && d.is_finite()) {
        return None;
    }
    let mu0 = -icpt / (1.0 + d);
    let l = -d.ln() / std::f64::consts::PI;
    let zeta = l / (1.0 + l * l).sqrt();
    Some((mu0, 2.0 * zeta))
}

/// Averaging-law regression: `dA/dτ` (from successive half-cycle peaks) regressed on `A^j`,
/// `j ∈ powers`, then `μ_j = −a_j / c_j` (eq. 27–28). Returns μ for the listed powers.
pub fn estimate_averaging(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    powers: &[usize],
) -> Option<Vec<f64>> {
    let pk = half_cycle_peaks(tau, y, ydot);
    if pk.len() < powers.len() + 2 {
        return None;
    }
    let mut rows = Vec::new();
    let mut rhs = Vec::new();
    for w in pk.windows(2) {
        let dt = w[1].0 - w[0].0;
        if dt <= 0.0 {
            continue;
        }
        let rate = (w[1].1 - w[0].1) / dt;
        // Midpoint amplitude, averaging A^j over the half cycle.
        let (a, b) = (w[0].1, w[1].1);
        rows.push(
            powers
                .iter()
                .map(|&j| {
                    if (b - a).abs() < 1e-12 {
                        a.powi(j as i32)
                    } else {
                        (b.powi(j as i32 + 1) - a.powi(j as i32 + 1)) / ((j as f64 + 1.0) * (b - a))
                    }
                })
                .collect::<Vec<f64>>(),
        );
        rhs.push(rate);
    }
    let coef = least_squares(&rows, &rhs)?;
    let mut a_full = vec![0.0; powers.iter().max().map_or(0, |m| m + 1)];
    for (i, &j) in powers.iter().enumerate() {
        a_full[j] = coef[i];
    }
    let mu_full = mu_from_averaging(&a_full);
    Some(powers.iter().map(|&j| mu_full[j]).collect())
}
