//! Half-cycle peaks: velocity reversals (zero crossings with hysteresis, interpolated between samples)
//! and the displacement at each reversal, fitted over a symmetric window.
//!
//! A displacement peak is where the velocity changes sign, so reversals are found on the velocity
//! channel, whose offset is captured exactly while the pin is held. The detector is armed only once
//! |v| exceeds a threshold on the new side, so noise around a crossing, or around zero once the pin has
//! stopped, cannot produce spurious reversals.
//!
//! The peak value is fitted by least squares over ±1 rad of phase (`±M` samples) around the reversal
//! with the model `x_k = P − K (1 − cos(ω k Δt))`. Either side of the peak the motion is a harmonic
//! oscillation about a different equilibrium (Coulomb shift ±r) with a slightly different amplitude
//! and some viscous decay: those differences are antisymmetric in `k` and therefore orthogonal to the
//! symmetric regressors, so `P` is unbiased to first order, with about a tenth of the noise of a single
//! sample.
use crate::fit;

/// Largest half-width of the peak window, in samples.
pub const MAX_HALF_WINDOW: usize = 128;
const RING: usize = 2 * MAX_HALF_WINDOW + 1;
/// Half-width of the window in radians of phase.
pub const WINDOW_RAD: f64 = 1.0;

/// A velocity reversal between the previous sample and the current one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reversal {
    /// Where the zero crossing lies between the previous sample (0) and the current one (1).
    pub frac: f32,
    /// Direction of motion before the reversal: +1 (rising, so the peak is a maximum) or −1.
    pub before: i8,
}

/// Velocity zero-crossing detector with arming hysteresis.
#[derive(Clone, Copy, Debug)]
pub struct ReversalDetector {
    threshold: f32,
    sign: i8,
    armed: bool,
    prev: f32,
}

impl ReversalDetector {
    /// A detector that arms once `|v| > threshold` (same units as the velocities fed to it).
    pub fn new(threshold: f32) -> Self {
        let threshold = if threshold.is_finite() && threshold > 0.0 {
            threshold
        } else {
            f32::MAX
        };
        Self {
            threshold,
            sign: 0,
            armed: false,
            prev: 0.0,
        }
    }

    /// Changes the arming threshold without touching the detector's state (ignored unless finite and
    /// positive). Used once the velocity noise has been measured from the motion itself.
    pub fn set_threshold(&mut self, threshold: f32) {
        if threshold.is_finite() && threshold > 0.0 {
            self.threshold = threshold;
        }
    }

    /// Current arming threshold.
    pub fn threshold(&self) -> f32 {
        self.threshold
    }

    /// Feeds one velocity; returns the reversal if the velocity crossed zero since the previous one.
    pub fn update(&mut self, v: f32) -> Option<Reversal> {
        let prev = self.prev;
        self.prev = v;
        let s = self.sign as f32;
        if self.sign == 0 {
            if v > self.threshold {
                self.sign = 1;
                self.armed = true;
            } else if v < -self.threshold {
                self.sign = -1;
                self.armed = true;
            }
            return None;
        }
        if self.armed && v * s < 0.0 {
            let denom = prev - v;
            let frac = if denom != 0.0 {
                (prev / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let before = self.sign;
            self.sign = -self.sign;
            self.armed = false;
            return Some(Reversal { frac, before });
        }
        if !self.armed && v * s > self.threshold {
            self.armed = true;
        }
        None
    }
}

/// A fitted peak (counts).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeakFit {
    /// The peak, the vertex's offset from the centre sample taken out.
    pub peak: f64,
    /// Its variance from the window's residuals (counts²; NaN when unknown).
    pub variance: f64,
    /// The residual variance of one sample about the fit (counts²; NaN when unknown).
    pub residual_variance: f64,
}

/// Ring of recent displacement counts and the symmetric cosine-window peak fit.
#[derive(Clone, Debug)]
pub struct PeakFitter {
    ring: [u16; RING],
    head: usize,
    len: usize,
    half: usize,
    /// `cos(ω Δt)`, `sin(ω Δt)`: one sample's rotation.
    rot: (f64, f64),
    /// Angular step `ω Δt` the table was built for.
    step: f64,
}

impl Default for PeakFitter {
    fn default() -> Self {
        Self::new()
    }
}

impl PeakFitter {
    /// An empty fitter; call [`PeakFitter::set_step`] before fitting.
    pub fn new() -> Self {
        Self {
            ring: [0; RING],
            head: 0,
            len: 0,
            half: 0,
            rot: (1.0, 0.0),
            step: 0.0,
        }
    }

    /// Forgets the stored samples.
    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
    }

    /// As new, in place: no samples, no window until the next [`PeakFitter::set_step`] (which then
    /// rebuilds the table whatever the step).
    pub fn reset(&mut self) {
        self.clear();
        self.half = 0;
        self.rot = (1.0, 0.0);
        self.step = 0.0;
    }

    /// Sets the phase advance per sample `ω Δt` (radians), which fixes the window (±1 rad, at most
    /// [`MAX_HALF_WINDOW`] samples, at least 1) and the regressor table. Only rebuilds the table
    /// when the step changed by more than 0.1 %.
    pub fn set_step(&mut self, step: f64) {
        if !(step.is_finite() && step > 0.0) {
            return;
        }
        if self.step > 0.0 && ((step - self.step) / self.step).abs() < 1e-3 {
            return;
        }
        self.step = step;
        let half = (WINDOW_RAD / step).clamp(1.0, MAX_HALF_WINDOW as f64) as usize;
        self.half = half;
        self.rot = (fit::cos(step), fit::sin(step));
    }

    /// Half-width of the window in samples (0 before [`PeakFitter::set_step`]).
    pub fn half_window(&self) -> usize {
        self.half
    }

    /// Stores the newest displacement count.
    pub fn push(&mut self, count: u16) {
        if let Some(slot) = self.ring.get_mut(self.head) {
            *slot = count;
        }
        self.head += 1;
        if self.head == RING {
            self.head = 0;
        }
        self.len = (self.len + 1).min(RING);
    }

    /// Count `age` samples before the newest (0 = newest).
    fn at(&self, age: usize) -> Option<u16> {
        if age >= self.len {
            return None;
        }
        self.ring.get((self.head + RING - 1 - age) % RING).copied()
    }

    /// Fitted peak count at the sample `half_window()` samples before the newest (see
    /// [`PeakFitter::fit`]), for a vertex exactly on that sample.
    pub fn fit_centre(&self) -> Option<f64> {
        self.fit(0.0).map(|f| f.peak)
    }

    /// Normal equations of the peak model over the window (see [`PeakFitter::fit`]), counts
    /// relative to `centre`, for a vertex `d` samples after the centre sample and a decay `a` a
    /// radian: the three linear regressors (1, `1 − f` before and after the vertex), and with
    /// `lin = Some([P, −K_before, −K_after])` the model's derivatives in `a` and `d` (for a
    /// Gauss–Newton step in them, and the covariance with them); without, those rows and columns
    /// are the identity's. Also Σy².
    fn normal(&self, centre: f64, d: f64, a: f64, lin: Option<[f64; 3]>) -> Normal {
        let half = self.half;
        let h = self.step;
        // θ of the newest sample (k = half after the centre), then one sample back at a time;
        // e^{−aθ} likewise (× e^{a h} a step back).
        let mut theta = (half as f64 - d) * h;
        let (mut c, mut sn) = (fit::cos(theta), fit::sin(theta));
        let mut decay = fit::exp(-a * theta);
        let back = fit::exp(a * h);
        let (c1, s1) = self.rot;
        let mut m = [[0.0f64; 5]; 5];
        let mut b = [0.0f64; 5];
        let mut yy = 0.0f64;
        let (newer, older) = self.ring.split_at(self.head.min(RING));
        let window = newer
            .iter()
            .rev()
            .chain(older.iter().rev())
            .take(2 * half + 1);
        let n = if lin.is_some() { 5 } else { 3 };
        for &count in window {
            let y = count as f64 - centre;
            // f = e^{−aθ}(cos θ + a sin θ): the damped arc from its vertex, f(0) = 1, f'(0) = 0
            let f = decay * (c + a * sn);
            let g = 1.0 - f;
            let after = theta > 0.0;
            let (da, dd) = lin.map_or((0.0, 0.0), |p| {
                // the arc's amplitude K either side (the coefficients are −K)
                let k = -(if after { p[2] } else { p[1] });
                // ∂f/∂a = e^{−aθ}(sin θ − θ (cos θ + a sin θ)); ∂f/∂θ = −(1 + a²) e^{−aθ} sin θ
                let df_da = decay * (sn - theta * (c + a * sn));
                let df_dth = -(1.0 + a * a) * decay * sn;
                // x = P − K (1 − f), θ = (k − d)·h
                (k * df_da, -h * k * df_dth)
            });
            let x = [
                1.0,
                if after { 0.0 } else { g },
                if after { g } else { 0.0 },
                da,
                dd,
            ];
            for r in 0..n {
                b[r] += x[r] * y;
                for q in r..n {
                    m[r][q] += x[r] * x[q];
                }
            }
            yy += y * y;
            theta -= h;
            (c, sn) = (c * c1 + sn * s1, sn * c1 - c * s1);
            decay *= back;
        }
        if n == 3 {
            m[3][3] = 1.0;
            m[4][4] = 1.0;
        }
        let upper = m;
        for (r, row) in m.iter_mut().enumerate() {
            for (q, x) in row.iter_mut().enumerate().take(r) {
                *x = upper[q][r];
            }
        }
        Normal { m, b, yy }
    }

    /// The peak of the window centred on the sample `half_window()` samples before the newest, the
    /// motion's vertex lying `delta` samples after that sample (|delta| ≤ ½: the velocity reversal
    /// falls between samples), with its variance. Falls back to the raw centre sample (variance
    /// unknown: NaN) when the window is not full or the fit is degenerate; `None` when nothing is
    /// stored.
    ///
    /// The model is the motion's own either side of the vertex, θ = ω_d (t − t_vertex):
    /// `P − K_before (1 − f(θ))` before it and `P − K_after (1 − f(θ))` after it, with the damped
    /// arc `f = e^{−aθ}(cos θ + a sin θ)` (a damped oscillation about a different equilibrium each
    /// side: the Coulomb shift changes sides at the vertex, and after the last one the pin may
    /// stick, K_after = 0), least squares over ±1 rad, the vertex and the decay `a` fitted with
    /// the three linear constants. A symmetric fit about the
    /// nearest sample (the method before) read a peak off by `0.1 δ ω Δt (K_after − K_before)`
    /// and `K (δ ω Δt)²/2` for a vertex δ samples off the sample: at 2–5 kS/s on a
    /// Coulomb-dominated run 10–25 times the noise of the peak. The residuals, the noise alone
    /// then, give the peak's variance.
    pub fn fit(&self, delta: f64) -> Option<PeakFit> {
        let half = self.half;
        let centre = self
            .at(half)
            .or_else(|| self.at(self.len.checked_sub(1)?))? as f64;
        let raw = PeakFit {
            peak: centre,
            variance: f64::NAN,
            residual_variance: f64::NAN,
        };
        if half == 0 || self.len < 2 * half + 1 {
            return Some(raw);
        }
        let mut d = if delta.is_finite() {
            delta.clamp(-0.5, 0.5)
        } else {
            0.0
        };
        // The vertex: the velocity's zero crossing, interpolated across the kink the Coulomb
        // shift puts in the velocity there (its slope changes by 2r/(x−e)), is off by up to a
        // tenth of a sample, and a kink misplaced by ε reads the peak 0.1 ε ωΔt (K_after −
        // K_before) off: two counts at 5 kS/s. So the vertex is fitted too, from the
        // displacement, with the decay (Gauss–Newton on both, from the crossing and no decay).
        let mut a = 0.0f64;
        for _ in 0..3 {
            let lin = self.linear(centre, d, a)?;
            let nq = self.normal(centre, d, a, Some(lin));
            let Some(step) = fit::solve(nq.m, nq.b) else {
                return Some(raw);
            };
            a = (a + step[3]).clamp(-0.2, 0.2);
            d = (d + step[4]).clamp(-1.5, 1.5);
        }
        let Some(lin) = self.linear(centre, d, a) else {
            return Some(raw);
        };
        let Normal { m, b, yy } = self.normal(centre, d, a, Some(lin));
        let Some(coef) = fit::solve(m, b) else {
            return Some(raw);
        };
        let mut e0 = [0.0f64; 5];
        e0[0] = 1.0;
        let Some(inv0) = fit::solve(m, e0) else {
            return Some(raw);
        };
        let explained: f64 = coef.iter().zip(&b).map(|(c, b)| c * b).sum();
        let dof = (2 * half + 1) as f64 - 5.0;
        let residual_variance = if dof >= 1.0 {
            (yy - explained).max(0.0) / dof
        } else {
            f64::NAN
        };
        Some(PeakFit {
            peak: centre + coef[0],
            variance: residual_variance * inv0[0],
            residual_variance,
        })
    }

    /// The linear coefficients (P, −K_before, −K_after) for a given vertex and decay.
    fn linear(&self, centre: f64, d: f64, a: f64) -> Option<[f64; 3]> {
        let nq = self.normal(centre, d, a, None);
        let c = fit::solve(nq.m, nq.b)?;
        Some([c[0], c[1], c[2]])
    }
}

/// Normal equations `m x = b` of the peak model, and Σy².
struct Normal {
    m: [[f64; 5]; 5],
    b: [f64; 5],
    yy: f64,
}
