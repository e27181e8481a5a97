//! Fail-safe: lease, safe command, boot report, magnet cool-down, stand-alone mode.

use super::*;

fn fault_reports(msgs: &[DeviceMsg]) -> Vec<FaultReport> {
    msgs.iter()
        .filter_map(|m| match m {
            DeviceMsg::Fault(f) => Some(*f),
            _ => None,
        })
        .collect()
}

impl Bench {
    /// Heating to 60 °C (the plate at 25 °C) and armed (magnet holding), the host's last frame now.
    fn heating_and_armed(&mut self) {
        let sp = HeaterSetpoint {
            setpoint_c: 60.0,
            ramp_c_per_min: 10.0,
        };
        assert_eq!(self.command(HostMsg::SetHeater(sp)).0, Ok(()));
        self.run_for(300);
        self.ready();
        assert!(self.hw.heater_duty > 0.0);
        assert!(matches!(self.hw.magnet(), MagnetDrive::Hold { .. }));
        self.take();
        assert_eq!(self.command(HostMsg::Heartbeat).0, Ok(()));
    }
}

#[test]
fn host_silence_while_heating_and_holding_makes_the_rig_safe_and_says_why() {
    let mut b = Bench::new();
    b.heating_and_armed();
    let last = b.hw.now_us;
    assert_eq!(b.app.control(), Control::Host);
    // Up to the lease, all on.
    b.run_for(limits::HOST_LEASE_MS as u64);
    assert!(b.hw.heater_duty > 0.0);
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    assert!(faults(&b.msgs()).is_empty());
    // The first poll past it: safe, then the fault frame.
    let period = b.app.cfg.poll_period_us as u64;
    b.hw.now_us += period;
    b.poll();
    assert_eq!(
        b.hw.now_us - last,
        limits::HOST_LEASE_MS as u64 * 1000 + period
    );
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(!b.hw.adc.is_running());
    let f = fault_reports(&b.msgs());
    assert_eq!(f.len(), 1);
    assert_eq!(f[0].reason, FaultReason::LeaseExpired);
    assert_eq!(f[0].uptime_ms, b.hw.now_us / 1000);
    assert_eq!(f[0].temp_c, 25.0);
    // Told once; the status keeps it; nothing heats until a host sets a setpoint again.
    b.run_for(5_000);
    assert!(fault_reports(&b.msgs()).is_empty());
    assert_eq!(b.hw.heater_duty, 0.0);
    let st = b.app.status();
    assert_eq!((st.last_fault, st.faults), (Some(f[0]), 1));
    assert_eq!(st.heater_setpoint_c, None);
    assert!(!st.magnet_on);
    assert_eq!(st.state, RigState::Configured);
    assert_eq!(st.control, Control::None);
    // Idle, a silent host is no fault.
    let mut b = Bench::new();
    b.run_for(10_000);
    assert!(faults(&b.msgs()).is_empty());
}

#[test]
fn heartbeats_and_any_command_keep_the_lease() {
    let mut b = Bench::new();
    b.heating_and_armed();
    b.app.cfg.release.hold_limit_us = 60_000_000;
    for i in 0..20 {
        b.run_for(limits::HEARTBEAT_MS as u64);
        let cmd = if i % 2 == 0 {
            HostMsg::Heartbeat
        } else {
            // A command that acts (here refused: the rig is armed) renews it too.
            HostMsg::Configure(Configure::real_rig(0.3))
        };
        b.send(cmd);
    }
    assert!(faults(&b.msgs()).is_empty());
    assert!(b.hw.heater_duty > 0.0);
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    // Garbage on the line is no sign of a live host.
    for _ in 0..4 {
        b.run_for(limits::HEARTBEAT_MS as u64);
        let now = b.hw.now_us;
        b.app.on_bytes(&mut b.hw, &[1, 2, 3, 0], now);
    }
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    // Nor is a program that only looks: status polls (and hellos, pulls) do not hold the rig.
    let mut b = Bench::new();
    b.heating_and_armed();
    for i in 0..4 {
        b.run_for(limits::HEARTBEAT_MS as u64);
        b.send(if i % 2 == 0 {
            HostMsg::Status
        } else {
            HostMsg::Hello {
                protocol: PROTOCOL_VERSION,
            }
        });
    }
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    assert_eq!(b.hw.heater_duty, 0.0);
}

#[test]
fn the_safe_command_turns_everything_off_at_once() {
    let mut b = Bench::new();
    b.heating_and_armed();
    let (r, msgs) = b.command(HostMsg::Safe);
    assert_eq!(r, Ok(()));
    // Within the same call that read the command: no poll needed.
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(!b.hw.adc.is_running());
    assert!(faults(&msgs).is_empty(), "asked for, not a fault");
    b.run_for(10_000);
    assert!(faults(&b.msgs()).is_empty());
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.app.status().heater_setpoint_c, None);
    // During a run: the run goes on recording.
    let mut b = Bench::new();
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(50);
    assert_eq!(b.command(HostMsg::Safe).0, Ok(()));
    assert_eq!(b.app.state(), RigState::Running);
    b.run_for(100);
    assert!(b.msgs().iter().any(is_block));
}

#[test]
fn the_boot_report_goes_to_the_first_hello_and_the_cause_stays_in_the_status() {
    let mut b = Bench::new();
    let mut msg = heapless::String::new();
    msg.push_str("panicked at src/heater.rs:1:1: boom").unwrap();
    b.app.set_boot_report(BootReport {
        cause: ResetCause::Panic,
        message: msg.clone(),
    });
    // The link refuses frames: kept for the next hello.
    b.hw.connected = false;
    b.send(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    b.hw.connected = true;
    let (r, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    assert_eq!(r, Ok(()));
    assert!(matches!(msgs[0], DeviceMsg::Hello(_)));
    assert_eq!(
        msgs[1],
        DeviceMsg::Boot(BootReport {
            cause: ResetCause::Panic,
            message: msg
        })
    );
    let (_, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    assert!(!msgs.iter().any(|m| matches!(m, DeviceMsg::Boot(_))));
    assert_eq!(b.app.status().reset_cause, ResetCause::Panic);
}

#[test]
fn an_empty_hold_budget_cuts_the_coil_and_arming_waits_for_the_cool_down() {
    let mut b = Bench::new();
    b.app.cfg.release.hold_limit_us = 2_000_000;
    b.app.release = Release::new(b.app.cfg.release);
    b.ready();
    b.take();
    b.run_for(2_100);
    let f = fault_reports(&b.msgs());
    assert_eq!(f.len(), 1);
    assert_eq!(f[0].reason, FaultReason::MagnetHoldTime);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    // Half the budget (1 s) back at 50 % duty: 1 s of rest from the cut, 2 s after arming, which
    // was 50 + 2100 ms ago.
    match b.command(HostMsg::Arm).0 {
        Err(ErrorCode::MagnetCooling { wait_ms }) => assert_eq!(wait_ms, 850),
        r => panic!("{r:?}"),
    }
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    b.run_for(1_000);
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
}

#[test]
fn stand_alone_mode_arms_on_a_long_press_with_its_own_limits() {
    let mut b = Bench::new();
    // Stand-alone heating for 45 s after each press (30 min on the rig), longer than the hold limit.
    b.app.cfg.standalone_heat_ms = 45_000;
    b.app.lease = crate::lease::Lease::new(b.app.cfg.host_lease_ms, 45_000);
    b.heating_and_armed();
    assert_eq!(b.command(HostMsg::Disarm).0, Ok(()));
    // The host goes away: safe.
    b.run_for(limits::HOST_LEASE_MS as u64 + 10);
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    assert_eq!(b.hw.heater_duty, 0.0);
    // A short press does not arm.
    b.hw.button = true;
    b.run_for(500);
    b.hw.button = false;
    b.run_for(100);
    assert_eq!(b.app.state(), RigState::Configured);
    // A long press does: magnet on, heating again to the host's last setpoint.
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    b.run_for(200);
    assert_eq!(b.app.state(), RigState::Armed);
    assert_eq!(b.app.control(), Control::StandAlone);
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    assert_eq!(b.app.status().heater_setpoint_c, Some(60.0));
    assert!(b.hw.heater_duty > 0.0);
    // Not released: the magnet holds at most the stand-alone limit (armed 210 ms ago).
    b.take();
    b.run_for(limits::STANDALONE_HOLD_MS as u64 - 220);
    let f = faults(&b.msgs());
    assert!(f.is_empty(), "{f:?}");
    b.run_for(20);
    assert_eq!(faults(&b.msgs()), vec![FaultReason::MagnetHoldTime]);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(
        b.hw.heater_duty > 0.0,
        "the heater runs on, within its own limit"
    );
    // Long press again, then a short one releases: a run, like with a host.
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    b.run_for(100);
    assert_eq!(b.app.state(), RigState::Armed);
    let press_at = b.hw.now_us;
    b.hw.button = true;
    b.run_for(30);
    b.hw.button = false;
    assert_eq!(b.app.state(), RigState::Running);
    b.run_for(1_000);
    // 45 s after the last press, the heater goes off and the fault says why.
    b.take();
    b.run_for(45_000 - (b.hw.now_us - press_at) / 1000 - 10);
    assert!(faults(&b.msgs()).is_empty());
    assert!(b.hw.heater_duty > 0.0);
    b.run_for(40);
    let f = faults(&b.msgs());
    assert_eq!(f, vec![FaultReason::StandAloneExpired]);
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.app.control(), Control::None);
}

#[test]
fn a_host_takes_over_stand_alone_mode_and_a_held_rig_ignores_long_presses() {
    let mut b = Bench::new();
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Ok(())
    );
    // Held by a host: a long press does nothing.
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    assert_eq!(b.app.state(), RigState::Configured);
    b.run_for(limits::HOST_LEASE_MS as u64 + 10);
    b.hw.button = true;
    b.run_for(limits::STANDALONE_PRESS_MS as u64 + 10);
    b.hw.button = false;
    assert_eq!(b.app.state(), RigState::Armed);
    assert_eq!(b.app.control(), Control::StandAlone);
    b.send(HostMsg::Status);
    assert_eq!(
        b.app.control(),
        Control::StandAlone,
        "a look does not take over"
    );
    b.send(HostMsg::Heartbeat);
    assert_eq!(b.app.control(), Control::Host);
    // The host now holds it, under its lease: silent, the magnet goes off.
    b.take();
    b.run_for(limits::HOST_LEASE_MS as u64 + 10);
    assert_eq!(faults(&b.msgs()), vec![FaultReason::LeaseExpired]);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
}
