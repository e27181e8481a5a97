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

/// Exponential; `NaN` for `NaN`, 0 below −708, `inf` above 709.
pub fn exp(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    if x > 709.0 {
        return f64::INFINITY;
    }
    if x < -708.0 {
        return 0.0;
    }
    const LN2: f64 = core::f64::consts::LN_2;
    // x = k ln2 + r, |r| ≤ ln2/2: the series in r converges by a factor ≥ 2.9 per term.
    let kf = x / LN2;
    let k = if kf >= 0.0 { kf + 0.5 } else { kf - 0.5 } as i64;
    // ln 2 in two parts (fdlibm's): k·LN2_HI is exact, so r keeps its precision at any k
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    let r = (x - k as f64 * LN2_HI) - k as f64 * LN2_LO;
    let (mut term, mut sum) = (1.0f64, 1.0f64);
    for n in 1..20 {
        term *= r / n as f64;
        sum += term;
    }
    sum * f64::from_bits(((k + 1023) as u64) << 52)
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

/// Solves the N×N system `a x = b` (Gaussian elimination with partial pivoting); `None` when `a`
/// is singular to working precision or anything is not finite.
pub fn solve<const N: usize>(a: [[f64; N]; N], b: [f64; N]) -> Option<[f64; N]> {
    solve_many(a, [b]).map(|[x]| x)
}

/// Solves `a x = b` for each of `R` right-hand sides with one elimination (see [`solve`]).
pub fn solve_many<const N: usize, const R: usize>(
    mut a: [[f64; N]; N],
    mut b: [[f64; N]; R],
) -> Option<[[f64; N]; R]> {
    let scale = a
        .iter()
        .flat_map(|r| r.iter())
        .fold(0.0f64, |m, v| m.max(v.abs()));
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    for col in 0..N {
        let mut piv = col;
        for r in col + 1..N {
            if a[r][col].abs() > a[piv][col].abs() {
                piv = r;
            }
        }
        if a[piv][col].abs() <= 1e-13 * scale || a[piv][col].is_nan() {
            return None;
        }
        a.swap(col, piv);
        for rhs in b.iter_mut() {
            rhs.swap(col, piv);
        }
        let (top, rest) = a.split_at_mut(col + 1);
        let pivot_row = &top[col];
        for (r, row) in rest.iter_mut().enumerate() {
            let f = row[col] / pivot_row[col];
            for (x, p) in row.iter_mut().zip(pivot_row.iter()).skip(col) {
                *x -= f * p;
            }
            for rhs in b.iter_mut() {
                rhs[col + 1 + r] -= f * rhs[col];
            }
        }
    }
    let mut out = [[0.0f64; N]; R];
    for (x, rhs) in out.iter_mut().zip(b.iter()) {
        for r in (0..N).rev() {
            let mut v = rhs[r];
            for q in r + 1..N {
                v -= a[r][q] * x[q];
            }
            x[r] = v / a[r][r];
        }
    }
    out.iter()
        .flat_map(|x| x.iter())
        .all(|v| v.is_finite())
        .then_some(out)
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
    /// Serial structure of the centred regressors (rows in the order fed, unit weights):
    /// `Σ d_i d_i'`, `Σ d_i d_{i+1}'`, `Σ d_i d_{i+2}'`, `d_0 + d_{n−1}` and `d_1 + d_{n−2}`.
    serial: Serial<P>,
}

/// Sums of the centred regressors that the covariance of a fit with serially correlated
/// residuals needs ([`Ols::var_of_correlated`]).
#[derive(Clone, Copy, Debug)]
struct Serial<const P: usize> {
    s0: [[f64; P]; P],
    s1: [[f64; P]; P],
    s2: [[f64; P]; P],
    e1: [f64; P],
    e2: [f64; P],
    /// Σ r_i², Σ r_i r_{i+1}, Σ r_i r_{i+2} of the residuals.
    r0: f64,
    r1: f64,
    r2: f64,
}

impl<const P: usize> Serial<P> {
    const fn new() -> Self {
        Serial {
            s0: [[0.0; P]; P],
            s1: [[0.0; P]; P],
            s2: [[0.0; P]; P],
            e1: [0.0; P],
            e2: [0.0; P],
            r0: 0.0,
            r1: 0.0,
            r2: 0.0,
        }
    }
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

    /// Variance of the linear combination `Σ g_i p_i` of the parameters (0 = intercept) when the
    /// residuals of neighbouring rows are correlated: `rho[0]` between rows one apart, `rho[1]`
    /// two apart, none further (rows in the order fed, unit weights). The sandwich
    /// `σ² (X'X)⁻¹ X'ΩX (X'X)⁻¹`; with `rho = [0, 0]` it is [`Ols::var_of`].
    ///
    /// A regression whose rows share a measurement — the decrement's (each peak in two rows: the
    /// residual `ε_{n+1} − D ε_n`, `ρ1 = −D/(1+D²)`), the averaging's (each amplitude in the
    /// central differences of two rows, `ρ2 ≈ −½`) — has residuals that nearly cancel along the
    /// run, and the textbook ± ([`Ols::var_of`]) overstated its error 1.5 to 10 times.
    pub fn var_of_correlated(&self, grad: &[f64], rho: [f64; 2]) -> f64 {
        let n = self.n as f64;
        let ser = &self.serial;
        let g = |i: usize| grad.get(i).copied().unwrap_or(0.0);
        // In the centred parameters (m = the mean of y, c): b = m − c·x̄.
        let gm = g(0);
        let mut gc = [0.0f64; P];
        for (k, v) in gc.iter_mut().enumerate() {
            *v = g(k + 1) - gm * self.mean_x.get(k).copied().unwrap_or(0.0);
        }
        // u = (Σ d d')⁻¹ g_c, a = g_m / n
        let mut u = [0.0f64; P];
        for (ui, row) in u.iter_mut().zip(self.inv.iter()) {
            *ui = row.iter().zip(gc.iter()).map(|(a, b)| a * b).sum();
        }
        let a = gm / n;
        let m00 = n + 2.0 * rho[0] * (n - 1.0).max(0.0) + 2.0 * rho[1] * (n - 2.0).max(0.0);
        let mut um0 = 0.0;
        let mut umu = 0.0;
        for i in 0..P {
            let ui = u[i];
            let e1 = ser.e1.get(i).copied().unwrap_or(0.0);
            let e2 = ser.e2.get(i).copied().unwrap_or(0.0);
            um0 += ui * (-rho[0] * e1 - rho[1] * (e1 + e2));
            for j in 0..P {
                let at = |m: &[[f64; P]; P], r: usize, c: usize| {
                    m.get(r).and_then(|x| x.get(c)).copied().unwrap_or(0.0)
                };
                let mij = at(&ser.s0, i, j)
                    + rho[0] * (at(&ser.s1, i, j) + at(&ser.s1, j, i))
                    + rho[1] * (at(&ser.s2, i, j) + at(&ser.s2, j, i));
                umu += ui * mij * u.get(j).copied().unwrap_or(0.0);
            }
        }
        self.sigma2 * (a * a * m00 + 2.0 * a * um0 + umu)
    }

    /// The residuals' correlation between rows one and two apart, as measured (`[0, 0]` when
    /// the residuals are all zero).
    pub fn residual_correlation(&self) -> [f64; 2] {
        let s = &self.serial;
        if s.r0 > 0.0 && s.r0.is_finite() {
            [s.r1 / s.r0, s.r2 / s.r0]
        } else {
            [0.0, 0.0]
        }
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
    serial: Serial<P>,
    /// Centred regressors of the two previous rows of pass 1 (newest first) and the first two.
    prev: [[f64; P]; 2],
    first: [[f64; P]; 2],
    /// Rows of pass 1 so far.
    k: usize,
    /// The two previous residuals of pass 2 (newest first) and the rows of pass 2 so far.
    res_prev: [f64; 2],
    k2: usize,
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
            serial: Serial::new(),
            prev: [[0.0; P]; 2],
            first: [[0.0; P]; 2],
            k: 0,
            res_prev: [0.0; 2],
            k2: 0,
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
                // The serial structure, unweighted (see `Ols::var_of_correlated`).
                let [p1, p2] = self.prev;
                let ser = &mut self.serial;
                for i in 0..P {
                    let di = d.get(i).copied().unwrap_or(0.0);
                    let (a1, a2) = (
                        p1.get(i).copied().unwrap_or(0.0),
                        p2.get(i).copied().unwrap_or(0.0),
                    );
                    for (j, &dj) in d.iter().enumerate() {
                        if let Some(v) = ser.s0.get_mut(i).and_then(|r| r.get_mut(j)) {
                            *v += di * dj;
                        }
                        if self.k >= 1 {
                            if let Some(v) = ser.s1.get_mut(i).and_then(|r| r.get_mut(j)) {
                                *v += a1 * dj;
                            }
                        }
                        if self.k >= 2 {
                            if let Some(v) = ser.s2.get_mut(i).and_then(|r| r.get_mut(j)) {
                                *v += a2 * dj;
                            }
                        }
                    }
                }
                if let Some(f) = self.first.get_mut(self.k) {
                    *f = d;
                }
                self.prev = [d, p1];
                self.k += 1;
            }
            2 => {
                let pred = self.intercept
                    + self
                        .coef
                        .iter()
                        .zip(x.iter())
                        .map(|(c, xi)| c * xi)
                        .sum::<f64>();
                let r = y - pred;
                self.rss += w * self.wn * r * r;
                // the residuals' own serial correlation (unweighted), rows one and two apart
                let [r1, r2] = self.res_prev;
                if self.k2 >= 1 {
                    self.serial.r1 += r * r1;
                }
                if self.k2 >= 2 {
                    self.serial.r2 += r * r2;
                }
                self.serial.r0 += r * r;
                self.res_prev = [r, r1];
                self.k2 += 1;
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
                // the ends: d_0 + d_{n−1} and d_1 + d_{n−2}
                let [last, before] = self.prev;
                let [f0, f1] = self.first;
                for i in 0..P {
                    let g = |a: &[f64; P]| a.get(i).copied().unwrap_or(0.0);
                    if let Some(e) = self.serial.e1.get_mut(i) {
                        *e = g(&f0) + g(&last);
                    }
                    if let Some(e) = self.serial.e2.get_mut(i) {
                        *e = g(&f1) + g(&before);
                    }
                }
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
                    serial: self.serial,
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

    #[test]
    fn exp_matches_std() {
        for x in [
            -700.0, -20.0, -1.5, -0.3, -1e-9, 0.0, 1e-9, 0.25, 0.3466, 1.0, 7.7, 300.0, 709.0,
        ] {
            let (got, want) = (exp(x), x.exp());
            assert!(((got - want) / want).abs() < 4e-15, "{x}: {got} vs {want}");
        }
        assert!(exp(f64::NAN).is_nan());
    }

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

    /// The sandwich variance for serially correlated residuals against the truth over many
    /// repeats: a straight line through points whose errors are first differences of white noise
    /// (`e_i = η_{i+1} − η_i`: ρ1 = −½) and central differences (`e_i = η_{i+1} − η_{i−1}`:
    /// ρ2 = −½); the textbook variance overstates both slope and intercept there.
    #[test]
    fn correlated_residuals_get_their_own_variance() {
        let mut seed = 0x9E37_79B9_7F4A_7C15u64;
        let mut gauss = || {
            let mut u = || {
                seed ^= seed << 13;
                seed ^= seed >> 7;
                seed ^= seed << 17;
                (seed >> 11) as f64 / (1u64 << 53) as f64
            };
            let (a, b) = (u().max(1e-300), u());
            sqrt(-2.0 * ln(a)) * cos(2.0 * core::f64::consts::PI * b - core::f64::consts::PI)
        };
        for (lag, rho) in [(1usize, [-0.5, 0.0]), (2, [0.0, -0.5])] {
            let n = 60;
            let reps = 2000;
            let (mut sq, mut var_c, mut var_t) = ([0.0f64; 2], [0.0f64; 2], [0.0f64; 2]);
            for _ in 0..reps {
                let eta: [f64; 64] = core::array::from_fn(|_| gauss());
                let rows = (0..n).map(|i| {
                    let x = i as f64 * 0.1 + 3.0;
                    ([x], 1.0 + 2.0 * x + eta[i + lag] - eta[i])
                });
                let f = Ols::<1>::fit(rows).unwrap();
                for (j, (g, truth)) in [([1.0, 0.0], 1.0), ([0.0, 1.0], 2.0)].iter().enumerate() {
                    let est = if j == 0 { f.intercept } else { f.coef[0] };
                    sq[j] += (est - truth) * (est - truth);
                    var_c[j] += f.var_of_correlated(g, rho);
                    var_t[j] += f.var_of(g);
                }
            }
            for j in 0..2 {
                let (actual, said, textbook) = (
                    sq[j] / reps as f64,
                    var_c[j] / reps as f64,
                    var_t[j] / reps as f64,
                );
                let ratio = said / actual;
                assert!(
                    (0.8..1.25).contains(&ratio),
                    "lag {lag}, parameter {j}: said {said:e}, actual {actual:e}"
                );
                assert!(
                    textbook > 2.0 * actual,
                    "lag {lag}, parameter {j}: textbook {textbook:e}"
                );
            }
            let plain = Ols::<1>::fit((0..n).map(|i| ([i as f64], (i * i % 7) as f64))).unwrap();
            let g = [0.3, 1.7];
            assert!(
                (plain.var_of_correlated(&g, [0.0, 0.0]) - plain.var_of(&g)).abs()
                    <= 1e-12 * plain.var_of(&g)
            );
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
