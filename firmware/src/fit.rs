//! Least squares and the little `f64` maths the on-board analysis needs.
//!
//! Everything here is written with `+ − × ÷` and comparisons only (no libm, no platform intrinsic),
//! so the Cortex-M7 (double-precision FPU) and the host compute bit-identical results. These run once
//! per half-cycle or once per run, never per sample, so `f64` costs nothing that matters and keeps the
//! regressions well conditioned (a decrement factor D ≈ 0.998 must be resolved to 1e-5).

/// Square root by Newton's iteration from an exponent-halving first guess.
/// `NaN` for negative or `NaN` input, `0` for `0`, `inf` for `inf`.
pub fn sqrt(x: f64) -> f64 {
    if x.is_nan() || x < 0.0 {
        return f64::NAN;
    }
    if x == 0.0 || x == f64::INFINITY {
        return x;
    }
    // Scale subnormals into the normal range so that the first guess is good.
    let (x_n, scale) = if x < 1e-300 {
        (x * 1e300, 1e-150)
    } else {
        (x, 1.0)
    };
    let mut y = f64::from_bits((x_n.to_bits() >> 1) + 0x1FF8_0000_0000_0000);
    for _ in 0..6 {
        y = 0.5 * (y + x_n / y);
    }
    y * scale
}

/// Natural logarithm; `NaN` for non-positive or `NaN` input, `inf` for `inf`.
pub fn ln(x: f64) -> f64 {
    if x.is_nan() || x <= 0.0 {
        return f64::NAN;
    }
    if x == f64::INFINITY {
        return x;
    }
    const LN2: f64 = core::f64::consts::LN_2;
    // Subnormals are scaled by 1e300 first, compensated at the end.
    let scaled = x < 1e-300;
    let x_n = if scaled { x * 1e300 } else { x };
    let bits = x_n.to_bits();
    let mut exp = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mut m = f64::from_bits((bits & 0x000F_FFFF_FFFF_FFFF) | 0x3FF0_0000_0000_0000);
    if m > core::f64::consts::SQRT_2 {
        m *= 0.5;
        exp += 1;
    }
    // ln m = 2 atanh(u), |u| ≤ 0.1716: the series converges by a factor ≥ 34 per term.
    let u = (m - 1.0) / (m + 1.0);
    let u2 = u * u;
    let mut term = u;
    let mut sum = 0.0;
    let mut k = 1.0;
    for _ in 0..16 {
        sum += term / k;
        term *= u2;
        k += 2.0;
    }
    let mut out = 2.0 * sum + exp as f64 * LN2;
    if scaled {
        out -= 300.0 * core::f64::consts::LN_10;
    }
    out
}

/// Cosine for |φ| ≤ π (Taylor series to full precision); the argument is clamped to that range.
pub fn cos(phi: f64) -> f64 {
    let p = if phi.is_nan() {
        0.0
    } else {
        phi.clamp(-core::f64::consts::PI, core::f64::consts::PI)
    };
    let p2 = p * p;
    let mut term = 1.0;
    let mut sum = 1.0;
    let mut k = 0.0;
    for _ in 0..16 {
        k += 2.0;
        term *= -p2 / ((k - 1.0) * k);
        sum += term;
    }
    sum
}

/// Sine for |φ| ≤ π (Taylor series to full precision); the argument is clamped to that range.
pub fn sin(phi: f64) -> f64 {
    let p = if phi.is_nan() {
        0.0
    } else {
        phi.clamp(-core::f64::consts::PI, core::f64::consts::PI)
    };
    let p2 = p * p;
    let mut term = p;
    let mut sum = p;
    let mut k = 1.0;
    for _ in 0..16 {
        k += 2.0;
        term *= -p2 / ((k - 1.0) * k);
        sum += term;
    }
    sum
}

/// Ordinary least squares `y = b + Σ c_i x_i` with `P` regressors plus an intercept, computed in
/// centred form (two passes over the data) for conditioning.
#[derive(Clone, Copy, Debug)]
pub struct Ols<const P: usize> {
    /// Number of rows used.
    pub n: usize,
    /// Intercept `b`.
    pub intercept: f64,
    /// Slopes `c_i`.
    pub coef: [f64; P],
    mean_x: [f64; P],
    /// Inverse of the centred normal matrix.
    inv: [[f64; P]; P],
    /// Residual variance `RSS / (n − P − 1)`.
    pub sigma2: f64,
}

impl<const P: usize> Ols<P> {
    /// Fits the rows; `None` when there are too few rows, the design is singular, or anything is
    /// not finite.
    pub fn fit<I>(rows: I) -> Option<Self>
    where
        I: Iterator<Item = ([f64; P], f64)> + Clone,
    {
        Self::fit_weighted(rows.map(|(x, y)| (x, y, 1.0)))
    }

    /// Weighted least squares over rows `(x, y, w)`, `w` an inverse variance of any scale
    /// (`sigma2` is then the residual variance of a row of mean weight). Rows with a non-positive
    /// or non-finite weight are ignored.
    pub fn fit_weighted<I>(rows: I) -> Option<Self>
    where
        I: Iterator<Item = ([f64; P], f64, f64)> + Clone,
    {
        let mut passes = OlsPasses::new();
        loop {
            for (x, y, w) in rows.clone() {
                passes.row(x, y, w);
            }
            if let Pass::Done(fit) = passes.end_pass() {
                return fit;
            }
        }
    }

    /// Covariance of parameters `i` and `j`, numbered 0 = intercept, 1.. = slopes.
    pub fn cov(&self, i: usize, j: usize) -> f64 {
        let inv_at = |a: usize, b: usize| {
            self.inv
                .get(a)
                .and_then(|r| r.get(b))
                .copied()
                .unwrap_or(0.0)
        };
        // Σ_k inv[a][k] x̄_k
        let inv_mean = |a: usize| -> f64 {
            (0..P)
                .map(|k| inv_at(a, k) * self.mean_x.get(k).copied().unwrap_or(0.0))
                .sum()
        };
        let c = match (i, j) {
            (0, 0) => {
                let quad: f64 = (0..P)
                    .map(|a| self.mean_x.get(a).copied().unwrap_or(0.0) * inv_mean(a))
                    .sum();
                1.0 / self.n as f64 + quad
            }
            (0, b) | (b, 0) => -inv_mean(b - 1),
            (a, b) => inv_at(a - 1, b - 1),
        };
        c * self.sigma2
    }

    /// Variance of the linear combination `Σ g_i p_i` of the parameters (0 = intercept).
    pub fn var_of(&self, grad: &[f64]) -> f64 {
        let mut v = 0.0;
        for (i, gi) in grad.iter().enumerate() {
            for (j, gj) in grad.iter().enumerate() {
                v += gi * gj * self.cov(i, j);
            }
        }
        v
    }
}

/// What [`OlsPasses::end_pass`] says.
#[derive(Clone, Copy, Debug)]
pub enum Pass<const P: usize> {
    /// Feed the same rows again, in the same order.
    Again,
    /// The fit ([`Ols::fit_weighted`]'s answer).
    Done(Option<Ols<P>>),
}

/// [`Ols::fit_weighted`] one row at a time: the same rows are fed three times (means, centred
/// sums, residuals), each pass closed by [`OlsPasses::end_pass`]. The arithmetic is the very same,
/// so the fit is identical bit for bit; a caller can spread the rows over as many calls as it likes
/// (the end-of-run analysis does, so that no poll of the application runs long).
#[derive(Clone, Copy, Debug)]
pub struct OlsPasses<const P: usize> {
    pass: u8,
    n: usize,
    sw: f64,
    mx: [f64; P],
    my: f64,
    wn: f64,
    sxx: [[f64; P]; P],
    sxy: [f64; P],
    inv: [[f64; P]; P],
    coef: [f64; P],
    intercept: f64,
    rss: f64,
}

impl<const P: usize> Default for OlsPasses<P> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const P: usize> OlsPasses<P> {
    pub const fn new() -> Self {
        OlsPasses {
            pass: 0,
            n: 0,
            sw: 0.0,
            mx: [0.0; P],
            my: 0.0,
            wn: 0.0,
            sxx: [[0.0; P]; P],
            sxy: [0.0; P],
            inv: [[0.0; P]; P],
            coef: [0.0; P],
            intercept: 0.0,
            rss: 0.0,
        }
    }

    /// Which pass is being fed (0, 1, 2; 3 once done).
    pub fn pass(&self) -> u8 {
        self.pass
    }

    /// Feeds one row to the current pass (ignored when its weight is not finite and positive).
    pub fn row(&mut self, x: [f64; P], y: f64, w: f64) {
        if !(w.is_finite() && w > 0.0) {
            return;
        }
        match self.pass {
            0 => {
                self.n += 1;
                self.sw += w;
                for (m, xi) in self.mx.iter_mut().zip(x.iter()) {
                    *m += w * xi;
                }
                self.my += w * y;
            }
            1 => {
                let w = w * self.wn;
                let mut d = [0.0f64; P];
                for ((di, xi), m) in d.iter_mut().zip(x.iter()).zip(self.mx.iter()) {
                    *di = xi - m;
                }
                let dy = y - self.my;
                for (i, row) in self.sxx.iter_mut().enumerate() {
                    let di = w * d.get(i).copied().unwrap_or(0.0);
                    for (s, dj) in row.iter_mut().zip(d.iter()) {
                        *s += di * dj;
                    }
                    if let Some(s) = self.sxy.get_mut(i) {
                        *s += di * dy;
                    }
                }
            }
            2 => {
                let pred = self.intercept
                    + self
                        .coef
                        .iter()
                        .zip(x.iter())
                        .map(|(c, xi)| c * xi)
                        .sum::<f64>();
                self.rss += w * self.wn * (y - pred) * (y - pred);
            }
            _ => {}
        }
    }

    /// Closes the current pass.
    pub fn end_pass(&mut self) -> Pass<P> {
        self.pass = self.pass.saturating_add(1);
        match self.pass {
            1 => {
                if self.n < P + 2 || self.sw.is_nan() || self.sw <= 0.0 {
                    return self.fail();
                }
                for m in self.mx.iter_mut() {
                    *m /= self.sw;
                }
                self.my /= self.sw;
                // weights normalised to a mean of 1
                self.wn = self.n as f64 / self.sw;
                Pass::Again
            }
            2 => {
                let Some(inv) = invert(self.sxx) else {
                    return self.fail();
                };
                self.inv = inv;
                for (c, row) in self.coef.iter_mut().zip(inv.iter()) {
                    *c = row.iter().zip(self.sxy.iter()).map(|(a, b)| a * b).sum();
                }
                self.intercept = self.my
                    - self
                        .coef
                        .iter()
                        .zip(self.mx.iter())
                        .map(|(c, m)| c * m)
                        .sum::<f64>();
                Pass::Again
            }
            3 => {
                let sigma2 = self.rss / (self.n - P - 1) as f64;
                let fit = Ols {
                    n: self.n,
                    intercept: self.intercept,
                    coef: self.coef,
                    mean_x: self.mx,
                    inv: self.inv,
                    sigma2,
                };
                let finite = fit.intercept.is_finite()
                    && sigma2.is_finite()
                    && fit.coef.iter().all(|c| c.is_finite())
                    && fit.inv.iter().flatten().all(|c| c.is_finite());
                Pass::Done(finite.then_some(fit))
            }
            _ => self.fail(),
        }
    }

    fn fail(&mut self) -> Pass<P> {
        self.pass = 3;
        Pass::Done(None)
    }
}

/// Inverse of a small symmetric positive matrix by Gauss–Jordan with partial pivoting; `None` when
/// (numerically) singular.
fn invert<const P: usize>(a: [[f64; P]; P]) -> Option<[[f64; P]; P]> {
    let mut m = a;
    let mut inv = [[0.0f64; P]; P];
    for (i, row) in inv.iter_mut().enumerate() {
        if let Some(d) = row.get_mut(i) {
            *d = 1.0;
        }
    }
    let scale = (0..P)
        .map(|i| {
            a.get(i)
                .and_then(|r| r.get(i))
                .copied()
                .unwrap_or(0.0)
                .abs()
        })
        .fold(0.0, f64::max);
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    for col in 0..P {
        // pivot
        let mut best = col;
        let mut best_val = 0.0;
        for (r, row) in m.iter().enumerate().skip(col) {
            let v = row.get(col).copied().unwrap_or(0.0).abs();
            if v > best_val {
                best_val = v;
                best = r;
            }
        }
        if best_val.is_nan() || best_val <= scale * 1e-14 {
            return None;
        }
        m.swap(col, best);
        inv.swap(col, best);
        let p = m.get(col).and_then(|r| r.get(col)).copied().unwrap_or(1.0);
        if let (Some(mr), Some(ir)) = (m.get_mut(col), inv.get_mut(col)) {
            for v in mr.iter_mut() {
                *v /= p;
            }
            for v in ir.iter_mut() {
                *v /= p;
            }
        }
        let pivot_m = m.get(col).copied().unwrap_or([0.0; P]);
        let pivot_i = inv.get(col).copied().unwrap_or([0.0; P]);
        for r in 0..P {
            if r == col {
                continue;
            }
            let f = m
                .get(r)
                .and_then(|row| row.get(col))
                .copied()
                .unwrap_or(0.0);
            if f == 0.0 {
                continue;
            }
            if let Some(row) = m.get_mut(r) {
                for (v, pv) in row.iter_mut().zip(pivot_m.iter()) {
                    *v -= f * pv;
                }
            }
            if let Some(row) = inv.get_mut(r) {
                for (v, pv) in row.iter_mut().zip(pivot_i.iter()) {
                    *v -= f * pv;
                }
            }
        }
    }
    Some(inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqrt_ln_cos_match_std() {
        for &x in &[1e-310, 1e-200, 3e-7, 0.5, 1.0, 2.0, 0.998, 12345.678, 1e250] {
            let s = sqrt(x);
            assert!(((s - x.sqrt()) / x.sqrt()).abs() < 4e-16, "sqrt {x}: {s}");
            let l = ln(x);
            assert!(
                (l - x.ln()).abs() < 4e-15 * x.ln().abs().max(1.0),
                "ln {x}: {l} vs {}",
                x.ln()
            );
        }
        assert!(
            sqrt(-1.0).is_nan() && ln(0.0).is_nan() && ln(-2.0).is_nan() && sqrt(f64::NAN).is_nan()
        );
        for i in -30..=30 {
            let p = i as f64 * 0.1;
            assert!((cos(p) - p.cos()).abs() < 1e-15, "cos {p}");
            assert!((sin(p) - p.sin()).abs() < 1e-15, "sin {p}");
        }
    }

    #[test]
    fn ols_recovers_a_plane_and_its_covariance_is_sane() {
        // y = 3 - 2 x1 + 0.5 x2 + small deterministic "noise"
        let rows = (0..50).map(|i| {
            let x1 = i as f64 * 0.1;
            let x2 = (i * i % 17) as f64;
            let e = if i % 2 == 0 { 1e-3 } else { -1e-3 };
            ([x1, x2], 3.0 - 2.0 * x1 + 0.5 * x2 + e)
        });
        let f = Ols::<2>::fit(rows).unwrap();
        assert!((f.intercept - 3.0).abs() < 1e-3);
        assert!((f.coef[0] + 2.0).abs() < 1e-3 && (f.coef[1] - 0.5).abs() < 1e-3);
        assert!(f.cov(0, 0) > 0.0 && f.cov(1, 1) > 0.0 && f.cov(2, 2) > 0.0);
        assert!((f.cov(0, 1) - f.cov(1, 0)).abs() < 1e-18);
        assert!(f.sigma2 > 0.9e-6 && f.sigma2 < 1.2e-6);
        // singular design is refused
        let bad = (0..10).map(|i| ([i as f64, 2.0 * i as f64], 1.0));
        assert!(Ols::<2>::fit(bad).is_none());
    }
}
