//! Which part of a record is the free decay: from the release to where the motion sinks into the
//! noise. Every choice here is derived from the record (its own noise, its own amplitude) and
//! reported ([`MotionSpan`]), so that a fit at a bench's noise compares what a fit on a clean
//! record compares, and says what it assumed.
//!
//! - **Release.** A bench record may start seconds before the release, while the magnet holds the
//!   carriage (displacement steady, velocity at the noise). The release is where the velocity
//!   first leaves the noise for good: `|y'|` above [`SPAN_SIGMAS`] × its noise (and above a
//!   twentieth of its largest value) for a run of samples, which a speckle spike is not; then back
//!   along the sine by `asin(|y'| / A)` to where it left zero.
//! - **End.** After the stop the record holds only the rest position and the noise; near it a
//!   noisy envelope no longer tracks the motion. The comparison stops at the last run of samples
//!   where `|y'|` is above the larger of [`SPAN_SIGMAS`] × the velocity noise and 2·10⁻³ of the
//!   initial amplitude (the resolution of a clean record's stop).

use crate::uncertainty::noise_sigma;
use serde::Serialize;

/// A velocity is "moving" when it is this many noise standard deviations from zero (the chance of
/// Gaussian noise reaching it in a run of [`SPAN_RUN`] samples is below 10⁻²⁵).
pub const SPAN_SIGMAS: f64 = 6.0;

/// Consecutive samples above the threshold that count as motion (a speckle dropout or spike is one
/// to a few samples).
pub const SPAN_RUN: usize = 4;

/// The free-decay part of a record, as found by [`motion_span`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MotionSpan {
    /// First sample compared (the release; 0 when the record starts with it).
    pub start: usize,
    /// One past the last sample compared.
    pub end: usize,
    /// Samples in the record.
    pub samples: usize,
    /// Noise standard deviation of the displacement y (dimensionless), read from the record.
    pub noise_y: f64,
    /// Noise standard deviation of the velocity y' (dimensionless), read from the record.
    pub noise_ydot: f64,
    /// The `|y'|` below which the pin is taken to be at rest (dimensionless).
    pub rest_level: f64,
    /// Samples of the span left out of the comparison as spikes (set by the fit:
    /// [`super::spikes`]).
    pub spikes: usize,
    /// Samples of the span left out at a converter's rail (set by the fit:
    /// [`super::clipped`]).
    pub clipped: usize,
}

impl MotionSpan {
    /// The whole record (for windows of an already delimited record).
    pub fn whole(n: usize) -> MotionSpan {
        MotionSpan {
            start: 0,
            end: n,
            samples: n,
            noise_y: 0.0,
            noise_ydot: 0.0,
            rest_level: 0.0,
            spikes: 0,
            clipped: 0,
        }
    }

    /// Samples held before the release.
    pub fn held(&self) -> usize {
        self.start
    }

    /// Samples after the compared part (at rest, or in the noise).
    pub fn at_rest(&self) -> usize {
        self.samples - self.end
    }

    /// The compared range.
    pub fn range(&self) -> std::ops::Range<usize> {
        self.start..self.end
    }

    /// Variance the noise adds to a Mark & Crandall envelope on average over the phase: the
    /// component of the noise across the state vector, `(σ_y² + σ_y'²)/2`. A noisy envelope reads
    /// `√(A² + this)` on average, not `A`.
    pub fn envelope_bias_var(&self) -> f64 {
        0.5 * (self.noise_y * self.noise_y + self.noise_ydot * self.noise_ydot)
    }
}

/// Index of the last sample of the first (or, with `rev`, the last) run of at least `run`
/// consecutive samples where `hit` holds.
fn run_index(n: usize, run: usize, rev: bool, hit: impl Fn(usize) -> bool) -> Option<usize> {
    let mut count = 0;
    let idx: Box<dyn Iterator<Item = usize>> = if rev {
        Box::new((0..n).rev())
    } else {
        Box::new(0..n)
    };
    let mut first_of_run = 0;
    for i in idx {
        if hit(i) {
            if count == 0 {
                first_of_run = i;
            }
            count += 1;
            if count >= run {
                // Forward: the run's first sample; backward: the run's last (its first seen).
                return Some(if rev { first_of_run } else { i + 1 - run });
            }
        } else {
            count = 0;
        }
    }
    None
}

/// Finds the free decay in dimensionless samples (see the module documentation). Never fails: a
/// record in which nothing leaves the noise spans the whole record (the screening refuses it).
pub fn motion_span(tau: &[f64], y: &[f64], ydot: &[f64]) -> MotionSpan {
    let n = tau.len().min(y.len()).min(ydot.len());
    let (noise_y, noise_ydot) = noise_of(&y[..n], &ydot[..n]);
    if n < 16 {
        return span_from(tau, y, ydot, 0, (noise_y, noise_ydot));
    }
    let vmax = {
        // The largest |y'| not made by a spike: the largest over runs of SPAN_RUN samples of their
        // smallest.
        let mut m = 0.0f64;
        for w in ydot[..n].windows(SPAN_RUN) {
            let lo = w.iter().fold(f64::INFINITY, |a, v| a.min(v.abs()));
            m = m.max(lo);
        }
        m
    };
    let start_level = (SPAN_SIGMAS * noise_ydot).max(0.05 * vmax);
    let dtau = (tau[n - 1] - tau[0]) / (n - 1) as f64;
    let start = match run_index(n, SPAN_RUN, false, |i| ydot[i].abs() > start_level) {
        Some(i) if i > 0 => {
            // Back along the sine to where the velocity left zero: y' ≈ −A sin(τ − τ_r).
            let a = y[i].hypot(ydot[i]).max(1e-300);
            let back = (ydot[i].abs() / a).clamp(0.0, 1.0).asin();
            let k = if dtau > 0.0 {
                (back / dtau).round() as usize
            } else {
                0
            };
            i.saturating_sub(k)
        }
        _ => 0,
    };
    span_from(tau, y, ydot, start, (noise_y, noise_ydot))
}

/// [`motion_span`] with the release at sample `start` (given, not searched).
pub fn motion_span_from(tau: &[f64], y: &[f64], ydot: &[f64], start: usize) -> MotionSpan {
    let n = tau.len().min(y.len()).min(ydot.len());
    span_from(tau, y, ydot, start, noise_of(&y[..n], &ydot[..n]))
}

/// Samples from which the noise of y and of y' are read on two threads.
const NOISE_PAIR_SPLIT: usize = 100_000;

/// [`noise_sigma`] of y and of y' (0 when too short), on two threads for a long record when the
/// fits on this thread may use more than one ([`super::set_fit_threads`]).
fn noise_of(y: &[f64], ydot: &[f64]) -> (f64, f64) {
    let of = |a: &[f64]| noise_sigma(a).unwrap_or(0.0);
    if y.len() < NOISE_PAIR_SPLIT || super::fit_threads() < 2 {
        return (of(y), of(ydot));
    }
    std::thread::scope(|s| {
        let h = s.spawn(|| of(ydot));
        let ny = of(y);
        match h.join() {
            Ok(nv) => (ny, nv),
            Err(e) => std::panic::resume_unwind(e),
        }
    })
}

/// The span from `start` to where the motion sinks into the noise, given the noise of y and y'.
fn span_from(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    start: usize,
    (noise_y, noise_ydot): (f64, f64),
) -> MotionSpan {
    let n = tau.len().min(y.len()).min(ydot.len());
    let start = start.min(n.saturating_sub(1));
    let a_start = if n > 0 {
        y[start].hypot(ydot[start])
    } else {
        0.0
    };
    let rest_level = (SPAN_SIGMAS * noise_ydot).max(2e-3 * a_start);
    let last = run_index(n, SPAN_RUN.min(n - start).max(1), true, |i| {
        i >= start && ydot[i].abs() > rest_level
    })
    .unwrap_or(n.saturating_sub(1));
    MotionSpan {
        start,
        end: (last + 2).clamp((start + 8).min(n), n),
        samples: n,
        noise_y,
        noise_ydot,
        rest_level,
        spikes: 0,
        clipped: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stats::Rng;

    /// A decaying sine from τ = 2, held at y = 2 before, at rest after τ = 40, with noise.
    fn held_record(noise: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut rng = Rng::new(7);
        let dtau = 0.02;
        let n = 3000;
        let (mut t, mut y, mut v) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..n {
            let tau = i as f64 * dtau;
            let (yy, vv) = if tau < 2.0 {
                (2.0, 0.0)
            } else if tau < 40.0 {
                let a = 2.0 * (1.0 - (tau - 2.0) / 40.0);
                (a * (tau - 2.0).cos(), -a * (tau - 2.0).sin())
            } else {
                (0.01, 0.0)
            };
            t.push(tau);
            y.push(yy + noise * rng.normal());
            v.push(vv + noise * rng.normal());
        }
        (t, y, v)
    }

    #[test]
    fn finds_the_release_and_the_rest_at_every_noise_level() {
        for noise in [0.0, 1e-4, 1e-3, 1e-2] {
            let (t, y, v) = held_record(noise);
            let s = motion_span(&t, &y, &v);
            // Release at τ = 2 (sample 100), within a few samples.
            assert!(
                (s.start as i64 - 100).abs() <= 4,
                "noise {noise}: start {}",
                s.start
            );
            // Motion ends before τ = 40 (sample 2000) and is compared at least to τ = 35.
            assert!(
                s.end <= 2002 && s.end >= 1750,
                "noise {noise}: end {}",
                s.end
            );
            if noise > 0.0 {
                assert!((s.noise_ydot / noise - 1.0).abs() < 0.2, "{}", s.noise_ydot);
            }
        }
    }

    #[test]
    fn a_spike_while_held_or_at_rest_is_not_motion() {
        let (t, mut y, mut v) = held_record(1e-3);
        v[30] = 1.5;
        v[31] = -1.5;
        v[2500] = 1.0;
        y[2500] = 1.0;
        let s = motion_span(&t, &y, &v);
        assert!((s.start as i64 - 100).abs() <= 4, "start {}", s.start);
        assert!(s.end <= 2002, "end {}", s.end);
    }

    #[test]
    fn a_record_from_the_release_starts_at_zero() {
        let (t, y, v) = held_record(1e-3);
        let s = motion_span(&t[100..], &y[100..], &v[100..]);
        assert!(s.start <= 2, "{}", s.start);
    }
}
