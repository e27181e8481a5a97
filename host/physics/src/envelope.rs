//! Envelopes of the free response (thesis ch. 3.3) and their closed forms.

use crate::law::{averaging_coefficients, averaging_factor};
use rustfft::{num_complex::Complex, FftPlanner};
use std::f64::consts::PI;

/// Mark & Crandall envelope `A = √(y² + y'²)` (eq. 15), dimensionless.
pub fn mark_crandall(y: &[f64], ydot: &[f64]) -> Vec<f64> {
    y.iter().zip(ydot).map(|(a, b)| a.hypot(*b)).collect()
}

/// Mark & Crandall envelope in SI: `√(x² + (v/Ω)²)` (m).
pub fn mark_crandall_si(x: &[f64], v: &[f64], omega: f64) -> Vec<f64> {
    x.iter().zip(v).map(|(a, b)| a.hypot(b / omega)).collect()
}

/// How a signal is mirrored before the FFT to tame the Hilbert edge effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mirror {
    /// Even reflection (a signal at an extremum, e.g. displacement at release).
    Even,
    /// Odd reflection (a signal crossing zero, e.g. velocity at release).
    Odd,
}

/// Hilbert envelope `|x + i H[x]|` computed by FFT, with the signal mirrored at the start
/// (`start`) and evenly about its last extremum at the end, over a quarter of its length, then
/// cropped (eq. 16–19).
pub fn hilbert_envelope(x: &[f64], start: Mirror) -> Vec<f64> {
    let n = x.len();
    if n < 4 {
        return x.iter().map(|v| v.abs()).collect();
    }
    let p = (n / 4).max(1).min(n - 1);
    let mut ext: Vec<f64> = Vec::with_capacity(n + 2 * p);
    for i in (1..=p).rev() {
        ext.push(match start {
            Mirror::Even => x[i],
            Mirror::Odd => 2.0 * x[0] - x[i],
        });
    }
    ext.extend_from_slice(x);
    // The record ends at an arbitrary phase: continue it by an even reflection about its last
    // extremum, which is smooth, rather than about the last sample.
    let e = (n / 2..n - 1)
        .rev()
        .find(|&i| i >= 1 && (x[i] - x[i - 1]) * (x[i + 1] - x[i]) <= 0.0)
        .unwrap_or(n - 1);
    for j in 1..=p {
        let d = (n - 1 - e) + j;
        ext.push(if d <= e { x[e - d] } else { 0.0 });
    }
    let m = ext.len();
    let mut buf: Vec<Complex<f64>> = ext.iter().map(|&v| Complex::new(v, 0.0)).collect();
    let mut planner = FftPlanner::new();
    planner.plan_fft_forward(m).process(&mut buf);
    // Analytic signal: keep DC (and Nyquist), double positive frequencies, zero negative ones.
    let half = m / 2;
    for (k, c) in buf.iter_mut().enumerate() {
        if k == 0 || (m & 1 == 0 && k == half) {
            continue;
        } else if k < m.div_ceil(2) {
            *c *= 2.0;
        } else {
            *c = Complex::new(0.0, 0.0);
        }
    }
    planner.plan_fft_inverse(m).process(&mut buf);
    buf[p..p + n].iter().map(|c| c.norm() / m as f64).collect()
}

/// Hilbert envelope of the displacement (eq. 16–17).
pub fn hilbert_displacement(y: &[f64]) -> Vec<f64> {
    hilbert_envelope(y, Mirror::Even)
}

/// Hilbert envelope of the velocity (eq. 18–19). In dimensionless units it is an amplitude
/// estimate of y too (y' ≈ A sin).
pub fn hilbert_velocity(ydot: &[f64]) -> Vec<f64> {
    hilbert_envelope(ydot, Mirror::Odd)
}

/// Averaging-method rate `F(A) = Σ a_n Aⁿ` for a pseudo-polynomial law `mu` (eq. 24–30).
pub fn averaging_rate(mu: &[f64], a: f64) -> f64 {
    averaging_coefficients(mu)
        .iter()
        .rev()
        .fold(0.0, |acc, &c| acc * a + c)
}

/// `F'(A)`.
pub fn averaging_rate_derivative(mu: &[f64], a: f64) -> f64 {
    let c = averaging_coefficients(mu);
    (1..c.len())
        .rev()
        .fold(0.0, |acc, n| acc * a + n as f64 * c[n])
}

/// Averaging envelope `A(τ)` from `dA/dτ = F(A)`, `A(τ0) = a0`, at increasing `taus` (RK4 with
/// small sub-steps). Once `A` reaches 0 it stays there (the motion has stopped).
pub fn averaging_envelope(mu: &[f64], a0: f64, taus: &[f64]) -> Vec<f64> {
    let c = averaging_coefficients(mu);
    let f = |a: f64| c.iter().rev().fold(0.0, |acc, &k| acc * a + k);
    let mut out = Vec::with_capacity(taus.len());
    let mut a = a0;
    let mut t = taus.first().copied().unwrap_or(0.0);
    for &tt in taus {
        while t < tt && a > 0.0 {
            let h = (tt - t).min(0.05);
            let k1 = f(a);
            let k2 = f(a + 0.5 * h * k1);
            let k3 = f(a + 0.5 * h * k2);
            let k4 = f(a + h * k3);
            a += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
            t += h;
        }
        t = t.max(tt);
        a = a.max(0.0);
        out.push(a);
    }
    out
}

/// Coulomb envelope `A = Y0 − 2 μ0 τ / π` (eq. 33), floored at 0.
pub fn coulomb_envelope(y0: f64, mu0: f64, tau: f64) -> f64 {
    (y0 - 2.0 * mu0 * tau / PI).max(0.0)
}

/// Viscous envelope `A = Y0 e^{−μ1 τ / 2}` (eq. 36).
pub fn viscous_envelope(y0: f64, mu1: f64, tau: f64) -> f64 {
    y0 * (-mu1 * tau / 2.0).exp()
}

/// Coulomb–viscous envelope `A = (Y0 + 4μ0/(πμ1)) e^{−μ1 τ/2} − 4μ0/(πμ1)` (eq. 38), floored at 0.
pub fn coulomb_viscous_envelope(y0: f64, mu0: f64, mu1: f64, tau: f64) -> f64 {
    if mu1 == 0.0 {
        return coulomb_envelope(y0, mu0, tau);
    }
    let c = 4.0 * mu0 / (PI * mu1);
    ((y0 + c) * (-mu1 * tau / 2.0).exp() - c).max(0.0)
}

/// Quadratic-law envelope by the sign of `Δ² = a1² − 4 a0 a2` (eq. 44–48), floored at 0.
/// Falls back to [`coulomb_viscous_envelope`] when `μ2 = 0`.
pub fn quadratic_envelope(y0: f64, mu0: f64, mu1: f64, mu2: f64, tau: f64) -> f64 {
    if mu2 == 0.0 {
        return coulomb_viscous_envelope(y0, mu0, mu1, tau);
    }
    let a0 = -mu0 * averaging_factor(0);
    let a1 = -mu1 * averaging_factor(1);
    let a2 = -mu2 * averaging_factor(2);
    let d2 = a1 * a1 - 4.0 * a0 * a2;
    let scale = a1 * a1 + (4.0 * a0 * a2).abs();
    let a = if d2.abs() <= 1e-14 * scale {
        // eq. 45
        let b = y0 + a1 / (2.0 * a2);
        b / (1.0 - a2 * b * tau) - a1 / (2.0 * a2)
    } else if d2 < 0.0 {
        // eq. 44
        let d = (-d2).sqrt();
        let phi = ((2.0 * a2 * y0 + a1) / d).atan();
        d / (2.0 * a2) * (d / 2.0 * tau + phi).tan() - a1 / (2.0 * a2)
    } else {
        // eq. 46–48: A(τ) = (A2 + A1 R e) / (R e + 1), R = −(A2 − A0)/(A0 − A1) … written as the
        // general solution of the logistic-type equation dA/dτ = a2 (A − A1)(A − A2).
        let d = d2.sqrt();
        let r1 = (-a1 - d) / (2.0 * a2);
        let r2 = (-a1 + d) / (2.0 * a2);
        // (A − r2)/(A − r1) = C e^{a2 (r2 − r1) τ}
        let c = (y0 - r2) / (y0 - r1);
        let e = c * (a2 * (r2 - r1) * tau).exp();
        (r2 - r1 * e) / (1.0 - e)
    };
    if a.is_finite() {
        a.max(0.0)
    } else {
        0.0
    }
}

/// Shape of a decaying envelope (thesis Tableau 2): by the sign of `F'(A)` over the amplitudes
/// visited.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// `F'(A) = 0`: linear decay (Coulomb).
    Straight,
    /// `F'(A) < 0`.
    Convex,
    /// `F'(A) > 0`.
    Concave,
    /// `F'(A)` changes sign: only a law of order ≥ 2 can produce it.
    Mixed,
}

impl Shape {
    /// Lower-case name.
    pub fn name(&self) -> &'static str {
        match self {
            Shape::Straight => "straight",
            Shape::Convex => "convex",
            Shape::Concave => "concave",
            Shape::Mixed => "mixed",
        }
    }
}

/// Classifies the envelope shape of a pseudo-polynomial law over amplitudes `[a_lo, a_hi]`:
/// `F'` is sampled on 200 points; values with `|F'| · (a_hi − a_lo) < rel_tol · |F|max` count as 0.
pub fn classify_shape(mu: &[f64], a_lo: f64, a_hi: f64) -> Shape {
    let n = 200;
    let (lo, hi) = (a_lo.min(a_hi).max(0.0), a_hi.max(a_lo));
    let span = (hi - lo).max(1e-12);
    let fmax = (0..=n)
        .map(|i| averaging_rate(mu, lo + span * i as f64 / n as f64).abs())
        .fold(0.0, f64::max)
        .max(1e-300);
    let tol = 1e-3 * fmax / span;
    let (mut pos, mut neg) = (false, false);
    for i in 0..=n {
        let d = averaging_rate_derivative(mu, lo + span * i as f64 / n as f64);
        if d > tol {
            pos = true;
        } else if d < -tol {
            neg = true;
        }
    }
    match (pos, neg) {
        (true, true) => Shape::Mixed,
        (true, false) => Shape::Concave,
        (false, true) => Shape::Convex,
        (false, false) => Shape::Straight,
    }
}

/// Extrema of the displacement: at each velocity sign change between samples, `(τ, |y|)` refined
/// by a parabola through three samples. Reversals closer than `min_sep` in τ to the previous
/// one are ignored (noise near the stop).
pub fn peaks(tau: &[f64], y: &[f64], ydot: &[f64], min_sep: f64) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::new();
    let n = tau.len().min(y.len()).min(ydot.len());
    if n >= 2 && ydot[0] == 0.0 {
        out.push((tau[0], y[0].abs()));
    }
    for i in 1..n {
        let (a, b) = (ydot[i - 1], ydot[i]);
        if (a > 0.0 && b <= 0.0) || (a < 0.0 && b >= 0.0) {
            // Extremum near the sample with the smaller |v|.
            let j = if a.abs() < b.abs() { i - 1 } else { i };
            let (tp, yp) = if j >= 1 && j + 1 < n {
                let (y0, y1, y2) = (y[j - 1], y[j], y[j + 1]);
                let den = y0 - 2.0 * y1 + y2;
                let h = 0.5 * (tau[j + 1] - tau[j - 1]);
                if den.abs() > 0.0 {
                    let d = (0.5 * (y0 - y2) / den).clamp(-1.0, 1.0);
                    (tau[j] + d * h, y1 - 0.25 * (y0 - y2) * d)
                } else {
                    (tau[j], y1)
                }
            } else {
                (tau[j], y[j])
            };
            if let Some(last) = out.last() {
                if tp - last.0 < min_sep {
                    continue;
                }
            }
            out.push((tp, yp.abs()));
        }
    }
    out
}
