//! Who may keep the rig heating and the magnet holding.
//!
//! * **A host**, while it holds a lease: every command it sends that acts on the rig, and
//!   [`crate::wire::HostMsg::Heartbeat`], renews it for [`limits::HOST_LEASE_MS`] ([`renews`]). A
//!   host that dies, hangs or loses its cable stops renewing; the application then drives heater and
//!   magnet safe and says why ([`FaultReason::LeaseExpired`]). Queries (`Hello`, `Status`, `Pull`,
//!   `PullBlocks`) do not renew it: a second program that only looks at a rig whose host died (a
//!   status poller, `tribo status`) must not keep it heating.
//! * **The technician at the rig** (stand-alone mode, button only): a long press
//!   ([`limits::STANDALONE_PRESS_MS`]) on an idle, configured rig that no host holds. Each press
//!   renews it for [`limits::STANDALONE_HEAT_MS`]; then the outputs go safe
//!   ([`FaultReason::StandAloneExpired`]). A host that speaks takes over.
//! * **Nobody**: nothing may heat or hold.

use crate::wire::{limits, Control, FaultReason, HostMsg};

/// Whether a frame from the host renews its lease: commands that act on the rig and heartbeats do,
/// queries do not.
pub fn renews(msg: &HostMsg) -> bool {
    !matches!(
        msg,
        HostMsg::Hello { .. }
            | HostMsg::Status
            | HostMsg::Pull { .. }
            | HostMsg::PullBlocks { .. }
            | HostMsg::RunFloor { .. }
    )
}

/// The lease bookkeeping (times in µs of device time).
#[derive(Debug, Clone, PartialEq)]
pub struct Lease {
    host_us: u64,
    standalone_us: u64,
    /// Last frame from a host.
    last_host_us: Option<u64>,
    /// Last button press in stand-alone mode (`None`: not stand-alone).
    last_press_us: Option<u64>,
}

impl Lease {
    /// A lease of `host_ms` for hosts and `standalone_ms` per press in stand-alone mode.
    pub fn new(host_ms: u32, standalone_ms: u32) -> Self {
        Lease {
            host_us: host_ms as u64 * 1000,
            standalone_us: standalone_ms as u64 * 1000,
            last_host_us: None,
            last_press_us: None,
        }
    }

    /// Changes the host lease (a virtual rig running faster than real time stretches it so that a
    /// real-time host keeps it).
    pub fn set_host_ms(&mut self, host_ms: u32) {
        self.host_us = host_ms as u64 * 1000;
    }

    /// A frame from the host arrived: the host holds the rig (and ends stand-alone mode).
    pub fn renew(&mut self, now_us: u64) {
        self.last_host_us = Some(now_us);
        self.last_press_us = None;
    }

    /// Enters stand-alone mode (or renews it with a press).
    pub fn press(&mut self, now_us: u64) {
        self.last_press_us = Some(now_us);
    }

    /// Who holds the rig now.
    pub fn control(&self, now_us: u64) -> Control {
        let within = |t: Option<u64>, d: u64| t.is_some_and(|t| now_us.saturating_sub(t) <= d);
        if self.last_press_us.is_some() {
            if within(self.last_press_us, self.standalone_us) {
                Control::StandAlone
            } else {
                Control::None
            }
        } else if within(self.last_host_us, self.host_us) {
            Control::Host
        } else {
            Control::None
        }
    }

    /// Time since the host's last frame, µs (`None` before any).
    pub fn host_silence_us(&self, now_us: u64) -> Option<u64> {
        self.last_host_us.map(|t| now_us.saturating_sub(t))
    }

    /// Whether outputs that `need` a holder (heating, holding) must go safe now, and why. Once it
    /// has said so, stand-alone mode is over.
    pub fn expired(&mut self, now_us: u64, need: bool) -> Option<FaultReason> {
        if !need || self.control(now_us) != Control::None {
            return None;
        }
        if self.last_press_us.take().is_some() {
            Some(FaultReason::StandAloneExpired)
        } else {
            Some(FaultReason::LeaseExpired)
        }
    }
}

impl Default for Lease {
    fn default() -> Self {
        Lease::new(limits::HOST_LEASE_MS, limits::STANDALONE_HEAT_MS)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_host_holds_the_rig_for_its_lease_after_each_frame() {
        let mut l = Lease::new(3_000, 60_000);
        assert_eq!(l.control(0), Control::None);
        assert_eq!(l.expired(0, false), None);
        assert_eq!(l.expired(0, true), Some(FaultReason::LeaseExpired));
        l.renew(1_000_000);
        assert_eq!(l.control(4_000_000), Control::Host);
        assert_eq!(l.expired(4_000_000, true), None);
        assert_eq!(l.control(4_000_001), Control::None);
        assert_eq!(l.expired(4_000_001, false), None, "nothing to make safe");
        assert_eq!(l.expired(4_000_001, true), Some(FaultReason::LeaseExpired));
        assert_eq!(l.host_silence_us(4_000_001), Some(3_000_001));
        l.renew(5_000_000);
        assert_eq!(l.control(5_000_000), Control::Host);
    }

    #[test]
    fn stand_alone_lasts_its_own_time_per_press_and_a_host_takes_over() {
        let mut l = Lease::new(3_000, 60_000);
        l.renew(0);
        l.press(10_000_000);
        assert_eq!(l.control(10_000_000), Control::StandAlone);
        assert_eq!(l.control(69_000_000), Control::StandAlone);
        l.press(69_000_000);
        assert_eq!(l.expired(129_000_000, true), None);
        assert_eq!(
            l.expired(129_000_001, true),
            Some(FaultReason::StandAloneExpired)
        );
        // Said once: then it is a plain unattended rig.
        assert_eq!(l.control(129_000_001), Control::None);
        assert_eq!(
            l.expired(129_000_002, true),
            Some(FaultReason::LeaseExpired)
        );
        l.press(200_000_000);
        l.renew(200_000_001);
        assert_eq!(l.control(200_000_002), Control::Host);
        assert_eq!(l.control(203_000_002), Control::None);
    }
}
