//! Whether a record can be analysed at all: oscillation, half-cycles, finite samples, saturation
//! (the reasons a fit is refused, [`NotAnalysable`]).

use super::*;

/// Why a record cannot be analysed: no constant is fitted for it.
#[derive(Debug, Clone, PartialEq)]
pub enum NotAnalysable {
    /// A sample is NaN or infinite (`what` says where).
    NonFinite {
        /// The channel and sample (or file, line and column) of the first one.
        what: String,
    },
    /// Nothing oscillates at the rig's natural period above the noise.
    NoOscillation {
        /// What was found instead.
        reason: String,
    },
    /// Too short a decay to fit.
    TooFewHalfCycles {
        /// Half cycles found.
        found: usize,
        /// Half cycles needed ([`MIN_HALF_CYCLES`]).
        need: usize,
    },
    /// A channel stays at its extreme value (the converter's full scale) while the pin moves.
    Saturated {
        /// `displacement` or `velocity`.
        channel: &'static str,
        /// First sample of the flat run.
        sample: usize,
        /// Length of the run (samples).
        samples: usize,
    },
    /// A channel reads one value for every sample: its input is stuck or dead (a converter fault,
    /// not a saturation: nothing moves it).
    Stuck {
        /// `displacement` or `velocity`.
        channel: &'static str,
        /// The value it reads (dimensionless, as screened).
        value: f64,
        /// Samples read.
        samples: usize,
    },
}

impl NotAnalysable {
    /// Short kebab-case name (`non-finite`, `no-oscillation`, `too-few-half-cycles`, `saturated`,
    /// `stuck`).
    pub fn name(&self) -> &'static str {
        match self {
            NotAnalysable::NonFinite { .. } => "non-finite",
            NotAnalysable::NoOscillation { .. } => "no-oscillation",
            NotAnalysable::TooFewHalfCycles { .. } => "too-few-half-cycles",
            NotAnalysable::Saturated { .. } => "saturated",
            NotAnalysable::Stuck { .. } => "stuck",
        }
    }
}

impl std::fmt::Display for NotAnalysable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NotAnalysable::NonFinite { what } => write!(f, "non-finite sample: {what}"),
            NotAnalysable::NoOscillation { reason } => write!(f, "no oscillation: {reason}"),
            NotAnalysable::TooFewHalfCycles { found, need } => write!(
                f,
                "too few half cycles: {found} above the noise, a fit needs at least {need}"
            ),
            NotAnalysable::Saturated {
                channel,
                sample,
                samples,
            } => write!(
                f,
                "the {channel} channel is saturated: it stays at its extreme value for {samples} \
                 samples from sample {sample} while the pin moves (widen the converter's range)"
            ),
            NotAnalysable::Stuck {
                channel,
                value,
                samples,
            } => write!(
                f,
                "the {channel} channel reads one value ({value:.4e}) for all {samples} samples: its \
                 input is stuck or dead (`tribo selftest` checks the converter's inputs)"
            ),
        }
    }
}

/// The record passed [`screen`]: what was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Screening {
    /// Half cycles above the noise at the natural period.
    pub half_cycles: usize,
    /// Noise standard deviation of the Mark & Crandall envelope (dimensionless).
    pub envelope_noise: f64,
}

/// Runs of consecutive samples equal to the channel's maximum or minimum (start, length), counting
/// only runs where `moving(i)` holds somewhere, longest first.
pub(super) fn flat_extreme_runs(c: &[f64], moving: impl Fn(usize) -> bool) -> Vec<(usize, usize)> {
    let hi = c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
    if hi <= lo || hi.is_nan() || lo.is_nan() {
        return Vec::new();
    }
    let mut runs = Vec::new();
    for ext in [hi, lo] {
        let mut i = 0;
        while i < c.len() {
            if c[i] == ext {
                let start = i;
                while i < c.len() && c[i] == ext {
                    i += 1;
                }
                if (start..i).any(&moving) {
                    runs.push((start, i - start));
                }
            } else {
                i += 1;
            }
        }
    }
    runs.sort_by_key(|r| std::cmp::Reverse(r.1));
    runs
}

/// A channel is saturated when it stays on its extreme value (the converter's rail) while the pin
/// moves, for at least one long run (`long` samples) or for two runs of [`SATURATION_RUN`]: a
/// quantised noisy sinusoid sampled 60+ times a cycle sits on its extreme code for one to four
/// samples, once (seen on 1 record in 200 at the rig's noise for four).
pub(super) fn saturated(runs: &[(usize, usize)], long: usize) -> Option<(usize, usize)> {
    let first = *runs.first()?;
    let repeated = runs.iter().filter(|r| r.1 >= SATURATION_RUN).count() >= 2;
    (first.1 >= long || repeated).then_some(first)
}

/// A displacement whose whole range is at most this fraction of its largest value never moved: a
/// released pin swings from one side of its rest to the other, a range of about twice its
/// largest value.
pub const STILL_FRACTION: f64 = 0.05;

/// A velocity whose largest value is at most this many times its noise is noise only: the pin
/// does not move.
pub const STILL_SIGMAS: f64 = 20.0;

/// Shortest flat run at a channel's extreme that counts, when it recurs.
pub(super) const SATURATION_RUN: usize = 3;

/// The first non-finite sample of τ, y or y', if any.
pub fn check_finite(tau: &[f64], y: &[f64], ydot: &[f64]) -> Result<(), NotAnalysable> {
    for (name, c) in [("time", tau), ("displacement", y), ("velocity", ydot)] {
        if let Some(i) = c.iter().position(|v| !v.is_finite()) {
            return Err(NotAnalysable::NonFinite {
                what: format!("{name} is {} at sample {i}", c[i]),
            });
        }
    }
    Ok(())
}

/// Checks that dimensionless samples can be fitted: finite, not saturated, oscillating at the natural
/// half period π (in τ) above the noise for at least [`MIN_HALF_CYCLES`] half cycles.
pub fn screen(tau: &[f64], y: &[f64], ydot: &[f64]) -> Result<Screening, NotAnalysable> {
    screen_with(tau, y, ydot, false)
}

/// Samples at a channel's rail while the pin moves, in a channel that reaches its rail in at
/// least two separate runs (a converter clipping the largest peaks): `true` for each such sample
/// and its two neighbours. Empty of `true` for a channel that does not clip.
pub fn clipped(y: &[f64], ydot: &[f64]) -> Vec<bool> {
    let n = y.len().min(ydot.len());
    let mut out = vec![false; n];
    let vmax = ydot[..n].iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let moving = |i: usize| ydot[i].abs() > 0.05 * vmax;
    let runs_y = flat_extreme_runs(&y[..n], moving);
    let runs_v = flat_extreme_runs(&ydot[..n], |i| ydot[i] != 0.0);
    for (c, runs) in [(&y[..n], runs_y), (&ydot[..n], runs_v)] {
        // A rail: one extreme value reached in two or more runs.
        let hi = c.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let lo = c.iter().copied().fold(f64::INFINITY, f64::min);
        for ext in [hi, lo] {
            let at: Vec<&(usize, usize)> = runs.iter().filter(|r| c[r.0] == ext).collect();
            if at.len() >= 2 {
                for r in at {
                    out[r.0.saturating_sub(1)..(r.0 + r.1 + 1).min(n)].fill(true);
                }
            }
        }
    }
    out
}

/// The most of a motion's samples that may sit at a converter's rail for the fit to leave them out
/// rather than refuse the record.
pub const MAX_CLIPPED_FRACTION: f64 = 0.02;

/// [`screen`], with `allow_clipped`: a record whose clipped samples ([`clipped`]) are at most
/// [`MAX_CLIPPED_FRACTION`] of it passes (the fit leaves them out).
pub fn screen_with(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    allow_clipped: bool,
) -> Result<Screening, NotAnalysable> {
    check_finite(tau, y, ydot)?;
    let n = tau.len().min(y.len()).min(ydot.len());
    if n < 8 {
        return Err(NotAnalysable::NoOscillation {
            reason: format!("only {n} samples"),
        });
    }
    let (tau, y, ydot) = (&tau[..n], &y[..n], &ydot[..n]);
    // Before anything reads the motion from the channels: a channel stuck at one value (a
    // converter input stuck or dead), or a pin that never moves (friction above the blades' pull
    // at the release, a magnet that never let go), whose noise sits at the converter's extreme
    // codes for long runs — no saturation either way.
    let constant = |c: &[f64]| c.iter().all(|v| *v == c[0]);
    let (ylo, yhi) = y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let yabs = ylo.abs().max(yhi.abs());
    // A released pin swings from one side of its rest to the other: the displacement's range is
    // about twice its largest value. A still one stays where it started, give or take its noise.
    let still = yhi - ylo <= STILL_FRACTION * yabs;
    let v_noise = noise_sigma(ydot).unwrap_or(0.0);
    let v_peak = ydot.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let v_moves = !constant(ydot) && v_peak > STILL_SIGMAS * v_noise;
    if constant(y) && v_moves {
        return Err(NotAnalysable::Stuck {
            channel: "displacement",
            value: y[0],
            samples: n,
        });
    }
    if constant(ydot) && !still {
        return Err(NotAnalysable::Stuck {
            channel: "velocity",
            value: ydot[0],
            samples: n,
        });
    }
    if still && !v_moves {
        return Err(NotAnalysable::NoOscillation {
            reason: format!(
                "the pin never moves: the displacement stays within {:.2} % of its value ({:.4} \
                 in units of N/k) over all {n} samples and the velocity is noise only (friction \
                 above the blades' pull at the release, or the magnet never let go)",
                if yabs > 0.0 {
                    100.0 * (yhi - ylo) / yabs
                } else {
                    0.0
                },
                y[0]
            ),
        });
    }
    let vmax = ydot.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // A displacement flat at its extreme while the velocity says the pin moves fast (not the
    // magnet's hold before the release, when both are still).
    let moving = |i: usize| ydot[i].abs() > 0.05 * vmax;
    // A long run: a fortieth of a cycle (9 samples at the rig's 10 kHz), at least 6.
    let dtau = (tau[n - 1] - tau[0]) / (n - 1) as f64;
    let long = ((2.0 * PI / dtau / 40.0).ceil() as usize).max(6);
    // A few clipped peaks (at most MAX_CLIPPED_FRACTION of the samples) are left out by the fit:
    // their runs do not count here. Any other flat run at a rail still does.
    let clip = if allow_clipped {
        clipped(y, ydot)
    } else {
        vec![false; n]
    };
    let masked = (clip.iter().filter(|&&b| b).count() as f64) <= MAX_CLIPPED_FRACTION * n as f64;
    let unmasked = |runs: Vec<(usize, usize)>| -> Vec<(usize, usize)> {
        runs.into_iter()
            .filter(|r| !(masked && clip[r.0]))
            .collect()
    };
    if let Some((sample, samples)) = saturated(&unmasked(flat_extreme_runs(y, moving)), long) {
        return Err(NotAnalysable::Saturated {
            channel: "displacement",
            sample,
            samples,
        });
    }
    if let Some((sample, samples)) =
        saturated(&unmasked(flat_extreme_runs(ydot, |i| ydot[i] != 0.0)), long)
    {
        return Err(NotAnalysable::Saturated {
            channel: "velocity",
            sample,
            samples,
        });
    }
    let a = mark_crandall(y, ydot);
    let noise = noise_sigma(&a).unwrap_or(0.0);
    // Extrema: displacement (signed) at each velocity sign change, at least π/8 apart (the noise
    // dithers the sign of the velocity about each reversal). A half cycle swings from one side to
    // the other by more than 10 × the noise; after the stop the noise only dithers about the rest
    // position.
    let mut ext: Vec<(f64, f64)> = Vec::new();
    for i in 1..n {
        let (p, q) = (ydot[i - 1], ydot[i]);
        if (p > 0.0 && q <= 0.0) || (p < 0.0 && q >= 0.0) {
            let j = if p.abs() < q.abs() { i - 1 } else { i };
            if ext.last().is_none_or(|e| tau[j] - e.0 >= PI / 8.0) {
                ext.push((tau[j], y[j]));
            }
        }
    }
    // A record that starts at rest (the release) starts at an extremum.
    if ydot[0].abs() <= 0.05 * vmax && ext.first().is_none_or(|e| e.0 - tau[0] >= PI / 8.0) {
        ext.insert(0, (tau[0], y[0]));
    }
    // A motion that ends at rest (the stop) ends at an extremum.
    if ydot[n - 1].abs() <= 0.05 * vmax && ext.last().is_none_or(|e| tau[n - 1] - e.0 >= PI / 8.0) {
        ext.push((tau[n - 1], y[n - 1]));
    }
    // The swing is a displacement: compare it with the displacement's own noise (the envelope's
    // mixes in the velocity's, and a large ripple when the rig constants are wrong).
    let level = 10.0 * noise_sigma(y).unwrap_or(0.0);
    let (mut regular, mut significant) = (0usize, Vec::new());
    for w in ext.windows(2) {
        let swing = (w[1].1 - w[0].1).abs();
        if swing > level && swing > 0.0 && w[0].1 * w[1].1 < 0.0 {
            let dt = w[1].0 - w[0].0;
            significant.push(dt);
            if (0.5 * PI..=2.0 * PI).contains(&dt) {
                regular += 1;
            }
        }
    }
    if regular == 0 {
        let reason = if significant.is_empty() {
            if vmax == 0.0 {
                "the velocity is zero throughout: the pin never moves".to_string()
            } else {
                "no swing of the displacement from one side to the other rises above 10 × the \
                 noise"
                    .to_string()
            }
        } else {
            significant.sort_by(f64::total_cmp);
            let med = significant[significant.len() / 2];
            format!(
                "the extrema are {:.2} natural half periods apart, not one: check the rig \
                 constants (mass_kg, stiffness_n_per_m)",
                med / PI
            )
        };
        return Err(NotAnalysable::NoOscillation { reason });
    }
    if regular < MIN_HALF_CYCLES {
        return Err(NotAnalysable::TooFewHalfCycles {
            found: regular,
            need: MIN_HALF_CYCLES,
        });
    }
    Ok(Screening {
        half_cycles: regular,
        envelope_noise: noise,
    })
}
