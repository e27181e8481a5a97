//! Counts to SI: per-channel calibration and the capture of offsets before release.
//!
//! A channel's SI value is `gain * (count - zero)` ([`ChannelCal`]). Zeros are captured while the
//! magnet holds the pin (see [`OffsetCapture`] and `analysis::Pipeline::release`): the pin is at rest,
//! so the velocity and force channels read their offsets, and the displacement channel reads the
//! configured initial amplitude `x0`.
use crate::wire::ChannelCal;

/// Number of channels of the rig (indexing of `Configure::calibration`).
pub use crate::wire::CHANNELS;

/// Largest count of the 16-bit converters.
pub const ADC_MAX: u16 = u16::MAX;

/// Count the converter would give for an SI value: rounded to nearest and saturated to
/// `0..=ADC_MAX` like a real 16-bit ADC (`NaN` reads as 0). `None` for a zero or non-finite gain.
pub fn to_count(cal: ChannelCal, si: f64) -> Option<u16> {
    if !(cal.gain.is_finite() && cal.gain != 0.0 && cal.zero.is_finite()) {
        return None;
    }
    let c = si / cal.gain as f64 + cal.zero as f64 + 0.5;
    let c = if c.is_nan() {
        0.0
    } else {
        c.clamp(0.0, ADC_MAX as f64)
    };
    // floor of a value in 0..=65535.5, then the saturating float-to-int cast
    Some(c as u16)
}

/// Calibration of a 16-bit converter whose full range `0..=ADC_MAX` spans `lo..=hi` (SI units).
/// `None` unless `lo < hi`, both finite, and the span lies within 16 widths of zero (farther, the
/// `f32` zero count could not hold a fraction of a step).
pub fn spanning(lo: f64, hi: f64) -> Option<ChannelCal> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return None;
    }
    let gain = (hi - lo) / ADC_MAX as f64;
    let zero = -lo / gain;
    let cal = ChannelCal {
        gain: gain as f32,
        zero: zero as f32,
    };
    let near = zero.abs() <= 16.0 * ADC_MAX as f64;
    (near && cal.gain.is_finite() && cal.gain > 0.0 && cal.zero.is_finite()).then_some(cal)
}

/// Running mean and spread of each channel's counts while the pin is held (exact integer sums).
#[derive(Clone, Copy, Debug, Default)]
pub struct OffsetCapture {
    n: u32,
    sum: [u64; CHANNELS],
    sum_sq: [u64; CHANNELS],
}

impl OffsetCapture {
    /// Samples beyond this many are ignored (keeps the integer sums exact: 2^24 · 2^32 < 2^64).
    pub const MAX_SAMPLES: u32 = 1 << 24;

    /// Adds one sample, given as `(channel index, count)` pairs.
    pub fn add(&mut self, counts: impl Iterator<Item = (usize, u16)>) {
        if self.n >= Self::MAX_SAMPLES {
            return;
        }
        self.n += 1;
        for (ch, c) in counts {
            if let (Some(s), Some(q)) = (self.sum.get_mut(ch), self.sum_sq.get_mut(ch)) {
                let c = c as u64;
                *s += c;
                *q += c * c;
            }
        }
    }

    /// Number of samples captured.
    pub fn samples(&self) -> u32 {
        self.n
    }

    /// Mean count of a channel (`None` before any sample).
    pub fn mean(&self, ch: usize) -> Option<f64> {
        if self.n == 0 {
            return None;
        }
        Some(*self.sum.get(ch)? as f64 / self.n as f64)
    }

    /// Standard deviation of a channel's counts (`None` with fewer than 2 samples).
    pub fn std(&self, ch: usize) -> Option<f64> {
        if self.n < 2 {
            return None;
        }
        let n = self.n as f64;
        let s = *self.sum.get(ch)? as f64;
        let q = *self.sum_sq.get(ch)? as f64;
        let var = (q - s * s / n) / (n - 1.0);
        Some(crate::fit::sqrt(var.max(0.0)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn capture_mean_and_std() {
        let mut c = OffsetCapture::default();
        for i in 0..1000u32 {
            let v = if i % 2 == 0 { 1000 } else { 1002 };
            c.add([(1usize, v), (7usize, 3)].into_iter()); // channel 7 does not exist: ignored
        }
        assert_eq!(c.samples(), 1000);
        assert!((c.mean(1).unwrap() - 1001.0).abs() < 1e-12);
        assert!((c.std(1).unwrap() - 1.0005).abs() < 1e-3);
        assert_eq!(c.mean(0), Some(0.0));
        assert_eq!(c.mean(9), None);
    }

    #[test]
    fn spanning_rejects_nonsense() {
        assert!(spanning(1.0, 1.0).is_none());
        assert!(spanning(f64::NAN, 1.0).is_none());
        assert!(spanning(2.0, 1.0).is_none());
        assert!(spanning(1000.0, 1000.1).is_none()); // too far from zero for an f32 zero count
        assert!(spanning(20.0, 150.0).is_some());
        assert!(to_count(
            ChannelCal {
                gain: 0.0,
                zero: 0.0
            },
            1.0
        )
        .is_none());
    }

    proptest! {
        /// SI → count → SI lands within half a step (the quantisation) inside the span, and out-of-span
        /// values saturate at the rails.
        #[test]
        fn calibration_round_trip(width in 1e-4f64..2.0, lo_frac in -10.0f64..10.0, frac in -0.2f64..1.2) {
            let lo = lo_frac * width;
            let hi = lo + width;
            let cal = spanning(lo, hi).unwrap();
            let si = lo + frac * width;
            let c = to_count(cal, si).unwrap();
            let back = cal.to_si(c) as f64;
            let step = width / ADC_MAX as f64;
            if (0.0..=1.0).contains(&frac) {
                prop_assert!((back - si).abs() <= 0.5 * step + 1e-6 * width, "{si} -> {c} -> {back}");
            } else if frac < 0.0 {
                prop_assert_eq!(c, 0);
            } else {
                prop_assert_eq!(c, ADC_MAX);
            }
        }
    }
}
