//! Electrical contact resistance: a DAC-driven voltage source across the contact, clamped to 2 mV
//! and 5 mA, and a transimpedance amplifier whose gain is switched automatically so that 1 Ω to
//! 1e8 Ω are all read well inside the ADC's range. Gives log10(R / Ω).
//!
//! Ranges are two decades apart. The controller steps down a range (less gain) when the output is
//! near full scale, up a range when it is below 0.8 % of full scale (so that, a hundred times larger,
//! it is still below 80 %): the hysteresis keeps it from hunting. The source is set to
//! `min(2 mV, 5 mA · R / 1.25)` from the last estimate, so the current stays below 5 mA with margin
//! even for contacts under 0.4 Ω.

#[allow(unused_imports)]
use micromath::F32Ext;

use crate::hal::EcrFrontEnd;

/// Number of transimpedance ranges.
pub const RANGES: u8 = 5;
/// Transimpedance gain of each range, V/A.
pub const GAIN_V_PER_A: [f32; RANGES as usize] = [5e2, 5e4, 5e6, 5e8, 5e10];
/// Output full scale of the transimpedance amplifier (the ADC's reference), V.
pub const FULL_SCALE_V: f32 = 3.3;
/// Largest source voltage across the contact, V.
pub const MAX_SOURCE_V: f32 = 2e-3;
/// Largest current through the contact, A.
pub const MAX_CURRENT_A: f32 = 5e-3;
/// Source voltage at start-up, before anything is known about the contact, V.
pub const START_SOURCE_V: f32 = 1e-4;
/// The source divider between the DAC (0–3.3 V) and the contact: 1000:1.
pub const SOURCE_DIVIDER: f32 = 1000.0;

/// The 12-bit DAC code that sets the source to `volts` (the divider's input clamped to the DAC's
/// 0–3.3 V; a NaN sets 0).
pub fn source_dac_code(volts: f32) -> u16 {
    let dac_v = (volts * SOURCE_DIVIDER).clamp(0.0, FULL_SCALE_V);
    if dac_v.is_nan() {
        return 0;
    }
    (dac_v / FULL_SCALE_V * 4095.0) as u16
}
/// Output fraction of full scale above which the gain is reduced.
pub const DOWN_FRACTION: f32 = 0.95;
/// Output fraction of full scale below which the gain is raised.
pub const UP_FRACTION: f32 = 0.008;
/// Settling time of the transimpedance amplifier after its range or the source changed, µs, per
/// range: to within half an LSB of 16 bits, ≈ 11 time constants of the feedback network. Assumed
/// front end (see `firmware/README.md`): ranges 0–2 with a 10 kHz feedback pole (τ = 16 µs), range 3
/// (5e8 V/A) with 1 kHz (τ = 160 µs), range 4 (5e10 V/A) with 100 Hz (τ = 1.6 ms).
pub const SETTLE_US: [u32; RANGES as usize] = [200, 200, 200, 2_000, 20_000];

/// Samples of a stream at `clock` that fall inside the settling time of `range` after a change: the
/// whole ones plus one, for the scan that may already have been under way when the change was made
/// (that scan's ECR conversion may be on either side of it).
pub fn settling_samples(range: u8, clock: crate::wire::SampleClock) -> u16 {
    let us = SETTLE_US[(range.min(RANGES - 1)) as usize] as u64;
    let rate = clock.rate_hz();
    if !rate.is_finite() || rate <= 0.0 {
        return u16::MAX;
    }
    // Samples whose instant lies within `us` of the change, rounded up.
    let n = clock.samples_in_us(us) + u64::from(clock.time_us(clock.samples_in_us(us)) < us);
    (n + 1).min(u16::MAX as u64) as u16
}

/// The transimpedance output, V, that an ECR channel count stands for (16 bits over
/// [`FULL_SCALE_V`]).
pub fn count_to_volts(count: f32) -> f32 {
    count / 65535.0 * FULL_SCALE_V
}

/// log10(R) reported for an open contact (no measurable current on the most sensitive range).
pub const LOG10_OPEN: f32 = 11.0;
/// log10(R) reported when the current limit cannot be met (dead short).
pub const LOG10_SHORT: f32 = -3.0;

/// Clamps a requested source voltage to the rig's limits for a contact of about `r_ohm`.
pub fn clamp_source(volts: f32, r_ohm: f32) -> f32 {
    let by_current = if r_ohm.is_finite() && r_ohm > 0.0 {
        MAX_CURRENT_A * r_ohm / 1.25
    } else {
        0.0
    };
    let v = if volts.is_nan() { 0.0 } else { volts };
    v.min(MAX_SOURCE_V)
        .min(if r_ohm.is_nan() {
            MAX_SOURCE_V
        } else {
            by_current
        })
        .max(0.0)
}

/// The autoranging controller.
#[derive(Debug, Clone)]
pub struct Ecr {
    range: u8,
    source_v: f32,
    r_ohm: f32,
    log10_r: f32,
    /// The range is held: readings still update R and the source, never the range.
    hold: bool,
    /// The last reading measured R (it was inside the range's useful span, or at the ends of the
    /// whole span); otherwise it only moved the range or the source.
    measured: bool,
}

impl Default for Ecr {
    fn default() -> Self {
        Self::new()
    }
}

impl Ecr {
    pub const fn new() -> Self {
        Ecr {
            range: 0,
            source_v: START_SOURCE_V,
            r_ohm: f32::NAN,
            log10_r: f32::NAN,
            hold: false,
            measured: false,
        }
    }

    /// Puts the front end in the start-up state (least gain, low source).
    pub fn init(&mut self, fe: &mut impl EcrFrontEnd) {
        *self = Ecr::new();
        fe.set_ecr_range(self.range);
        fe.set_ecr_source(self.source_v);
    }

    pub fn range(&self) -> u8 {
        self.range
    }

    /// Holds the current range (true) or lets the controller switch again (false).
    pub fn set_hold(&mut self, hold: bool) {
        self.hold = hold;
    }

    /// Whether the range is held.
    pub fn is_held(&self) -> bool {
        self.hold
    }

    /// Switches to `range` now (clamped to the ranges that exist).
    pub fn set_range(&mut self, range: u8, fe: &mut impl EcrFrontEnd) {
        self.range = range.min(RANGES - 1);
        fe.set_ecr_range(self.range);
    }

    pub fn source_v(&self) -> f32 {
        self.source_v
    }

    /// Whether the last [`Ecr::update`] measured R (else it returned the previous estimate).
    pub fn measured(&self) -> bool {
        self.measured
    }

    /// Latest log10(R / Ω) (NaN before the first reading).
    pub fn log10_r(&self) -> f32 {
        self.log10_r
    }

    /// Takes one output reading made with the current range and source, updates log10 R, and sets
    /// the range and source for the next reading. Returns log10 R.
    pub fn update(&mut self, output_v: f32, fe: &mut impl EcrFrontEnd) -> f32 {
        let v = if output_v.is_nan() {
            0.0
        } else {
            output_v.clamp(0.0, FULL_SCALE_V)
        };
        let gain = GAIN_V_PER_A[self.range as usize];
        let current = v / gain;
        let saturated = v >= DOWN_FRACTION * FULL_SCALE_V;
        let tiny = v < UP_FRACTION * FULL_SCALE_V;
        // Estimate R unless the reading is out of the range's useful span.
        self.measured = true;
        if !saturated && current > 0.0 && !tiny {
            self.r_ohm = self.source_v / current;
            self.log10_r = self.r_ohm.log10();
        } else if tiny && self.range == RANGES - 1 {
            // Too little current even at the highest gain: open contact (or above 1e11 Ω).
            self.r_ohm = if current > 0.0 {
                self.source_v / current
            } else {
                f32::INFINITY
            };
            self.log10_r = if self.r_ohm.is_finite() {
                self.r_ohm.log10().min(LOG10_OPEN)
            } else {
                LOG10_OPEN
            };
        } else if saturated && self.range == 0 {
            // More than full scale on the least gain: at least this much current.
            let r_max = self.source_v / (FULL_SCALE_V / gain);
            self.r_ohm = r_max;
            self.log10_r = if r_max > 0.0 {
                r_max.log10().max(LOG10_SHORT)
            } else {
                LOG10_SHORT
            };
        } else {
            self.measured = false;
        }
        let least_gain = self.range == 0;
        if !self.hold {
            if saturated && self.range > 0 {
                self.range -= 1;
            } else if tiny && self.range + 1 < RANGES {
                self.range += 1;
            }
        }
        // The source: as high as the limits allow for the contact as last measured; while saturated
        // at the least gain, halve it until the current is readable.
        let wanted = if saturated && least_gain {
            self.source_v * 0.5
        } else if self.r_ohm.is_finite() {
            MAX_SOURCE_V
        } else {
            self.source_v.max(START_SOURCE_V)
        };
        self.source_v = clamp_source(
            wanted,
            if self.r_ohm.is_finite() {
                self.r_ohm
            } else {
                f32::NAN
            },
        );
        if self.r_ohm.is_infinite() {
            self.source_v = MAX_SOURCE_V;
        }
        fe.set_ecr_range(self.range);
        fe.set_ecr_source(self.source_v);
        self.log10_r
    }
}

/// Which range each ECR sample of the converter's stream was converted on, and the mean of the
/// samples converted after the last change settled (the reading a block gives the controller).
///
/// A change made when the converter's next sample is `at` applies to samples `at..`; of those, the
/// first `settling` ([`settling_samples`]) are taken while the amplifier settles and are left out
/// of the mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RangeTrack {
    range: u8,
    prev: u8,
    switched_at: u64,
    settled_from: u64,
    sum: u64,
    n: u32,
    max: u16,
}

impl RangeTrack {
    /// A stream whose samples are all on `range`, settled.
    pub const fn new(range: u8) -> Self {
        RangeTrack {
            range,
            prev: range,
            switched_at: 0,
            settled_from: 0,
            sum: 0,
            n: 0,
            max: 0,
        }
    }

    /// The range (or only the source) changed when the next sample was `at`; the first `settling`
    /// samples from there settle. The mean starts again.
    pub fn switch(&mut self, at: u64, range: u8, settling: u16) {
        if at >= self.switched_at {
            self.prev = self.range_at(at);
            self.switched_at = at;
        }
        self.range = range;
        self.settled_from = at + settling as u64;
        self.sum = 0;
        self.n = 0;
        self.max = 0;
    }

    /// Range sample `index` was converted on (for samples since the change before last: the range
    /// before the last change).
    pub fn range_at(&self, index: u64) -> u8 {
        if index < self.switched_at {
            self.prev
        } else {
            self.range
        }
    }

    /// First sample past the settling of the last change.
    pub fn settled_from(&self) -> u64 {
        self.settled_from
    }

    /// Whether sample `index` was taken while the amplifier settled.
    pub fn is_settling(&self, index: u64) -> bool {
        (self.switched_at..self.settled_from).contains(&index)
    }

    /// One ECR count of sample `index`: counted in the mean once settled.
    pub fn add(&mut self, index: u64, count: u16) {
        if index >= self.settled_from {
            self.sum += count as u64;
            self.n += 1;
            self.max = self.max.max(count);
        }
    }

    /// The reading of the settled counts since the last call or change (`None` if there were
    /// none), and starts a new one: their mean, or their largest if that one is past the range's
    /// top ([`DOWN_FRACTION`] of full scale), so that a range overrun by part of the samples is
    /// left rather than averaged into a wrong resistance.
    pub fn take_mean(&mut self) -> Option<f32> {
        let top = (DOWN_FRACTION * 65535.0) as u16;
        let m = (self.n > 0).then(|| {
            if self.max >= top {
                self.max as f32
            } else {
                (self.sum as f64 / self.n as f64) as f32
            }
        });
        self.sum = 0;
        self.n = 0;
        self.max = 0;
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An ideal front end on a contact of `r` Ω: current = V/R, output = current × gain clipped to full
    /// scale and quantised to 16 bits. Records the worst current and voltage it was ever driven at.
    struct Contact {
        r: f32,
        range: u8,
        source: f32,
        max_current: f32,
        max_source: f32,
    }
    impl EcrFrontEnd for Contact {
        fn set_ecr_source(&mut self, v: f32) {
            self.source = v;
            self.max_source = self.max_source.max(v);
        }
        fn set_ecr_range(&mut self, r: u8) {
            self.range = r;
        }
        fn read_ecr_output(&mut self) -> f32 {
            let i = self.source / self.r;
            self.max_current = self.max_current.max(i);
            let v = (i * GAIN_V_PER_A[self.range as usize]).min(FULL_SCALE_V);
            (v / FULL_SCALE_V * 65535.0).round() / 65535.0 * FULL_SCALE_V
        }
    }

    fn settle(ecr: &mut Ecr, c: &mut Contact, n: usize) -> f32 {
        let mut l = f32::NAN;
        for _ in 0..n {
            let v = c.read_ecr_output();
            l = ecr.update(v, c);
        }
        l
    }

    #[test]
    fn reads_1_ohm_to_1e8_ohm_within_limits_from_a_cold_start() {
        for k in 0..=32 {
            let log_r = k as f32 * 0.25; // 1 Ω .. 1e8 Ω
            let mut c = Contact {
                r: 10f32.powf(log_r),
                range: 9,
                source: 0.0,
                max_current: 0.0,
                max_source: 0.0,
            };
            let mut ecr = Ecr::new();
            ecr.init(&mut c);
            let l = settle(&mut ecr, &mut c, 12);
            assert!((l - log_r).abs() < 0.01, "R = 1e{log_r}: read 1e{l}");
            assert!(
                c.max_source <= MAX_SOURCE_V * 1.0001,
                "source {}",
                c.max_source
            );
            assert!(c.max_current <= MAX_CURRENT_A, "current {}", c.max_current);
            // The range in use keeps the output between the thresholds.
            let out = c.read_ecr_output() / FULL_SCALE_V;
            assert!(
                (UP_FRACTION..DOWN_FRACTION).contains(&out) || ecr.range() == RANGES - 1,
                "{out}"
            );
            // At 1 Ω and above the full 2 mV is used.
            assert!((ecr.source_v() - MAX_SOURCE_V).abs() < 1e-9);
        }
    }

    #[test]
    fn follows_a_contact_that_changes_by_decades_both_ways() {
        let mut c = Contact {
            r: 1e7,
            range: 0,
            source: 0.0,
            max_current: 0.0,
            max_source: 0.0,
        };
        let mut ecr = Ecr::new();
        ecr.init(&mut c);
        let mut ranges_seen = [false; RANGES as usize];
        for &log_r in &[7.0f32, 1.0, 5.5, 0.2, 8.0, 3.0] {
            c.r = 10f32.powf(log_r);
            let l = settle(&mut ecr, &mut c, 6);
            ranges_seen[ecr.range() as usize] = true;
            assert!((l - log_r).abs() < 0.01, "1e{log_r} read as 1e{l}");
        }
        assert!(
            ranges_seen.iter().filter(|&&s| s).count() >= 4,
            "{ranges_seen:?}"
        );
        assert!(c.max_current <= MAX_CURRENT_A);
    }

    #[test]
    fn current_clamp_holds_below_the_source_limit() {
        // 0.05 Ω: 2 mV would drive 40 mA; the source must back off to keep ≤ 5 mA, and still read R.
        let mut c = Contact {
            r: 0.05,
            range: 0,
            source: 0.0,
            max_current: 0.0,
            max_source: 0.0,
        };
        let mut ecr = Ecr::new();
        ecr.init(&mut c);
        let l = settle(&mut ecr, &mut c, 10);
        assert!(c.max_current <= MAX_CURRENT_A, "current {}", c.max_current);
        assert!((l - 0.05f32.log10()).abs() < 0.02, "{l}");
        assert!(ecr.source_v() < MAX_SOURCE_V);
    }

    #[test]
    fn the_range_track_flags_settling_samples_and_averages_the_settled_ones() {
        let mut t = RangeTrack::new(1);
        for i in 0..10 {
            t.add(i, 1000 + i as u16);
        }
        // Mean of 1000..=1009.
        assert_eq!(t.take_mean(), Some(1004.5));
        assert_eq!(t.take_mean(), None);
        // A change to range 2 when the converter's next sample is 14, 3 samples to settle.
        t.switch(14, 2, 3);
        for i in 10..20 {
            t.add(i, if i < 17 { 9_999 } else { 2000 });
        }
        // 10..14 were on range 1, 14..17 settle (their counts are left out), 17.. count.
        assert_eq!((t.range_at(13), t.range_at(14)), (1, 2));
        assert!(!t.is_settling(13) && t.is_settling(14) && t.is_settling(16));
        assert!(!t.is_settling(17));
        assert_eq!(t.take_mean(), Some(2000.0));
        // Nothing settled in a block: no reading rather than a settling one.
        t.switch(20, 3, 50);
        for i in 20..60 {
            t.add(i, 5);
        }
        assert_eq!(t.take_mean(), None);
        assert_eq!(t.settled_from(), 70);
    }

    #[test]
    fn a_held_range_still_reads_but_never_switches() {
        let mut c = Contact {
            r: 1e7,
            range: 0,
            source: 0.0,
            max_current: 0.0,
            max_source: 0.0,
        };
        let mut ecr = Ecr::new();
        ecr.init(&mut c);
        ecr.set_range(1, &mut c);
        ecr.set_hold(true);
        for _ in 0..10 {
            let v = c.read_ecr_output();
            ecr.update(v, &mut c);
        }
        // 1e7 Ω on 5e4 V/A: tiny output, the controller would go up; held, it stays.
        assert_eq!((ecr.range(), c.range), (1, 1));
        assert!(ecr.is_held());
        ecr.set_hold(false);
        let l = settle(&mut ecr, &mut c, 12);
        assert!((l - 7.0).abs() < 0.01, "{l}");
        assert!(ecr.range() > 1);
    }

    #[test]
    fn settling_covers_the_stated_time_and_the_scan_under_way() {
        let c10k = crate::wire::SampleClock {
            timer_hz: 200_000_000,
            ticks_per_sample: 20_000,
        };
        // 200 µs at 10 kS/s: two periods, plus the scan under way.
        assert_eq!(settling_samples(0, c10k), 3);
        // 20 ms: 200 periods + 1.
        assert_eq!(settling_samples(4, c10k), 201);
        // 9 999.0001 S/s: 200 µs is 1.99980 periods, so two whole ones cover it, plus one.
        let odd = crate::wire::SampleClock {
            timer_hz: 200_000_000,
            ticks_per_sample: 20_002,
        };
        assert_eq!(settling_samples(0, odd), 3);
        // 1 kS/s: 2 ms is exactly two periods.
        let c1k = crate::wire::SampleClock {
            timer_hz: 200_000_000,
            ticks_per_sample: 200_000,
        };
        assert_eq!(settling_samples(3, c1k), 3);
        for r in 0..RANGES {
            for c in [c10k, odd, c1k] {
                let n = settling_samples(r, c) as u64;
                // The samples after the flagged ones are at least the settling time after the change
                // (the change may come just after a scan began: n − 1 periods must cover it).
                assert!(
                    c.time_us(n - 1) >= SETTLE_US[r as usize] as u64,
                    "{r} {c:?}"
                );
                // ... and no more than one period later than needed.
                assert!(c.time_us(n - 2) < SETTLE_US[r as usize] as u64, "{r} {c:?}");
            }
        }
        let bad = crate::wire::SampleClock {
            timer_hz: 0,
            ticks_per_sample: 0,
        };
        assert_eq!(settling_samples(0, bad), u16::MAX);
        assert_eq!(count_to_volts(65535.0), FULL_SCALE_V);
    }

    #[test]
    fn open_contact_reads_high_and_nan_output_is_harmless() {
        let mut c = Contact {
            r: f32::INFINITY,
            range: 0,
            source: 0.0,
            max_current: 0.0,
            max_source: 0.0,
        };
        let mut ecr = Ecr::new();
        ecr.init(&mut c);
        let l = settle(&mut ecr, &mut c, 8);
        assert_eq!(l, LOG10_OPEN);
        assert_eq!(ecr.range(), RANGES - 1);
        let l = ecr.update(f32::NAN, &mut c);
        assert!(l.is_finite());
        assert!(ecr.source_v() <= MAX_SOURCE_V);
    }
}
