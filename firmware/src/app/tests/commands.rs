//! Commands and their replies: hello, interlocks, the release pulse, the button, refused
//! settings, and bytes or commands at random that never make the application panic.

use super::*;

#[test]
fn hello_is_answered_and_a_wrong_protocol_named() {
    let mut b = Bench::new();
    let (r, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION,
    });
    assert_eq!(r, Ok(()));
    assert!(matches!(
        msgs[0],
        DeviceMsg::Hello(DeviceInfo {
            protocol: PROTOCOL_VERSION,
            serial: 42,
            ..
        })
    ));
    let (r, msgs) = b.command(HostMsg::Hello {
        protocol: PROTOCOL_VERSION + 1,
    });
    assert_eq!(
        r,
        Err(ErrorCode::ProtocolMismatch {
            device: PROTOCOL_VERSION
        })
    );
    assert!(matches!(msgs[0], DeviceMsg::Hello(_)));
}

#[test]
fn release_interlocks_in_order() {
    let mut b = Bench::new();
    assert_eq!(b.command(HostMsg::Release).0, Err(ErrorCode::NotConfigured));
    assert_eq!(b.command(HostMsg::Arm).0, Err(ErrorCode::NotConfigured));
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Ok(())
    );
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::NotArmed))
    );
    // A converter that does not start: armed, but no release.
    b.hw.adc_ok = false;
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::NotSampling))
    );
    assert_eq!(b.command(HostMsg::Disarm).0, Ok(()));
    b.hw.adc_ok = true;
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    // Heater unhealthy: thermocouple open.
    b.hw.tc = Some(bad(crate::thermocouple::sr::OPEN));
    b.run_for(TC_FAULT_MS);
    assert!(faults(&b.msgs()).contains(&FaultReason::Heater(HeaterFault::OpenThermocouple)));
    assert_eq!(b.app.state(), RigState::Fault);
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::HeaterUnhealthy))
    );
    assert!(b.hw.released_at.is_none(), "an interlock let the pin go");
    // Healthy again, cleared by HeaterOff: the release goes through.
    b.hw.tc = Some(reg(25.0));
    assert_eq!(b.command(HostMsg::HeaterOff).0, Ok(()));
    b.run_for(200);
    assert_eq!(b.app.state(), RigState::Armed);
    let (r, msgs) = b.command(HostMsg::Release);
    assert_eq!(r, Ok(()));
    assert_eq!(b.app.state(), RigState::Running);
    b.run_for(10);
    let msgs: Vec<_> = msgs.into_iter().chain(b.msgs()).collect();
    assert!(
        matches!(&msgs[..], [DeviceMsg::Ack { .. }, DeviceMsg::RunStarted(h), ..] if h.run_id == 1)
    );
    assert_eq!(b.command(HostMsg::Release).0, Err(ErrorCode::Busy));
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Err(ErrorCode::Busy)
    );
}

#[test]
fn release_is_hold_then_reverse_pulse_then_off() {
    let mut b = Bench::new();
    b.ready();
    let t_rel = b.hw.now_us;
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(20);
    let d: Vec<_> = b.hw.drives.iter().filter(|(t, _)| *t >= t_rel).collect();
    assert!(
        matches!(d[0], (t, MagnetDrive::Reverse { duty }) if *t == t_rel && *duty > 0.0),
        "{d:?}"
    );
    let off = d
        .iter()
        .find(|(_, m)| *m == MagnetDrive::Off)
        .expect("coil switched off after the pulse");
    let pulse = off.0 - t_rel;
    let cfg = ReleaseConfig::default();
    assert!(
        pulse >= cfg.reverse_us as u64 && pulse <= cfg.reverse_us as u64 + 1000,
        "pulse {pulse} µs"
    );
    assert!(!b.app.status().magnet_on);
}

#[test]
fn hold_time_limit_disarms_and_is_reported() {
    let mut b = Bench::new();
    b.app.cfg.release.hold_limit_us = 2_000_000;
    b.app.release = Release::new(b.app.cfg.release);
    b.ready();
    b.take();
    b.run_for(2_100);
    assert!(faults(&b.msgs()).contains(&FaultReason::MagnetHoldTime));
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert!(
        !b.hw.adc.is_running(),
        "sampling left running after the magnet was cut"
    );
    assert_eq!(
        b.command(HostMsg::Release).0,
        Err(ErrorCode::Interlock(Interlock::NotArmed))
    );
    assert_eq!(b.app.state(), RigState::Configured);
    assert_eq!(
        b.app.run_id(),
        0,
        "no run may start from a coil cut by the hold-time limit"
    );
}

#[test]
fn button_releases_only_when_armed_and_is_debounced() {
    let mut b = Bench::new();
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Ok(())
    );
    b.hw.button = true;
    b.run_for(40);
    b.hw.button = false;
    b.run_for(40);
    let e = b.take();
    assert!(e.iter().any(|f| f.1.msg
        == DeviceMsg::Error(DeviceError {
            code: ErrorCode::Interlock(Interlock::NotArmed),
            about_seq: None
        })));
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    b.run_for(50);
    // A 5 ms glitch is not a press.
    b.hw.button = true;
    b.run_for(5);
    b.hw.button = false;
    b.run_for(30);
    assert_eq!(b.app.state(), RigState::Armed);
    b.hw.button = true;
    b.run_for(30);
    assert_eq!(b.app.state(), RigState::Running);
    assert!(b.hw.released_at.is_some());
}

#[test]
fn out_of_range_commands_are_refused_by_field() {
    let mut b = Bench::new();
    let good = Configure::real_rig(0.3);
    let cases: Vec<(Configure, Field)> = vec![
        (
            Configure {
                rig: crate::wire::RigConstants {
                    mass_kg: 0.0,
                    ..good.rig
                },
                ..good
            },
            Field::Mass,
        ),
        (
            Configure {
                rig: crate::wire::RigConstants {
                    stiffness_n_per_m: f32::NAN,
                    ..good.rig
                },
                ..good
            },
            Field::Stiffness,
        ),
        (
            Configure {
                rig: crate::wire::RigConstants {
                    load_n: 0.9,
                    ..good.rig
                },
                ..good
            },
            Field::Load,
        ),
        (
            Configure {
                sample_rate_hz: 100,
                ..good
            },
            Field::SampleRate,
        ),
        (
            Configure {
                channels: ChannelSet::EMPTY.with(Channel::Force),
                ..good
            },
            Field::Channels,
        ),
        (
            Configure {
                initial_amplitude_m: 2e-3,
                ..good
            },
            Field::InitialAmplitude,
        ),
        (
            Configure {
                max_duration_s: f32::INFINITY,
                ..good
            },
            Field::MaxDuration,
        ),
    ];
    for (c, f) in cases {
        assert_eq!(
            b.command(HostMsg::Configure(c)).0,
            Err(ErrorCode::OutOfRange(f))
        );
    }
    // In range for the wire, but too few samples per cycle for the on-board analysis (1.6 kHz rig
    // sampled at 1 kS/s): refused now, not discovered after the run.
    let fast = Configure {
        rig: crate::wire::RigConstants {
            mass_kg: 1e-3,
            stiffness_n_per_m: 1e5,
            ..good.rig
        },
        sample_rate_hz: 1000,
        ..good
    };
    assert_eq!(
        b.command(HostMsg::Configure(fast)).0,
        Err(ErrorCode::OutOfRange(Field::SampleRate))
    );
    assert_eq!(
        b.app.state(),
        RigState::Idle,
        "a refused Configure changed the state"
    );
    for (sp, f) in [
        (
            HeaterSetpoint {
                setpoint_c: 150.0,
                ramp_c_per_min: 5.0,
            },
            Field::HeaterSetpoint,
        ),
        (
            HeaterSetpoint {
                setpoint_c: f32::NAN,
                ramp_c_per_min: 5.0,
            },
            Field::HeaterSetpoint,
        ),
        (
            HeaterSetpoint {
                setpoint_c: 50.0,
                ramp_c_per_min: 0.0,
            },
            Field::HeaterRamp,
        ),
    ] {
        assert_eq!(
            b.command(HostMsg::SetHeater(sp)).0,
            Err(ErrorCode::OutOfRange(f))
        );
    }
    assert_eq!(b.app.status().heater_setpoint_c, None);
    assert_eq!(
        b.command(HostMsg::Pull {
            run_id: 1,
            from_block: 0
        })
        .0,
        Err(ErrorCode::NoRun)
    );
    // Garbage, a corrupted frame, then a good one: one Malformed each, and the good one still works.
    let mut bad = encode_vec(7, &HostMsg::Status).unwrap();
    bad[3] ^= 0x10;
    b.app.on_bytes(&mut b.hw, &[1, 2, 3, 0], 0);
    b.app.on_bytes(&mut b.hw, &bad, 0);
    let (r, msgs) = b.command(HostMsg::Status);
    assert_eq!(r, Ok(()));
    assert_eq!(errors(&msgs), [ErrorCode::Malformed, ErrorCode::Malformed]);
    assert!(msgs
        .iter()
        .any(|m| matches!(m, DeviceMsg::Status(s) if s.state == RigState::Idle)));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn random_bytes_never_panic_and_every_reply_decodes(chunks in prop::collection::vec(prop::collection::vec(any::<u8>(), 0..300), 1..8)) {
        let mut b = Bench::with_store(16 * 1024);
        b.ready();
        for c in &chunks {
            let now = b.hw.now_us;
            b.app.on_bytes(&mut b.hw, c, now);
            b.run_for(3);
            // take() decodes every frame sent, or fails the test.
            b.take();
        }
        // A zero byte ends whatever partial frame the garbage left.
        b.app.on_bytes(&mut b.hw, &[0], 0);
        // Still alive and talking.
        let (r, _) = b.command(HostMsg::Status);
        prop_assert_eq!(r, Ok(()));
    }

    #[test]
    fn random_commands_never_panic(cmds in prop::collection::vec(0u8..10, 1..30), k in any::<u32>()) {
        let mut b = Bench::with_store(16 * 1024);
        for c in cmds {
            let msg = match c {
                0 => HostMsg::Configure(Configure::real_rig(0.3)),
                1 => HostMsg::Arm,
                2 => HostMsg::Release,
                3 => HostMsg::Abort,
                4 => HostMsg::Disarm,
                5 => HostMsg::Pull { run_id: k % 3, from_block: k },
                6 => HostMsg::SetHeater(HeaterSetpoint { setpoint_c: (k % 200) as f32, ramp_c_per_min: 1.0 }),
                7 => HostMsg::HeaterOff,
                8 => HostMsg::Status,
                _ => HostMsg::Hello { protocol: (k % 3) as u16 },
            };
            let _ = b.command(msg);
            b.run_for(20);
        }
    }
}
