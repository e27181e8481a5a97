//! The heater of the plane: PID on the thermocouple to a host setpoint, with a setpoint ramp,
//! anti-windup, and a hard cut-off above 110 °C or on any thermocouple fault.
//!
//! A fault switches the heater off and stays latched until the host sends a new setpoint or
//! `HeaterOff` *and* the fault condition has gone (checked at the next reading).

use crate::hal::ThermocoupleFault;
use crate::wire::{limits, HeaterFault, HeaterSetpoint};

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
    /// Consecutive converter failures before [`HeaterFault::NoReading`].
    pub misses_for_fault: u8,
}

impl Default for HeaterConfig {
    fn default() -> Self {
        HeaterConfig {
            kp: 0.08,
            ki: 0.002,
            kd: 0.0,
            max_duty: 1.0,
            misses_for_fault: 5,
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
    /// A fault was cleared by a command: re-check before heating again.
    misses: u8,
    temp_c: f32,
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
            misses: 0,
            temp_c: f32::NAN,
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
        self.misses = 0;
    }

    /// Heater off (and a latched fault cleared, see [`Heater::set`]).
    pub fn off(&mut self) {
        self.target = None;
        self.fault = None;
        self.duty = 0.0;
        self.integral = 0.0;
    }

    pub fn setpoint(&self) -> Option<f32> {
        self.target.map(|t| t.setpoint_c)
    }

    pub fn duty(&self) -> f32 {
        self.duty
    }

    pub fn fault(&self) -> Option<HeaterFault> {
        self.fault
    }

    /// Latest good temperature (NaN before the first one).
    pub fn temp_c(&self) -> f32 {
        self.temp_c
    }

    /// No fault and a temperature known.
    pub fn healthy(&self) -> bool {
        self.fault.is_none() && self.temp_c.is_finite()
    }

    /// One controller step with the latest reading, `dt_s` after the previous one. Returns the duty to
    /// apply (0 when off or faulted).
    pub fn step(&mut self, reading: Result<f32, ThermocoupleFault>, dt_s: f32) -> HeaterStep {
        let detected = match reading {
            Ok(t) if !t.is_finite() => self.miss(),
            Ok(t) => {
                self.misses = 0;
                self.temp_c = t;
                if t > limits::HEATER_CUTOFF_C {
                    Some(HeaterFault::OverTemperature)
                } else {
                    None
                }
            }
            Err(ThermocoupleFault::Open) => Some(HeaterFault::OpenThermocouple),
            Err(ThermocoupleFault::Shorted) => Some(HeaterFault::ShortedThermocouple),
            Err(ThermocoupleFault::NoReading) => self.miss(),
        };
        if matches!(
            detected,
            Some(HeaterFault::OpenThermocouple | HeaterFault::ShortedThermocouple)
        ) {
            self.temp_c = f32::NAN;
        }
        let mut new_fault = None;
        if let Some(f) = detected {
            if self.fault.is_none() {
                new_fault = Some(f);
            }
            self.fault = Some(f);
        }
        self.duty = match (self.fault, self.target) {
            (None, Some(sp)) if self.temp_c.is_finite() => self.pid(sp, dt_s),
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

    fn miss(&mut self) -> Option<HeaterFault> {
        self.misses = self.misses.saturating_add(1);
        if self.misses >= self.cfg.misses_for_fault {
            self.temp_c = f32::NAN;
            Some(HeaterFault::NoReading)
        } else {
            None
        }
    }

    fn pid(&mut self, sp: HeaterSetpoint, dt_s: f32) -> f32 {
        let dt = if dt_s.is_finite() && dt_s > 0.0 {
            dt_s.min(10.0)
        } else {
            0.0
        };
        let t = self.temp_c;
        // Ramp the internal setpoint towards the target at the allowed rate.
        if !self.ramp_c.is_finite() {
            self.ramp_c = t;
        }
        let max_step = sp.ramp_c_per_min / 60.0 * dt;
        let gap = sp.setpoint_c - self.ramp_c;
        self.ramp_c += gap.clamp(-max_step, max_step);
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
    }
    impl Plant {
        fn step(&mut self, duty: f32, dt: f32) {
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
        }
    }

    #[test]
    fn regulates_to_setpoint_following_the_ramp() {
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        h.step(Ok(p.t), 0.1);
        h.set(HeaterSetpoint {
            setpoint_c: 60.0,
            ramp_c_per_min: 10.0,
        });
        let dt = 0.1;
        let mut max_t = 0.0f32;
        for i in 0..(20 * 60 * 10) {
            let s = h.step(Ok(p.t), dt);
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
        // without anti-windup the integral would be huge and overshoot far.
        let mut h = Heater::new(HeaterConfig::default());
        let mut p = plant();
        h.step(Ok(p.t), 0.1);
        h.set(HeaterSetpoint {
            setpoint_c: 80.0,
            ramp_c_per_min: 30.0,
        });
        p.power_w = 10.0; // at most 62 °C
        for _ in 0..(600 * 10) {
            let s = h.step(Ok(p.t), 0.1);
            p.step(s.duty, 0.1);
        }
        assert!(p.t < 63.0);
        p.power_w = 30.0;
        let mut max_t = 0.0f32;
        for _ in 0..(900 * 10) {
            let s = h.step(Ok(p.t), 0.1);
            p.step(s.duty, 0.1);
            max_t = max_t.max(p.t);
        }
        assert!(max_t < 82.0, "overshoot to {max_t} after saturation");
        assert!((p.t - 80.0).abs() < 0.2);
    }

    #[test]
    fn over_temperature_cuts_off_and_latches() {
        let mut h = Heater::new(HeaterConfig::default());
        h.step(Ok(100.0), 0.1);
        h.set(HeaterSetpoint {
            setpoint_c: 100.0,
            ramp_c_per_min: 30.0,
        });
        assert!(h.step(Ok(100.0), 0.1).duty >= 0.0);
        let s = h.step(Ok(110.5), 0.1);
        assert_eq!(s.duty, 0.0);
        assert_eq!(s.new_fault, Some(HeaterFault::OverTemperature));
        // Back below the cut-off: still off, fault still reported but not as new.
        let s = h.step(Ok(90.0), 0.1);
        assert_eq!((s.duty, s.new_fault), (0.0, None));
        assert_eq!(h.fault(), Some(HeaterFault::OverTemperature));
        assert!(!h.healthy());
        // A new setpoint clears it; the heater works again.
        h.set(HeaterSetpoint {
            setpoint_c: 100.0,
            ramp_c_per_min: 30.0,
        });
        let s = h.step(Ok(90.0), 0.1);
        assert!(s.duty > 0.0 && s.new_fault.is_none());
    }

    #[test]
    fn open_and_shorted_thermocouple_cut_off_even_when_idle() {
        for (tc, f) in [
            (ThermocoupleFault::Open, HeaterFault::OpenThermocouple),
            (ThermocoupleFault::Shorted, HeaterFault::ShortedThermocouple),
        ] {
            let mut h = Heater::new(HeaterConfig::default());
            h.step(Ok(30.0), 0.1);
            h.set(HeaterSetpoint {
                setpoint_c: 90.0,
                ramp_c_per_min: 30.0,
            });
            assert!(h.step(Ok(30.0), 0.1).duty > 0.0);
            let s = h.step(Err(tc), 0.1);
            assert_eq!((s.duty, s.new_fault), (0.0, Some(f)));
            assert!(h.temp_c().is_nan());
            // A new setpoint while the fault is still there: it comes straight back.
            h.set(HeaterSetpoint {
                setpoint_c: 90.0,
                ramp_c_per_min: 30.0,
            });
            let s = h.step(Err(tc), 0.1);
            assert_eq!((s.duty, s.new_fault), (0.0, Some(f)));
        }
    }

    #[test]
    fn converter_silence_becomes_a_fault_after_several_misses() {
        let mut h = Heater::new(HeaterConfig::default());
        h.step(Ok(30.0), 0.1);
        h.set(HeaterSetpoint {
            setpoint_c: 90.0,
            ramp_c_per_min: 30.0,
        });
        for _ in 0..4 {
            assert_eq!(
                h.step(Err(ThermocoupleFault::NoReading), 0.1).new_fault,
                None
            );
        }
        let s = h.step(Ok(f32::NAN), 0.1);
        assert_eq!((s.duty, s.new_fault), (0.0, Some(HeaterFault::NoReading)));
    }
}
