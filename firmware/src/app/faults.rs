//! The safe state, faults the rig handles by itself, and stand-alone mode.

use super::*;

impl App<'_> {
    /// Drives everything that heats or holds to its safe value: heater off, magnet off, armed state
    /// left. A run in progress goes on recording.
    pub(super) fn make_safe<H: Hardware>(&mut self, hw: &mut H) {
        self.heater.off();
        hw.set_heater_duty(0.0);
        self.release.off(hw, self.now_us);
        if self.state == RigState::Armed {
            hw.adc_stop();
            self.state = RigState::Configured;
        }
    }

    /// Records and reports a fault the rig handled by itself (its outputs are already safe).
    pub(super) fn fault<H: Hardware>(&mut self, hw: &mut H, reason: FaultReason) {
        let report = FaultReport {
            reason,
            uptime_ms: self.now_us / 1000,
            temp_c: self.heater.temp_c(),
        };
        self.last_fault = Some(report);
        self.faults = self.faults.saturating_add(1);
        self.send(hw, &DeviceMsg::Fault(report));
    }

    /// A long press: stand-alone mode on an idle, configured rig that no host holds. The magnet
    /// holds (for at most the stand-alone limit) and the heater goes back to the host's last
    /// setpoint; a short press then releases, as with a host.
    pub(super) fn stand_alone<H: Hardware>(&mut self, hw: &mut H) {
        let now = self.now_us;
        let idle = matches!(self.state, RigState::Configured | RigState::Finished);
        if !idle || self.config.is_none() || self.lease.control(now) == Control::Host {
            return;
        }
        info!("stand-alone mode");
        self.lease.press(now);
        if let Some(sp) = self.last_setpoint {
            if self.heater.target() != Some(sp) || self.heater.fault().is_some() {
                self.heater.set(sp);
            }
        }
        let limit = self.cfg.standalone_hold_ms as u64 * 1000;
        if let Err(code) = self.arm_for(hw, limit) {
            self.error(hw, code, None);
        }
    }
}
