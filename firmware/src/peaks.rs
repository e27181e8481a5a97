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

pub mod arc;

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

/// The newest `N` displacement counts (a ring: `buf[head − 1]` the newest, `len` stored).
#[derive(Clone, Debug)]
pub(crate) struct Counts<const N: usize> {
    pub(crate) buf: [u16; N],
    pub(crate) head: usize,
    pub(crate) len: usize,
}

impl<const N: usize> Counts<N> {
    pub(crate) const fn new() -> Self {
        Self {
            buf: [0; N],
            head: 0,
            len: 0,
        }
    }

    /// Forgets the stored counts.
    pub(crate) fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
    }

    /// Stores the newest count.
    pub(crate) fn push(&mut self, count: u16) {
        if let Some(slot) = self.buf.get_mut(self.head) {
            *slot = count;
        }
        self.head += 1;
        if self.head == N {
            self.head = 0;
        }
        self.len = (self.len + 1).min(N);
    }

    /// Count `age` samples before the newest (0 = newest).
    pub(crate) fn at(&self, age: usize) -> Option<u16> {
        if age >= self.len {
            return None;
        }
        self.buf.get((self.head + N - 1 - age) % N).copied()
    }
}

/// The window's half-width in samples for the phase step `ω Δt`: ±[`WINDOW_RAD`], at most
/// [`MAX_HALF_WINDOW`], at least 1.
pub(crate) fn window_half(step: f64) -> usize {
    (WINDOW_RAD / step).clamp(1.0, MAX_HALF_WINDOW as f64) as usize
}

/// Whether a fitter set for the step `old` must be set again for `new`: `new` is a step (finite,
/// positive) and differs from `old` by 0.1 % or more (or nothing was set).
pub(crate) fn step_changes(old: f64, new: f64) -> bool {
    new.is_finite() && new > 0.0 && !(old > 0.0 && ((new - old) / old).abs() < 1e-3)
}

/// Ring of recent displacement counts and the symmetric cosine-window peak fit.
#[derive(Clone, Debug)]
pub struct PeakFitter {
    counts: Counts<RING>,
    half: usize,
    /// `g_k = 1 − cos(ω k Δt)` for k = 0..=half
    g: [f64; MAX_HALF_WINDOW + 1],
    sg: f64,
    sgg: f64,
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
            counts: Counts::new(),
            half: 0,
            g: [0.0; MAX_HALF_WINDOW + 1],
            sg: 0.0,
            sgg: 0.0,
            step: 0.0,
        }
    }

    /// Forgets the stored samples.
    pub fn clear(&mut self) {
        self.counts.clear();
    }

    /// As new, in place: no samples, no window until the next [`PeakFitter::set_step`] (which then
    /// rebuilds the table whatever the step).
    pub fn reset(&mut self) {
        self.clear();
        self.half = 0;
        self.sg = 0.0;
        self.sgg = 0.0;
        self.step = 0.0;
    }

    /// Sets the phase advance per sample `ω Δt` (radians), which fixes the window (±1 rad, at most
    /// [`MAX_HALF_WINDOW`] samples, at least 1) and the regressor table. Only rebuilds the table
    /// when the step changed by more than 0.1 %.
    pub fn set_step(&mut self, step: f64) {
        if !step_changes(self.step, step) {
            return;
        }
        self.step = step;
        let half = window_half(step);
        self.half = half;
        let (mut sg, mut sgg) = (0.0, 0.0);
        // cos(k·step) by rotating (cos, sin) one step at a time: one series evaluation for the whole
        // table instead of one per entry (this runs at reversals, inside a poll; on the M7 the
        // series per entry cost 10k instructions at 10 kS/s). Accurate to ~1e-14 over the window.
        let (c1, s1) = (fit::cos(step), fit::sin(step));
        let (mut c, mut s) = (1.0f64, 0.0f64);
        for (k, g) in self.g.iter_mut().enumerate() {
            *g = if k <= half { 1.0 - c } else { 0.0 };
            let w = if k == 0 { 1.0 } else { 2.0 };
            sg += w * *g;
            sgg += w * *g * *g;
            (c, s) = (c * c1 - s * s1, s * c1 + c * s1);
        }
        self.sg = sg;
        self.sgg = sgg;
    }

    /// The phase step `ω Δt` the window is cut for (0 before [`PeakFitter::set_step`]).
    pub fn step(&self) -> f64 {
        self.step
    }

    /// Half-width of the window in samples (0 before [`PeakFitter::set_step`]).
    pub fn half_window(&self) -> usize {
        self.half
    }

    /// Stores the newest displacement count.
    pub fn push(&mut self, count: u16) {
        self.counts.push(count);
    }

    /// Count `age` samples before the newest (0 = newest).
    fn at(&self, age: usize) -> Option<u16> {
        self.counts.at(age)
    }

    /// Copies the window about the sample `half_window()` samples before the newest (its
    /// `2·half_window() + 1` counts, oldest first) into `out`; the number copied, 0 when the
    /// window is not full or `out` too short.
    pub fn window(&self, out: &mut [u16]) -> usize {
        let n = 2 * self.half + 1;
        let Counts { buf, head, len } = &self.counts;
        let (head, len) = (*head, *len);
        if self.half == 0 || len < n || out.len() < n {
            return 0;
        }
        // the oldest at `head − n` (wrapping), as two slices of the ring
        let start = (head + RING - n) % RING;
        let first = buf.get(start..(start + n).min(RING)).unwrap_or(&[]);
        let second = buf.get(..n - first.len()).unwrap_or(&[]);
        let (a, b) = out.split_at_mut(first.len());
        a.copy_from_slice(first);
        if let Some(b) = b.get_mut(..second.len()) {
            b.copy_from_slice(second);
        }
        n
    }

    /// Fitted peak count at the sample `half_window()` samples before the newest, i.e. the window's
    /// centre once `half_window()` samples have followed it. Falls back to the raw centre sample when
    /// the window is not full or the fit is degenerate; `None` when nothing is stored.
    pub fn fit_centre(&self) -> Option<f64> {
        let half = self.half;
        let centre = self
            .at(half)
            .or_else(|| self.at(self.counts.len.checked_sub(1)?))? as f64;
        if half == 0 || self.counts.len < 2 * half + 1 {
            return Some(centre);
        }
        let (mut sx, mut sxg) = (0.0, 0.0);
        // Newest to oldest, as `at(age)` for age = 0..=2·half, without an index modulo per sample.
        let (newer, older) = self.counts.buf.split_at(self.counts.head.min(RING));
        let window = newer
            .iter()
            .rev()
            .chain(older.iter().rev())
            .take(2 * half + 1);
        for (age, &c) in window.enumerate() {
            let k = age.abs_diff(half);
            let x = c as f64 - centre;
            let g = self.g.get(k).copied().unwrap_or(0.0);
            sx += x;
            sxg += x * g;
        }
        let n = (2 * half + 1) as f64;
        let det = n * self.sgg - self.sg * self.sg;
        if det.is_nan() || det <= 0.0 {
            return Some(centre);
        }
        let p = (self.sgg * sx - self.sg * sxg) / det;
        Some(centre + p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detector_finds_sign_changes_with_interpolation_and_ignores_noise_at_rest() {
        let mut d = ReversalDetector::new(0.5);
        let mut found = heapless::Vec::<(usize, f32, i8), 8>::new();
        // a sine of period 100 samples, then rest with ±0.3 noise
        for i in 0..400usize {
            let v = if i < 250 {
                (i as f32 * core::f32::consts::TAU / 100.0).sin() * 10.0
            } else if i % 2 == 0 {
                0.3
            } else {
                -0.3
            };
            if let Some(r) = d.update(v) {
                let _ = found.push((i, r.frac, r.before));
            }
        }
        // crossings at 50, 100, 150, 200, 250(start of rest) → the sine crosses at exact multiples of 50
        assert_eq!(found.len(), 5, "{found:?}");
        for (j, &(i, frac, before)) in found.iter().take(4).enumerate() {
            let t = i as f32 - 1.0 + frac;
            assert!((t - 50.0 * (j as f32 + 1.0)).abs() < 0.02, "{t}");
            assert_eq!(before, if j % 2 == 0 { 1 } else { -1 });
        }
    }

    /// The window table equals `1 − cos(k·step)` entry by entry.
    #[test]
    fn window_table_is_one_minus_cosine() {
        for step in [0.0079, 0.017, 0.1, 0.9] {
            let mut f = PeakFitter::new();
            f.set_step(step);
            let half = f.half_window();
            for (k, g) in f.g.iter().enumerate() {
                let want = if k <= half {
                    1.0 - (k as f64 * step).cos()
                } else {
                    0.0
                };
                assert!(
                    (g - want).abs() < 1e-14,
                    "step {step}, k {k}: {g} vs {want}"
                );
            }
        }
    }

    /// The fitted peak of a noiseless asymmetric peak (different curvature and equilibrium either
    /// side, as with Coulomb friction) is the true peak, far closer than the neighbouring samples.
    #[test]
    fn peak_fit_is_unbiased_for_asymmetric_coulomb_peaks() {
        let mut f = PeakFitter::new();
        f.set_step(ASYMMETRIC_STEP);
        assert_eq!(f.half_window(), 100);
        asymmetric_coulomb_peak().for_each(|c| f.push(c));
        let p = f.fit_centre().unwrap();
        assert!((p - ASYMMETRIC_PEAK).abs() < 0.1, "{p}");
    }

    /// Phase step and peak (counts) of [`asymmetric_coulomb_peak`].
    pub(crate) const ASYMMETRIC_STEP: f64 = 0.01;
    pub(crate) const ASYMMETRIC_PEAK: f64 = 40000.25;

    /// A noiseless peak with a different curvature and equilibrium either side (as with Coulomb
    /// friction), a 0.4-count ripple of odd symmetry on it, rounded to counts: its vertex is the
    /// `half_window()`-th sample before the last at [`ASYMMETRIC_STEP`] (100 samples of ±1 rad).
    pub(crate) fn asymmetric_coulomb_peak() -> impl Iterator<Item = u16> {
        let (r1, r2) = (20000.0, 19000.0);
        (-150i32..=100).map(move |k| {
            let g = 1.0 - (k as f64 * ASYMMETRIC_STEP).cos();
            let x = if k < 0 {
                ASYMMETRIC_PEAK - r1 * g
            } else {
                ASYMMETRIC_PEAK - r2 * g
            };
            let x = x + 0.4 * (k as f64 * 0.37).sin();
            x.round().clamp(0.0, 65535.0) as u16
        })
    }
}
