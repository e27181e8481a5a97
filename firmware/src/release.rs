//! The release electromagnet: hold with PWM, release with a short reverse pulse (kills the
//! remanent field that would otherwise keep the pin for a few ms and spoil the start of the run),
//! the coil's limits so it cannot cook, the release interlocks, and the button debouncer.
//!
//! Coil limits ([`crate::wire::limits`]): one hold lasts at most [`limits::MAGNET_MAX_HOLD_MS`] (or
//! less, as the caller asks: stand-alone mode holds at most [`limits::STANDALONE_HOLD_MS`]); and the
//! coil is on at most [`limits::MAGNET_MAX_DUTY`] of the time on average, kept as a budget of
//! [`limits::MAGNET_MAX_HOLD_MS`] of holding that holding spends and rest refills at
//! `duty / (1 − duty)` per second. An empty budget switches the coil off and starts a cool-down: it
//! may hold again once half the budget is back.

use crate::hal::{Magnet, MagnetDrive};
use crate::wire::{limits, Interlock};

/// Timing and drive of the electromagnet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReleaseConfig {
    /// PWM duty while holding.
    pub hold_duty: f32,
    /// Duty of the reverse pulse.
    pub reverse_duty: f32,
    /// Length of the reverse pulse, µs.
    pub reverse_us: u32,
    /// Longest continuous hold, µs, and the size of the hold budget; then the coil is switched off.
    pub hold_limit_us: u64,
    /// Largest fraction of the time the coil may be on, on average (0 < duty < 1).
    pub max_duty: f32,
    /// The button must read the same level this long to count, µs.
    pub debounce_us: u32,
}

impl Default for ReleaseConfig {
    fn default() -> Self {
        ReleaseConfig {
            hold_duty: 0.6,
            reverse_duty: 0.3,
            reverse_us: 3_000,
            hold_limit_us: limits::MAGNET_MAX_HOLD_MS as u64 * 1000,
            max_duty: limits::MAGNET_MAX_DUTY,
            debounce_us: 20_000,
        }
    }
}

/// What the coil is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoilState {
    Off,
    /// Holding since `since_us`, for at most `limit_us`.
    Holding {
        since_us: u64,
        limit_us: u64,
    },
    Reversing {
        until_us: u64,
    },
}

/// Something the magnet did by itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MagnetEvent {
    /// The hold-time limit or the hold budget was reached: the coil is off.
    HoldTimeExceeded,
    /// The reverse pulse is over: the coil is off, the pin is free.
    Released,
}

/// The electromagnet's state machine.
#[derive(Debug, Clone)]
pub struct Release {
    cfg: ReleaseConfig,
    state: CoilState,
    /// Hold budget left, µs.
    budget_us: u64,
    /// Time up to which the budget is accounted.
    accounted_us: u64,
    /// The budget ran out: no hold until half of it is back.
    cooling: bool,
}

impl Release {
    pub fn new(cfg: ReleaseConfig) -> Self {
        Release {
            cfg,
            state: CoilState::Off,
            budget_us: cfg.hold_limit_us,
            accounted_us: 0,
            cooling: false,
        }
    }

    pub fn state(&self) -> CoilState {
        self.state
    }

    pub fn is_holding(&self) -> bool {
        matches!(self.state, CoilState::Holding { .. })
    }

    /// Whether the coil is energised at all.
    pub fn is_on(&self) -> bool {
        self.state != CoilState::Off
    }

    /// Hold budget left, µs.
    pub fn budget_us(&self) -> u64 {
        self.budget_us
    }

    /// Refill rate of the budget while off, per µs of rest.
    fn refill(&self) -> f64 {
        let d = self.cfg.max_duty as f64;
        if d.is_finite() && d > 0.0 && d < 1.0 {
            d / (1.0 - d)
        } else {
            0.0
        }
    }

    /// Spends or refills the budget up to `now_us`.
    fn account(&mut self, now_us: u64) {
        let dt = now_us.saturating_sub(self.accounted_us);
        self.accounted_us = self.accounted_us.max(now_us);
        if self.is_on() {
            self.budget_us = self.budget_us.saturating_sub(dt);
        } else {
            let add = (dt as f64 * self.refill()) as u64;
            self.budget_us = self
                .budget_us
                .saturating_add(add)
                .min(self.cfg.hold_limit_us);
        }
        if self.cooling && self.budget_us >= self.cfg.hold_limit_us / 2 {
            self.cooling = false;
        }
    }

    /// How long until the coil may hold again (0: it may now).
    pub fn cooldown_left_us(&mut self, now_us: u64) -> u64 {
        self.account(now_us);
        if !self.cooling {
            return 0;
        }
        let missing = (self.cfg.hold_limit_us / 2).saturating_sub(self.budget_us) as f64;
        let rate = self.refill();
        if rate > 0.0 {
            let w = missing / rate;
            let whole = w as u64;
            if (whole as f64) < w {
                whole + 1
            } else {
                whole
            }
        } else {
            u64::MAX
        }
    }

    /// Starts holding for at most `limit_us` (capped at the configured limit; keeps the hold timer if
    /// already holding). Refused while the coil cools down: `Err(µs left)`.
    pub fn hold(&mut self, m: &mut impl Magnet, now_us: u64, limit_us: u64) -> Result<(), u64> {
        let wait = self.cooldown_left_us(now_us);
        if wait > 0 {
            return Err(wait);
        }
        let limit_us = limit_us.min(self.cfg.hold_limit_us);
        match &mut self.state {
            CoilState::Holding { limit_us: l, .. } => *l = (*l).min(limit_us),
            _ => {
                self.state = CoilState::Holding {
                    since_us: now_us,
                    limit_us,
                }
            }
        }
        m.magnet_drive(MagnetDrive::Hold {
            duty: clamp01(self.cfg.hold_duty),
        });
        Ok(())
    }

    /// Releases: reverse pulse now, coil off when [`Release::poll`] sees it is over. Call only after
    /// the interlocks passed.
    pub fn release(&mut self, m: &mut impl Magnet, now_us: u64) {
        self.account(now_us);
        self.state = CoilState::Reversing {
            until_us: now_us + self.cfg.reverse_us as u64,
        };
        m.magnet_drive(MagnetDrive::Reverse {
            duty: clamp01(self.cfg.reverse_duty),
        });
    }

    /// Coil off at once.
    pub fn off(&mut self, m: &mut impl Magnet, now_us: u64) {
        self.account(now_us);
        self.state = CoilState::Off;
        m.magnet_drive(MagnetDrive::Off);
    }

    /// Ends the reverse pulse and enforces the hold limits.
    pub fn poll(&mut self, m: &mut impl Magnet, now_us: u64) -> Option<MagnetEvent> {
        self.account(now_us);
        match self.state {
            CoilState::Reversing { until_us } if now_us >= until_us => {
                self.off(m, now_us);
                Some(MagnetEvent::Released)
            }
            CoilState::Holding { since_us, limit_us }
                if now_us.saturating_sub(since_us) > limit_us || self.budget_us == 0 =>
            {
                self.cooling = self.budget_us == 0;
                self.off(m, now_us);
                Some(MagnetEvent::HoldTimeExceeded)
            }
            _ => None,
        }
    }
}

fn clamp01(x: f32) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        x.clamp(0.0, 1.0)
    }
}

/// The release interlocks, checked in this order: armed, magnet holding, sampling, heater healthy.
pub fn check_interlocks(
    armed: bool,
    holding: bool,
    sampling: bool,
    heater_healthy: bool,
) -> Result<(), Interlock> {
    if !armed {
        Err(Interlock::NotArmed)
    } else if !holding {
        Err(Interlock::MagnetOff)
    } else if !sampling {
        Err(Interlock::NotSampling)
    } else if !heater_healthy {
        Err(Interlock::HeaterUnhealthy)
    } else {
        Ok(())
    }
}

/// Debounces the button: a press counts once the raw level has read "pressed" for `debounce_us`,
/// and the next press needs a release (stable for as long) first.
#[derive(Debug, Clone)]
pub struct Debouncer {
    debounce_us: u64,
    raw: bool,
    raw_since_us: u64,
    stable: bool,
}

impl Debouncer {
    pub fn new(debounce_us: u32) -> Self {
        Debouncer {
            debounce_us: debounce_us as u64,
            raw: false,
            raw_since_us: 0,
            stable: false,
        }
    }

    /// How long the button has been held down (debounced), µs; 0 when it is up.
    pub fn held_us(&self, now_us: u64) -> u64 {
        if self.stable && self.raw {
            now_us.saturating_sub(self.raw_since_us)
        } else {
            0
        }
    }

    /// Feeds the raw level; returns true exactly once per debounced press.
    pub fn update(&mut self, pressed: bool, now_us: u64) -> bool {
        if pressed != self.raw {
            self.raw = pressed;
            self.raw_since_us = now_us;
        }
        if self.raw != self.stable && now_us.saturating_sub(self.raw_since_us) >= self.debounce_us {
            self.stable = self.raw;
            return self.stable;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Default)]
    struct Coil(Vec<MagnetDrive>);
    impl Magnet for Coil {
        fn magnet_drive(&mut self, d: MagnetDrive) {
            self.0.push(d);
        }
    }

    const FULL: u64 = u64::MAX;

    #[test]
    fn release_is_a_reverse_pulse_then_off() {
        let cfg = ReleaseConfig::default();
        let mut r = Release::new(cfg);
        let mut c = Coil::default();
        r.hold(&mut c, 0, FULL).unwrap();
        r.release(&mut c, 1_000);
        assert!(matches!(c.0[1], MagnetDrive::Reverse { duty } if duty > 0.0));
        assert_eq!(
            r.poll(&mut c, 1_000 + cfg.reverse_us as u64 - 1),
            None,
            "pulse too short"
        );
        assert_eq!(
            r.poll(&mut c, 1_000 + cfg.reverse_us as u64),
            Some(MagnetEvent::Released)
        );
        assert_eq!(c.0.last(), Some(&MagnetDrive::Off));
        assert!(!r.is_on());
    }

    #[test]
    fn hold_time_limit_switches_the_coil_off() {
        let cfg = ReleaseConfig {
            hold_limit_us: 5_000_000,
            ..Default::default()
        };
        let mut r = Release::new(cfg);
        let mut c = Coil::default();
        r.hold(&mut c, 10, FULL).unwrap();
        // Re-arming while holding does not restart the timer.
        r.hold(&mut c, 4_000_000, FULL).unwrap();
        assert_eq!(r.poll(&mut c, 5_000_009), None);
        assert_eq!(
            r.poll(&mut c, 5_000_011),
            Some(MagnetEvent::HoldTimeExceeded)
        );
        assert_eq!(c.0.last(), Some(&MagnetDrive::Off));
        // A shorter limit asked by the caller (stand-alone) wins.
        let mut r = Release::new(cfg);
        r.hold(&mut c, 0, 1_000_000).unwrap();
        assert_eq!(r.poll(&mut c, 1_000_000), None);
        assert_eq!(
            r.poll(&mut c, 1_000_001),
            Some(MagnetEvent::HoldTimeExceeded)
        );
    }

    #[test]
    fn duty_budget_and_cool_down() {
        // 10 s budget at 50 %: 10 s of hold, then 5 s of rest before the next hold.
        let cfg = ReleaseConfig {
            hold_limit_us: 10_000_000,
            max_duty: 0.5,
            ..Default::default()
        };
        let mut r = Release::new(cfg);
        let mut c = Coil::default();
        // Holds of 4 s with 1 s rests spend 3 s of budget per cycle: 10 → 7 → 4 → 0 at the end of
        // the third hold, which is cut there.
        let mut t = 0u64;
        let mut cut = None;
        'cycles: for cycle in 0..5 {
            r.hold(&mut c, t, FULL).unwrap();
            for _ in 0..4000 {
                t += 1000;
                if r.poll(&mut c, t) == Some(MagnetEvent::HoldTimeExceeded) {
                    cut = Some((cycle, t));
                    break 'cycles;
                }
            }
            r.off(&mut c, t);
            t += 1_000_000;
            r.poll(&mut c, t);
        }
        let (cycle, at) = cut.expect("the budget ran out");
        assert_eq!((cycle, at), (2, 2 * 5_000_000 + 4_000_000));
        assert!(!r.is_on());
        // Cooling: refused, with the wait; half the budget (5 s) is back after 5 s of rest.
        let wait = r.hold(&mut c, at, FULL).unwrap_err();
        assert_eq!(wait, 5_000_000);
        assert_eq!(r.hold(&mut c, at + 4_999_000, FULL), Err(1_000));
        assert!(r.hold(&mut c, at + 5_000_000, FULL).is_ok());
        // Off without a budget trip (limit or release) is no cool-down.
        let mut r = Release::new(cfg);
        r.hold(&mut c, 0, 1_000_000).unwrap();
        assert_eq!(
            r.poll(&mut c, 1_000_001),
            Some(MagnetEvent::HoldTimeExceeded)
        );
        assert!(r.hold(&mut c, 1_000_002, FULL).is_ok());
    }

    #[test]
    fn interlock_order() {
        assert_eq!(
            check_interlocks(false, true, true, true),
            Err(Interlock::NotArmed)
        );
        assert_eq!(
            check_interlocks(true, false, true, true),
            Err(Interlock::MagnetOff)
        );
        assert_eq!(
            check_interlocks(true, true, false, true),
            Err(Interlock::NotSampling)
        );
        assert_eq!(
            check_interlocks(true, true, true, false),
            Err(Interlock::HeaterUnhealthy)
        );
        assert_eq!(check_interlocks(true, true, true, true), Ok(()));
    }

    #[test]
    fn debouncer_ignores_bounces_and_counts_one_press() {
        let mut d = Debouncer::new(20_000);
        let mut presses = 0;
        // Contact bounce: 1 ms toggles for 10 ms, then held 50 ms, then bounces on release.
        let mut t = 0u64;
        for i in 0..10 {
            presses += d.update(i % 2 == 0, t) as u32;
            t += 1_000;
        }
        for _ in 0..50 {
            presses += d.update(true, t) as u32;
            t += 1_000;
        }
        assert!(d.held_us(t) >= 50_000, "{}", d.held_us(t));
        for i in 0..10 {
            presses += d.update(i % 2 == 1, t) as u32;
            t += 1_000;
        }
        for _ in 0..50 {
            presses += d.update(false, t) as u32;
            t += 1_000;
        }
        assert_eq!(presses, 1);
        assert_eq!(d.held_us(t), 0);
        // A glitch shorter than the debounce time is no press.
        for _ in 0..15 {
            presses += d.update(true, t) as u32;
            t += 1_000;
        }
        presses += d.update(false, t) as u32;
        assert_eq!(presses, 1);
    }
}
