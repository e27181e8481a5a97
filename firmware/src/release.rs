//! The release electromagnet: hold with PWM, release with a short reverse pulse (kills the
//! remanent field that would otherwise keep the pin for a few ms and spoil the start of the run),
//! a hold-time limit so the coil cannot cook, the release interlocks, and the button debouncer.

use crate::hal::{Magnet, MagnetDrive};
use crate::wire::Interlock;

/// Timing and drive of the electromagnet.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReleaseConfig {
    /// PWM duty while holding.
    pub hold_duty: f32,
    /// Duty of the reverse pulse.
    pub reverse_duty: f32,
    /// Length of the reverse pulse, µs.
    pub reverse_us: u32,
    /// Longest continuous hold, µs; then the coil is switched off.
    pub hold_limit_us: u64,
    /// The button must read the same level this long to count, µs.
    pub debounce_us: u32,
}

impl Default for ReleaseConfig {
    fn default() -> Self {
        ReleaseConfig {
            hold_duty: 0.6,
            reverse_duty: 0.3,
            reverse_us: 3_000,
            hold_limit_us: 120_000_000,
            debounce_us: 20_000,
        }
    }
}

/// What the coil is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoilState {
    Off,
    Holding { since_us: u64 },
    Reversing { until_us: u64 },
}

/// Something the magnet did by itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MagnetEvent {
    /// The hold-time limit was reached: the coil is off.
    HoldTimeExceeded,
    /// The reverse pulse is over: the coil is off, the pin is free.
    Released,
}

/// The electromagnet's state machine.
#[derive(Debug, Clone)]
pub struct Release {
    cfg: ReleaseConfig,
    state: CoilState,
}

impl Release {
    pub fn new(cfg: ReleaseConfig) -> Self {
        Release {
            cfg,
            state: CoilState::Off,
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

    /// Starts holding (keeps the hold timer if already holding).
    pub fn hold(&mut self, m: &mut impl Magnet, now_us: u64) {
        if !self.is_holding() {
            self.state = CoilState::Holding { since_us: now_us };
        }
        m.magnet_drive(MagnetDrive::Hold {
            duty: clamp01(self.cfg.hold_duty),
        });
    }

    /// Releases: reverse pulse now, coil off when [`Release::poll`] sees it is over. Call only after
    /// the interlocks passed.
    pub fn release(&mut self, m: &mut impl Magnet, now_us: u64) {
        self.state = CoilState::Reversing {
            until_us: now_us + self.cfg.reverse_us as u64,
        };
        m.magnet_drive(MagnetDrive::Reverse {
            duty: clamp01(self.cfg.reverse_duty),
        });
    }

    /// Coil off at once.
    pub fn off(&mut self, m: &mut impl Magnet) {
        self.state = CoilState::Off;
        m.magnet_drive(MagnetDrive::Off);
    }

    /// Ends the reverse pulse and enforces the hold-time limit.
    pub fn poll(&mut self, m: &mut impl Magnet, now_us: u64) -> Option<MagnetEvent> {
        match self.state {
            CoilState::Reversing { until_us } if now_us >= until_us => {
                self.off(m);
                Some(MagnetEvent::Released)
            }
            CoilState::Holding { since_us }
                if now_us.saturating_sub(since_us) > self.cfg.hold_limit_us =>
            {
                self.off(m);
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

    #[test]
    fn release_is_a_reverse_pulse_then_off() {
        let cfg = ReleaseConfig::default();
        let mut r = Release::new(cfg);
        let mut c = Coil::default();
        r.hold(&mut c, 0);
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
        r.hold(&mut c, 10);
        // Re-arming while holding does not restart the timer.
        r.hold(&mut c, 4_000_000);
        assert_eq!(r.poll(&mut c, 5_000_010), None);
        assert_eq!(
            r.poll(&mut c, 5_000_011),
            Some(MagnetEvent::HoldTimeExceeded)
        );
        assert_eq!(c.0.last(), Some(&MagnetDrive::Off));
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
        for i in 0..10 {
            presses += d.update(i % 2 == 1, t) as u32;
            t += 1_000;
        }
        for _ in 0..50 {
            presses += d.update(false, t) as u32;
            t += 1_000;
        }
        assert_eq!(presses, 1);
        // A glitch shorter than the debounce time is no press.
        for _ in 0..15 {
            presses += d.update(true, t) as u32;
            t += 1_000;
        }
        presses += d.update(false, t) as u32;
        assert_eq!(presses, 1);
    }
}
