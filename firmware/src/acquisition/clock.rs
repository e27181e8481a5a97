//! The sample clock and the converter's timing: which prescaler and reload make the timer produce
//! the rate asked for (or the nearest one it can make, which is then the rate the run records), how
//! long the ADC takes per scan, and where the stream stands after the converter was restarted.
//!
//! Pure arithmetic, so that the board and the virtual rig use the very same numbers and the tests
//! can check them exhaustively.

use crate::wire::SampleClock;

/// Kernel clock of the board's sample timer (TIM6 on APB1: timer clocks run at twice the 100 MHz
/// bus clock), Hz. The virtual rig models the same timer; the board checks the clock tree gives it.
pub const BOARD_TIMER_HZ: u32 = 200_000_000;

/// Largest divider of a 16-bit prescaler or auto-reload register (`PSC + 1`, `ARR + 1`).
pub const MAX_DIVIDER: u32 = 1 << 16;
/// Fewest timer ticks per sample (a reload of 0 stops a basic timer).
pub const MIN_TICKS: u32 = 2;

/// Prescaler and auto-reload of a 16-bit timer: one update (one trigger) every
/// `(psc + 1) * (arr + 1)` ticks of its kernel clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimerSetting {
    pub psc: u16,
    pub arr: u16,
}

impl TimerSetting {
    /// Kernel clock ticks between two updates.
    pub const fn ticks(&self) -> u32 {
        (self.psc as u32 + 1) * (self.arr as u32 + 1)
    }
}

/// Integer square root (largest `r` with `r * r <= n`).
fn isqrt(n: u32) -> u32 {
    if n < 2 {
        return n;
    }
    // Newton from above: monotone, at most ~20 steps for a u32.
    let mut x = n;
    let mut y = x.div_ceil(2);
    while y < x {
        x = y;
        y = (x + n / x) / 2;
    }
    x
}

/// The prescaler and reload that count exactly `ticks`, if a 16-bit timer can (the smallest
/// prescaler that works, so the reload is as fine as possible).
///
/// `ticks` must split into two factors of at most [`MAX_DIVIDER`]; the smaller one lies between
/// `ticks / 65536` and `√ticks`, so at most √ticks candidates are tried (448 for 200 000 ticks).
pub fn split(ticks: u32) -> Option<TimerSetting> {
    if ticks < MIN_TICKS {
        return None;
    }
    if ticks <= MAX_DIVIDER {
        return Some(TimerSetting {
            psc: 0,
            arr: (ticks - 1) as u16,
        });
    }
    let lo = ticks.div_ceil(MAX_DIVIDER).max(2);
    let hi = isqrt(ticks);
    (lo..=hi)
        .find(|&d| ticks.is_multiple_of(d))
        .map(|d| TimerSetting {
            psc: (d - 1) as u16,
            arr: (ticks / d - 1) as u16,
        })
}

/// `|timer_hz / ticks − rate_hz| · ticks`, the rate error times `ticks` (exact, integers).
fn scaled_error(timer_hz: u32, rate_hz: u32, ticks: u32) -> u64 {
    (timer_hz as u64).abs_diff(rate_hz as u64 * ticks as u64)
}

/// Whether `a` ticks give a rate at least as close to `rate_hz` as `b` ticks (compares
/// `err_a / a` with `err_b / b` by cross-multiplication).
fn no_worse(timer_hz: u32, rate_hz: u32, a: u32, b: u32) -> bool {
    scaled_error(timer_hz, rate_hz, a) as u128 * b as u128
        <= scaled_error(timer_hz, rate_hz, b) as u128 * a as u128
}

/// The timer setting whose rate is nearest to `rate_hz` on a timer clocked at `timer_hz`, and the
/// sample clock it makes. The rate is exact when `timer_hz / rate_hz` is a whole number of ticks a
/// 16-bit prescaler and reload can count; otherwise it is the nearest rate the timer can make (the
/// caller reports it: it is what the samples' time axis must use). `None` when no setting comes
/// near: a zero rate or clock, or a rate above half the timer clock.
pub fn choose(timer_hz: u32, rate_hz: u32) -> Option<(TimerSetting, SampleClock)> {
    if timer_hz == 0 || rate_hz == 0 || rate_hz > timer_hz / MIN_TICKS {
        return None;
    }
    let below = timer_hz / rate_hz;
    let above = below + u32::from(!timer_hz.is_multiple_of(rate_hz));
    // A splittable count is never far: every multiple of 65536 up to 2^32 splits, so each search
    // ends within MAX_DIVIDER steps (in practice within a handful).
    let down = (0..MAX_DIVIDER)
        .map_while(|d| below.checked_sub(d))
        .take_while(|&t| t >= MIN_TICKS)
        .find_map(split);
    let up = (0..MAX_DIVIDER)
        .map_while(|d| above.checked_add(d))
        .find_map(split);
    let best = match (down, up) {
        (Some(d), Some(u)) => {
            if no_worse(timer_hz, rate_hz, d.ticks(), u.ticks()) {
                d
            } else {
                u
            }
        }
        (Some(s), None) | (None, Some(s)) => s,
        (None, None) => return None,
    };
    Some((
        best,
        SampleClock {
            timer_hz,
            ticks_per_sample: best.ticks(),
        },
    ))
}

/// ADC sampling time of one channel, as the H7 ADC's `SMPR` code (cycles of the ADC clock).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum SamplingTime {
    Cycles1_5 = 0,
    Cycles2_5 = 1,
    Cycles8_5 = 2,
    Cycles16_5 = 3,
    Cycles32_5 = 4,
    Cycles64_5 = 5,
    Cycles387_5 = 6,
    Cycles810_5 = 7,
}

impl SamplingTime {
    /// The `SMPR` field value.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// Duration in half cycles of the ADC clock.
    pub const fn half_cycles(self) -> u32 {
        match self {
            SamplingTime::Cycles1_5 => 3,
            SamplingTime::Cycles2_5 => 5,
            SamplingTime::Cycles8_5 => 17,
            SamplingTime::Cycles16_5 => 33,
            SamplingTime::Cycles32_5 => 65,
            SamplingTime::Cycles64_5 => 129,
            SamplingTime::Cycles387_5 => 775,
            SamplingTime::Cycles810_5 => 1621,
        }
    }
}

/// Clock of the ADC's conversions, Hz: the 25 MHz kernel clock (PLL2P) through the H743 rev V's
/// fixed divider by two (see `firmware/README.md`). Lower than the real clock would only make the
/// scan-time check below more conservative.
pub const ADC_CLOCK_HZ: u32 = 12_500_000;
/// Successive-approximation time of a 16-bit conversion: 8.5 ADC cycles (in half cycles).
pub const CONVERSION_HALF_CYCLES: u32 = 17;
/// Sampling time of each analog channel, in scan order (displacement, velocity, force, ECR). Every
/// input is an op-amp output behind an RC anti-alias filter; the settling assumption behind 64.5
/// cycles (5.2 µs) is written down in `firmware/README.md`.
pub const SAMPLING: [SamplingTime; crate::hal::ANALOG_CHANNELS] = [SamplingTime::Cycles64_5; 4];

/// Time one scan of the analog channels takes, ns (sampling + conversion of each, back to back).
pub const fn scan_time_ns() -> u32 {
    let mut half = 0;
    let mut i = 0;
    while i < SAMPLING.len() {
        half += SAMPLING[i].half_cycles() + CONVERSION_HALF_CYCLES;
        i += 1;
    }
    // half cycles → ns, rounded up.
    ((half as u64 * 1_000_000_000).div_ceil(2 * ADC_CLOCK_HZ as u64)) as u32
}

/// Index of the first trigger a converter armed now will see, from the timer's own state: the
/// timer started `elapsed_ticks` ago by a coarse clock (error well under half a period), and its
/// counter shows `counter_ticks` since its last update. Update `k` (the trigger of sample `k - 1`)
/// comes `k` periods after the start, so the next trigger is that of sample `updates so far`.
///
/// The counter makes the answer exact: `elapsed − counter` is a whole number of periods, so rounding
/// it to the nearest period absorbs any coarse-clock error below half a period.
pub fn next_trigger(elapsed_ticks: u64, counter_ticks: u32, period_ticks: u32) -> u64 {
    if period_ticks == 0 {
        return 0;
    }
    let p = period_ticks as u64;
    let since_last = elapsed_ticks.saturating_sub(counter_ticks as u64 % p);
    (since_last + p / 2) / p
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn the_board_rates_are_exact_and_their_settings_count_the_ticks() {
        // 200 MHz timer clock (APB1 timers at twice the 100 MHz bus clock).
        for (rate, psc, arr) in [
            (10_000, 0, 19_999),
            (20_000, 0, 9_999),
            (5_000, 0, 39_999),
            (1_000, 3, 49_999),
        ] {
            let (t, c) = choose(200_000_000, rate).unwrap();
            assert_eq!((t.psc, t.arr), (psc, arr), "{rate} S/s");
            assert!(c.is_exactly(rate));
            assert_eq!(t.ticks(), c.ticks_per_sample);
        }
    }

    #[test]
    fn a_rate_the_timer_cannot_make_is_answered_with_the_nearest_it_can() {
        // 9 999 S/s: 20 002.0002 ticks; 20 002 is the nearest count, 9 999.0001 S/s.
        let (t, c) = choose(200_000_000, 9_999).unwrap();
        assert_eq!(c.ticks_per_sample, 20_002);
        assert_eq!(t.ticks(), 20_002);
        assert!(!c.is_exactly(9_999));
        assert!((c.rate_hz() - 9_999.0).abs() < 1e-3);
        // A prime count above 65 536 cannot be split into two 16-bit dividers: 131 071 = 2^17 − 1.
        // Its neighbours 131 070 = 2 × 65 535 and 131 072 = 2 × 65 536 can; the upper one is nearer
        // in rate (the error goes as 1/ticks).
        assert_eq!(split(131_071), None);
        let (t, c) = choose(131_071_000, 1_000).unwrap();
        assert_eq!(c.ticks_per_sample, 131_072);
        assert_eq!((t.psc, t.arr), (1, 65_535));
        assert!((c.rate_hz() - 131_071_000.0 / 131_072.0).abs() < 1e-9);
    }

    #[test]
    fn impossible_requests_are_refused() {
        assert_eq!(choose(0, 10_000), None);
        assert_eq!(choose(200_000_000, 0), None);
        assert_eq!(choose(1_000, 501), None);
        assert!(choose(1_000, 500).is_some());
        assert_eq!(split(0), None);
        assert_eq!(split(1), None);
    }

    proptest! {
        #[test]
        fn the_chosen_clock_is_the_nearest_splittable_one(
            timer_hz in 1_000_000u32..=480_000_000,
            rate_hz in 1u32..=100_000,
        ) {
            let (t, c) = choose(timer_hz, rate_hz).unwrap();
            prop_assert_eq!(t.ticks(), c.ticks_per_sample);
            prop_assert_eq!(c.timer_hz, timer_hz);
            prop_assert_eq!(split(t.ticks()).map(|s| s.ticks()), Some(t.ticks()));
            // No splittable count near the ideal one gives a closer rate.
            let ideal = timer_hz / rate_hz;
            for n in ideal.saturating_sub(300).max(MIN_TICKS)..=ideal + 300 {
                if split(n).is_some() {
                    prop_assert!(
                        no_worse(timer_hz, rate_hz, t.ticks(), n),
                        "{} ticks beat {}", n, t.ticks()
                    );
                }
            }
            // An exact rate is found whenever one exists.
            if timer_hz % rate_hz == 0 && split(ideal).is_some() {
                prop_assert!(c.is_exactly(rate_hz));
            }
        }

        #[test]
        fn split_counts_exactly_or_not_at_all(ticks in 0u32..=u32::MAX) {
            match split(ticks) {
                Some(s) => prop_assert_eq!(s.ticks(), ticks),
                None => {
                    // Then no pair of 16-bit dividers multiplies to it.
                    let lo = ticks.div_ceil(MAX_DIVIDER).max(2);
                    let hi = isqrt(ticks);
                    prop_assert!(ticks < MIN_TICKS
                        || (ticks > MAX_DIVIDER && (lo..=hi).all(|d| ticks % d != 0)));
                }
            }
        }

        #[test]
        fn isqrt_is_the_floor_of_the_square_root(n in 0u32..=u32::MAX) {
            let r = isqrt(n) as u64;
            prop_assert!(r * r <= n as u64 && (r + 1) * (r + 1) > n as u64);
        }

        #[test]
        fn the_next_trigger_is_exact_whatever_the_coarse_clock_error(
            updates in 0u64..10_000_000,
            period in 10u32..200_000,
            phase_frac in 0.0f64..1.0,
            error_frac in -0.49f64..0.49,
        ) {
            let counter = ((period - 1) as f64 * phase_frac) as u32;
            let true_elapsed = updates * period as u64 + counter as u64;
            let coarse = (true_elapsed as f64 + error_frac * period as f64).max(0.0) as u64;
            prop_assert_eq!(next_trigger(coarse, counter, period), updates);
        }
    }

    #[test]
    fn a_scan_fits_well_inside_the_fastest_sample_period() {
        let fastest = *crate::wire::limits::SAMPLE_RATE_HZ.end();
        let period_ns = 1_000_000_000 / fastest;
        let scan = scan_time_ns();
        // 4 × (64.5 + 8.5) cycles at 12.5 MHz = 23.36 µs, against 50 µs at 20 kS/s: a trigger never
        // finds the ADC still busy with the previous scan (it would be ignored, silently).
        assert_eq!(scan, 23_360);
        assert!(scan * 2 <= period_ns + 3_000, "{scan} ns of {period_ns} ns");
        assert!(scan < period_ns);
    }
}
