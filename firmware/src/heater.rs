//! The heater of the plane: PID on the thermocouple to a host setpoint, with a setpoint ramp and
//! anti-windup, and every thermal interlock of the rig (limits in [`crate::wire::limits`]):
//!
//! * **thermocouple**: a read that [`crate::thermocouple::check`] does not trust switches the heater
//!   off for that step; [`limits::TC_BAD_READS`] in a row latch the fault it names;
//! * **over-temperature**: off above [`limits::HEATER_CUTOFF_C`] whatever the setpoint;
//! * **heating watch**: while the plate lags the (ramped) setpoint by more than
//!   [`limits::HEATER_BAND_C`] it must gain [`limits::HEATER_WATCH_GAIN_C`] every
//!   [`limits::HEATER_WATCH_PERIOD_S`] (`HeatingFailed`: the heater does not heat, or the thermocouple
//!   fell off the plate). Once at setpoint, dropping below the band puts the watch on again;
//! * **runaway**: while no heat is wanted (no setpoint, a fault, or the plate above the band) the plate
//!   may not rise [`limits::HEATER_RUNAWAY_RISE_C`] above its lowest reading of the current watch
//!   period (`Runaway`: the heater's switch is stuck on).
//!
//! A fault switches the heater off and stays latched until the host sends a new setpoint or
//! `HeaterOff` (it comes back at the next reading if its cause is still there).

use crate::thermocouple::{BadRead, Reading};
use crate::wire::{limits, HeaterFault, HeaterSetpoint};

/// The thermal interlocks' limits (defaults: [`crate::wire::limits`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ThermalLimits {
    pub cutoff_c: f32,
    pub bad_reads: u8,
    /// Bad reads before this time since start do not latch a fault (the converter's first
    /// conversion).
    pub startup_grace_s: f32,
    pub watch_gain_c: f32,
    pub watch_period_s: f32,
    pub band_c: f32,
    pub runaway_rise_c: f32,
}

impl Default for ThermalLimits {
    fn default() -> Self {
        ThermalLimits {
            cutoff_c: limits::HEATER_CUTOFF_C,
            bad_reads: limits::TC_BAD_READS,
            startup_grace_s: limits::TC_STARTUP_GRACE_MS as f32 / 1000.0,
            watch_gain_c: limits::HEATER_WATCH_GAIN_C,
            watch_period_s: limits::HEATER_WATCH_PERIOD_S,
            band_c: limits::HEATER_BAND_C,
            runaway_rise_c: limits::HEATER_RUNAWAY_RISE_C,
        }
    }
}

/// Controller constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeaterConfig {
    /// Proportional gain, duty per K.
    pub kp: f32,
    /// Integral gain, duty per K·s.
    pub ki: f32,
    /// Derivative gain on the measurement, duty per K/s.
    pub kd: f32,
    /// Largest duty the stage may be driven at.
    pub max_duty: f32,
    pub limits: ThermalLimits,
}

impl Default for HeaterConfig {
    fn default() -> Self {
        HeaterConfig {
            kp: 0.08,
            ki: 0.002,
            kd: 0.0,
            max_duty: 1.0,
            limits: ThermalLimits::default(),
        }
    }
}

/// What one controller step decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeaterStep {
    pub duty: f32,
    /// A fault that appeared at this step (reported once).
    pub new_fault: Option<HeaterFault>,
}

/// A reference reading of a watch: when and at what temperature it started.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Mark {
    t_s: f32,
    temp_c: f32,
}

#[derive(Debug, Clone)]
pub struct Heater {
    cfg: HeaterConfig,
    target: Option<HeaterSetpoint>,
    /// The ramped setpoint the PID follows.
    ramp_c: f32,
    integral: f32,
    last_temp: Option<f32>,
    duty: f32,
    fault: Option<HeaterFault>,
    /// Consecutive bad reads.
    bad: u8,
    last_bad: Option<BadRead>,
    temp_c: f32,
    /// Time since start, s (sum of the steps' dt).
    t_s: f32,
    /// Heating watch: the last time the plate made its gain.
    watch: Option<Mark>,
    /// Runaway watch: the lowest reading of the current period while no heat is wanted.
    rest: Option<Mark>,
}

impl Heater {
    pub fn new(cfg: HeaterConfig) -> Self {
        Heater {
            cfg,
            target: None,
            ramp_c: f32::NAN,
            integral: 0.0,
            last_temp: None,
            duty: 0.0,
            fault: None,
            bad: 0,
            last_bad: None,
            temp_c: f32::NAN,
            t_s: 0.0,
            watch: None,
            rest: None,
        }
    }

    /// Regulates to `sp` (validated by the caller) from now on; clears a latched fault (it comes back
    /// at the next step if its cause is still there).
    pub fn set(&mut self, sp: HeaterSetpoint) {
        if self.target.is_none() || self.fault.is_some() {
            self.ramp_c = self.temp_c;
            self.integral = 0.0;
        }
        self.target = Some(sp);
        self.fault = None;
        self.bad = 0;
        self.watch = None;
        self.rest = None;
    }

    /// Heater off (and a latched fault cleared, see [`Heater::set`]).
    pub fn off(&mut self) {
        self.target = None;
        self.fault = None;
        self.duty = 0.0;
        self.integral = 0.0;
        self.watch = None;
        self.rest = None;
    }

    pub fn setpoint(&self) -> Option<f32> {
        self.target.map(|t| t.setpoint_c)
    }

    /// The setpoint being regulated to, with its ramp.
    pub fn target(&self) -> Option<HeaterSetpoint> {
        self.target
    }

    /// Whether the heater is asked to heat (a setpoint, no fault).
    pub fn heating(&self) -> bool {
        self.target.is_some() && self.fault.is_none()
    }

    pub fn duty(&self) -> f32 {
        self.duty
    }

    pub fn fault(&self) -> Option<HeaterFault> {
        self.fault
    }

    /// The last read the thermocouple check refused, if the latest read was bad.
    pub fn last_bad_read(&self) -> Option<BadRead> {
        self.last_bad.filter(|_| self.bad > 0)
    }

    /// Latest good temperature (NaN before the first one and once the thermocouple faulted).
    pub fn temp_c(&self) -> f32 {
        self.temp_c
    }

    /// No fault and a temperature known.
    pub fn healthy(&self) -> bool {
        self.fault.is_none() && self.temp_c.is_finite()
    }

    /// One controller step with the latest read, `dt_s` after the previous one. Returns the duty to
    /// apply (0 when off, faulted, or the read is not trusted).
    pub fn step(&mut self, read: Result<Reading, BadRead>, dt_s: f32) -> HeaterStep {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s.min(10.0)
        } else {
            0.0
        };
        self.t_s += dt;
        let lim = self.cfg.limits;
        let detected = match read {
            Err(bad) => {
                self.bad = self.bad.saturating_add(1);
                self.last_bad = Some(bad);
                if self.bad >= lim.bad_reads.max(1) && self.t_s >= lim.startup_grace_s {
                    self.temp_c = f32::NAN;
                    self.watch = None;
                    self.rest = None;
                    Some(bad.fault())
                } else {
                    None
                }
            }
            Ok(r) => {
                self.bad = 0;
                self.temp_c = r.plate_c;
                self.watches(dt)
            }
        };
        let mut new_fault = None;
        if let Some(f) = detected {
            if self.fault.is_none() {
                new_fault = Some(f);
            }
            self.fault = Some(f);
        }
        self.duty = match (self.fault, self.target) {
            (None, Some(_)) if self.bad == 0 && self.temp_c.is_finite() => self.pid(dt),
            (None, Some(_)) if self.bad > 0 => 0.0,
            _ => {
                self.integral = 0.0;
                0.0
            }
        };
        self.last_temp = Some(self.temp_c).filter(|t| t.is_finite());
        HeaterStep {
            duty: self.duty,
            new_fault,
        }
    }

    /// Over-temperature, the heating watch and the runaway watch, on a good reading; moves the ramp.
    fn watches(&mut self, dt: f32) -> Option<HeaterFault> {
        let lim = self.cfg.limits;
        let t = self.temp_c;
        if t > lim.cutoff_c {
            return Some(HeaterFault::OverTemperature);
        }
        let now = self.t_s;
        let mut wants_heat = false;
        let mut lagging = false;
        if let (None, Some(sp)) = (self.fault, self.target) {
            // Ramp the internal setpoint towards the target at the allowed rate.
            if !self.ramp_c.is_finite() {
                self.ramp_c = t;
            }
            let max_step = sp.ramp_c_per_min / 60.0 * dt;
            let gap = sp.setpoint_c - self.ramp_c;
            self.ramp_c += gap.clamp(-max_step, max_step);
            lagging = t < self.ramp_c - lim.band_c;
            wants_heat = t <= self.ramp_c + lim.band_c;
        }
        // Heating watch.
        if lagging {
            let m = *self.watch.get_or_insert(Mark {
                t_s: now,
                temp_c: t,
            });
            if t >= m.temp_c + lim.watch_gain_c {
                self.watch = Some(Mark {
                    t_s: now,
                    temp_c: t,
                });
            } else if now - m.t_s > lim.watch_period_s {
                return Some(HeaterFault::HeatingFailed);
            }
        } else {
            self.watch = None;
        }
        // Runaway watch.
        if wants_heat {
            self.rest = None;
        } else {
            let m = self.rest.get_or_insert(Mark {
                t_s: now,
                temp_c: t,
            });
            if now - m.t_s > lim.watch_period_s {
                // A new period starts from the current reading.
                *m = Mark {
                    t_s: now,
                    temp_c: t,
                };
            } else if t < m.temp_c {
                m.temp_c = t;
            }
            if t > m.temp_c + lim.runaway_rise_c {
                return Some(HeaterFault::Runaway);
            }
        }
        None
    }

    fn pid(&mut self, dt: f32) -> f32 {
        let t = self.temp_c;
        if !self.ramp_c.is_finite() {
            self.ramp_c = t;
        }
        let err = self.ramp_c - t;
        let deriv = match self.last_temp {
            Some(prev) if dt > 0.0 => (t - prev) / dt,
            _ => 0.0,
        };
        let p = self.cfg.kp * err - self.cfg.kd * deriv;
        let max = self.cfg.max_duty.clamp(0.0, 1.0);
        // Anti-windup by conditional integration: integrate only when the output is not pushed
        // further into saturation by it, and keep the integral term itself within the output range.
        let unsat = p + self.integral;
        let pushing_high = unsat >= max && err > 0.0;
        let pushing_low = unsat <= 0.0 && err < 0.0;
        if !pushing_high && !pushing_low {
            self.integral = (self.integral + self.cfg.ki * err * dt).clamp(0.0, max);
        }
        (p + self.integral).clamp(0.0, max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// First-order plant: C dT/dt = P duty − (T − T_amb)/R, integrated exactly over each step.
    struct Plant {
        t: f32,
        amb: f32,
        power_w: f32,
        r_k_per_w: f32,
        c_j_per_k: f32,
        /// The heater's switch is stuck on: full power whatever the duty.
        stuck_on: bool,
    }
    impl Plant {
        fn step(&mut self, duty: f32, dt: f32) {
            let duty = if self.stuck_on { 1.0 } else { duty };
            let t_inf = self.amb + self.power_w * duty * self.r_k_per_w;
            let a = (-dt / (self.r_k_per_w * self.c_j_per_k)).exp();
            self.t = t_inf + (self.t - t_inf) * a;
        }
    }

    fn plant() -> Plant {
        Plant {
            t: 22.0,
            amb: 22.0,
            power_w: 30.0,
            r_k_per_w: 4.0,
            c_j_per_k: 20.0,
            stuck_on: false,
        }
    }

    fn ok(t: f32) -> Result<Reading, BadRead> {
        Ok(Reading {
            plate_c: t,
            cold_junction_c: 25.0,
        })
    }

    fn sp(setpoint_c: f32, ramp_c_per_min: f32) -> HeaterSetpoint {
        HeaterSetpoint {
            setpoint_c,
            ramp_c_per_min,
        }
    }

    /// Runs heater and plant in 100 ms steps for `secs`; returns the first new fault and when (s).
    fn run(h: &mut Heater, p: &mut Plant, secs: f32) -> Option<(HeaterFault, f32)> {
        let dt = 0.1;
        for i in 0..(secs / dt) as usize {
            let s = h.step(ok(p.t), dt);
            assert!((0.0..=1.0).contains(&s.duty));
            p.step(s.duty, dt);
            if let Some(f) = s.new_fault {
                assert_eq!(s.duty, 0.0, "a fault step drives the heater");
                return Some((f, (i + 1) as f32 * dt));
            }
        }
        None
    }

    #[test]
    fn regulates_to_setpoint_following_the_ramp() {
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        h.step(ok(p.t), 0.1);
        h.set(sp(60.0, 10.0));
        let dt = 0.1;
        let mut max_t = 0.0f32;
        for i in 0..(20 * 60 * 10) {
            let s = h.step(ok(p.t), dt);
            assert!(s.new_fault.is_none());
            assert!((0.0..=1.0).contains(&s.duty));
            p.step(s.duty, dt);
            max_t = max_t.max(p.t);
            // During the ramp (38 K at 10 K/min ≈ 228 s) the plate must not run ahead of the ramp.
            let t_s = i as f32 * dt;
            if t_s < 200.0 {
                assert!(
                    p.t < 22.0 + 10.0 / 60.0 * t_s + 1.0,
                    "ahead of the ramp at {t_s} s: {}",
                    p.t
                );
            }
        }
        assert!((p.t - 60.0).abs() < 0.1, "settled at {}", p.t);
        assert!(max_t < 61.5, "overshoot to {max_t}");
    }

    #[test]
    fn anti_windup_limits_overshoot_after_long_saturation() {
        // A setpoint out of reach for a while (heater power cut to a third), then the power comes back:
        // without anti-windup the integral would be huge and overshoot far. The heating watch would
        // (rightly) call a heater that cannot reach its setpoint faulty: it is off for this test.
        let mut cfg = HeaterConfig::default();
        cfg.limits.watch_period_s = f32::INFINITY;
        let mut h = Heater::new(cfg);
        let mut p = plant();
        h.step(ok(p.t), 0.1);
        h.set(sp(80.0, 30.0));
        p.power_w = 10.0; // at most 62 °C
        for _ in 0..(600 * 10) {
            let s = h.step(ok(p.t), 0.1);
            p.step(s.duty, 0.1);
        }
        assert!(p.t < 63.0);
        p.power_w = 30.0;
        let mut max_t = 0.0f32;
        for _ in 0..(900 * 10) {
            let s = h.step(ok(p.t), 0.1);
            p.step(s.duty, 0.1);
            max_t = max_t.max(p.t);
        }
        assert!(max_t < 82.0, "overshoot to {max_t} after saturation");
        assert!((p.t - 80.0).abs() < 0.2);
    }

    #[test]
    fn over_temperature_cuts_off_and_latches() {
        let mut h = Heater::new(HeaterConfig::default());
        h.step(ok(100.0), 0.1);
        h.set(sp(100.0, 30.0));
        assert!(h.step(ok(100.0), 0.1).duty >= 0.0);
        let s = h.step(ok(110.5), 0.1);
        assert_eq!(s.duty, 0.0);
        assert_eq!(s.new_fault, Some(HeaterFault::OverTemperature));
        // Back below the cut-off: still off, fault still reported but not as new.
        let s = h.step(ok(90.0), 0.1);
        assert_eq!((s.duty, s.new_fault), (0.0, None));
        assert_eq!(h.fault(), Some(HeaterFault::OverTemperature));
        assert!(!h.healthy());
        // A new setpoint clears it; the heater works again.
        h.set(sp(100.0, 30.0));
        let s = h.step(ok(90.0), 0.1);
        assert!(s.duty > 0.0 && s.new_fault.is_none());
    }

    #[test]
    fn a_bad_read_cuts_the_heater_at_once_and_repeated_ones_latch_their_fault() {
        for (bad, f) in [
            (BadRead::Open, HeaterFault::OpenThermocouple),
            (BadRead::OverUnderVoltage, HeaterFault::ShortedThermocouple),
            (BadRead::AllZero, HeaterFault::BadConverterData),
            (BadRead::AllOnes, HeaterFault::BadConverterData),
            (
                BadRead::ColdJunctionImplausible(60.0),
                HeaterFault::ColdJunction,
            ),
            (BadRead::Missing { age_ms: 400 }, HeaterFault::NoReading),
        ] {
            let mut h = Heater::new(HeaterConfig::default());
            // Past the start-up grace.
            h.step(ok(30.0), 2.0);
            h.set(sp(90.0, 30.0));
            assert!(h.step(ok(30.0), 0.1).duty > 0.0);
            for _ in 1..limits::TC_BAD_READS {
                let s = h.step(Err(bad), 0.1);
                assert_eq!((s.duty, s.new_fault), (0.0, None), "{bad:?}");
                assert_eq!(h.last_bad_read(), Some(bad));
            }
            let s = h.step(Err(bad), 0.1);
            assert_eq!((s.duty, s.new_fault), (0.0, Some(f)), "{bad:?}");
            assert!(h.temp_c().is_nan());
            // A new setpoint while the fault is still there: it comes back after as many reads.
            h.set(sp(90.0, 30.0));
            let faults: Vec<_> = (0..limits::TC_BAD_READS)
                .map(|_| h.step(Err(bad), 0.1))
                .collect();
            assert!(faults.iter().all(|s| s.duty == 0.0));
            assert_eq!(faults.last().unwrap().new_fault, Some(f));
        }
        // One glitch among good reads is no fault, and heating resumes after it.
        let mut h = Heater::new(HeaterConfig::default());
        h.step(ok(30.0), 0.1);
        h.set(sp(90.0, 30.0));
        for i in 0..100 {
            let r = if i % 2 == 0 {
                Err(BadRead::AllOnes)
            } else {
                ok(30.0)
            };
            let s = h.step(r, 0.1);
            assert_eq!(s.new_fault, None);
            assert_eq!(s.duty > 0.0, i % 2 == 1);
        }
    }

    #[test]
    fn bad_reads_at_start_up_wait_for_the_converter_then_count() {
        let lim = ThermalLimits::default();
        // A converter that is still converting its first reading: no fault.
        let mut h = Heater::new(HeaterConfig::default());
        assert_eq!(h.step(Err(BadRead::StuckWord), 0.0).new_fault, None);
        assert_eq!(h.step(Err(BadRead::StuckWord), 0.1).new_fault, None);
        assert_eq!(h.step(Err(BadRead::StuckWord), 0.1).new_fault, None);
        assert_eq!(h.step(ok(23.0), 0.1).new_fault, None);
        assert_eq!(h.fault(), None);
        // One that never answers: the fault at the end of the grace.
        let mut h = Heater::new(HeaterConfig::default());
        let mut t = 0.0;
        let at = loop {
            let s = h.step(Err(BadRead::Missing { age_ms: u32::MAX }), 0.1);
            assert_eq!(s.duty, 0.0);
            if s.new_fault.is_some() {
                break t;
            }
            t += 0.1;
            assert!(t < 5.0);
        };
        assert!((at - lim.startup_grace_s).abs() < 0.15, "{at}");
        assert_eq!(h.fault(), Some(HeaterFault::NoReading));
    }

    #[test]
    fn a_heater_that_does_not_heat_fails_the_watch() {
        let lim = ThermalLimits::default();
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        p.power_w = 0.0;
        h.step(ok(p.t), 0.1);
        h.set(sp(60.0, 10.0));
        let (f, at) = run(&mut h, &mut p, 300.0).expect("a fault");
        assert_eq!(f, HeaterFault::HeatingFailed);
        // The ramp leaves the band after band / rate, then the watch period runs out.
        let expect = lim.band_c / (10.0 / 60.0) + lim.watch_period_s;
        assert!((at - expect).abs() <= 0.5, "{at} s, expected {expect} s");
        // The thermocouple falls off the plate at setpoint: it reads the room, the heater runs flat
        // out and the reading does not follow.
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        h.step(ok(p.t), 0.1);
        h.set(sp(60.0, 30.0));
        assert_eq!(run(&mut h, &mut p, 600.0), None);
        let mut stuck = plant();
        stuck.power_w = 0.0;
        let (f, at) = run(&mut h, &mut stuck, 300.0).expect("a fault");
        assert_eq!(f, HeaterFault::HeatingFailed);
        assert!(at <= lim.watch_period_s + 1.0, "{at} s");
    }

    #[test]
    fn a_weak_heater_reaching_its_setpoint_slowly_is_not_a_fault() {
        // At full power this plate reaches 102 °C: the last degrees come slowly.
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        p.power_w = 20.0;
        h.step(ok(p.t), 0.1);
        h.set(sp(100.0, 10.0));
        assert_eq!(run(&mut h, &mut p, 1800.0), None);
        assert!((p.t - 100.0).abs() < 0.3, "{}", p.t);
    }

    #[test]
    fn a_heater_stuck_on_is_a_runaway_whether_off_or_at_setpoint() {
        let lim = ThermalLimits::default();
        // Off: the plate warms by itself.
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        p.stuck_on = true;
        let (f, at) = run(&mut h, &mut p, 60.0).expect("a fault");
        assert_eq!(f, HeaterFault::Runaway);
        assert!(
            p.t < 22.0 + lim.runaway_rise_c + 0.5,
            "caught at {} °C",
            p.t
        );
        assert!(at < 5.0, "{at} s");
        // At setpoint: regulated first, then the switch sticks.
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        h.step(ok(p.t), 0.1);
        h.set(sp(50.0, 30.0));
        assert_eq!(run(&mut h, &mut p, 400.0), None);
        assert!((p.t - 50.0).abs() < 0.2);
        p.stuck_on = true;
        let (f, _) = run(&mut h, &mut p, 120.0).expect("a fault");
        assert_eq!(f, HeaterFault::Runaway);
        assert!(
            p.t <= 50.0 + lim.band_c + lim.runaway_rise_c + 0.5,
            "caught at {} °C",
            p.t
        );
    }

    #[test]
    fn cooling_down_and_a_warming_room_are_not_runaways() {
        // Heated to 90 °C at full speed, then switched off: it cools, no fault.
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        h.step(ok(p.t), 0.1);
        h.set(sp(90.0, 30.0));
        assert_eq!(run(&mut h, &mut p, 600.0), None);
        h.off();
        assert_eq!(run(&mut h, &mut p, 600.0), None);
        // A setpoint lowered from 90 to 40: the plate is above the band while it cools.
        h.set(sp(90.0, 30.0));
        assert_eq!(run(&mut h, &mut p, 600.0), None);
        h.set(sp(40.0, 30.0));
        assert_eq!(run(&mut h, &mut p, 900.0), None);
        assert!((p.t - 40.0).abs() < 0.3);
        // The room warms by 4 °C in ten minutes with the heater off.
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        for _ in 0..6000 {
            p.amb += 4.0 / 6000.0;
            let s = h.step(ok(p.t), 0.1);
            assert_eq!(s.new_fault, None);
            p.step(s.duty, 0.1);
        }
    }
}
