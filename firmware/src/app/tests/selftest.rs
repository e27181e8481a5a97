//! The self-test's checks through the application (the measurements themselves are tested in
//! `crate::selftest`): between runs only, one at a time, reports sent whole and in order.

use super::*;
use crate::selftest::{judge_channel, judge_flash, judge_rate, ChannelProblem, Deliberate};
use crate::wire::{filler_byte, SelfTestCheck, SelfTestReport};

fn reports(msgs: &[DeviceMsg]) -> Vec<SelfTestReport> {
    msgs.iter()
        .filter_map(|m| match m {
            DeviceMsg::SelfTest(r) => Some(r.clone()),
            _ => None,
        })
        .collect()
}

/// Runs until a report other than a filler frame comes (at most `ms`); the reports on the way.
fn until_report(b: &mut Bench, ms: u64) -> Vec<SelfTestReport> {
    let mut got = Vec::new();
    for _ in 0..ms {
        b.run_for(1);
        let msgs = b.msgs();
        got.extend(reports(&msgs));
        if got
            .last()
            .is_some_and(|r| !matches!(r, SelfTestReport::Filler { .. }))
        {
            return got;
        }
    }
    panic!("no report within {ms} ms: {got:?}");
}

#[test]
fn a_converter_check_counts_the_samples_against_the_time_base_then_stops_the_converter() {
    let mut b = Bench::new();
    let check = SelfTestCheck::Converter {
        rate_hz: 10_000,
        ms: 500,
    };
    assert_eq!(b.command(HostMsg::SelfTest(check)).0, Ok(()));
    assert!(b.app.selftest_running() && b.hw.adc_running());
    // One check at a time.
    assert_eq!(b.command(HostMsg::SelfTest(check)).0, Err(ErrorCode::Busy));
    let got = until_report(&mut b, 1000);
    let [SelfTestReport::Converter(r)] = &got[..] else {
        panic!("{got:?}")
    };
    let (rate, ppm, ok) = judge_rate(r);
    assert!(ok, "{rate} S/s, {ppm} ppm");
    assert!((4_990..=5_010).contains(&r.samples), "{r:?}");
    // The mock's inputs hold perfectly still (no noise at all): every one reads a single code,
    // which on a real converter means it does not convert.
    for s in &r.channels {
        assert_eq!(
            judge_channel(s, r.samples),
            Err(ChannelProblem::Stuck),
            "{s:?}"
        );
    }
    assert!(!b.app.selftest_running() && !b.hw.adc_running());
}

#[test]
fn a_flash_check_uses_a_sector_no_run_needs_and_leaves_it_erased() {
    let mut b = Bench::new();
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Flash { bytes: 2048 }))
            .0,
        Ok(())
    );
    let got = until_report(&mut b, 5000);
    let [SelfTestReport::Flash(r)] = &got[..] else {
        panic!("{got:?}")
    };
    assert_eq!(judge_flash(r), Ok(()), "{r:?}");
    assert_eq!(
        (r.sector, r.bytes),
        (7, 2048),
        "no run held: the last sector"
    );
    assert_eq!(b.hw.flash.erase_count(7), 2);
    assert!(b.hw.flash.bytes()[7 * 128 * 1024..]
        .iter()
        .all(|&x| x == 0xFF));
    // Armed: refused (the converter and the flash are the run's).
    b.ready();
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Flash { bytes: 256 }))
            .0,
        Err(ErrorCode::Busy)
    );
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Panic)).0,
        Err(ErrorCode::Busy)
    );
    assert_eq!(b.app.take_deliberate(), None);
}

#[test]
fn the_flash_check_waits_for_the_run_s_flash_copy_and_spares_the_sectors_it_holds() {
    let mut b = Bench::new();
    full_run(&mut b);
    settle_flash(&mut b);
    // The second run starts at sector 1 (after the first one's): the spare sector is the one
    // before it, which the next runs reach last. Mid-run, its copy is being written.
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(300);
    assert_eq!(b.app.store().flash_state(), FlashState::Writing);
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Flash { bytes: 256 }))
            .0,
        Err(ErrorCode::Busy),
        "the run is still being written to flash"
    );
    for _ in 0..3000 {
        if b.app.state() == RigState::Finished {
            break;
        }
        b.run_for(1);
    }
    settle_flash(&mut b);
    let run = b.app.store().run_id();
    let held: Vec<u8> = b.hw.flash.bytes()[128 * 1024..129 * 1024].to_vec();
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Flash { bytes: 256 }))
            .0,
        Ok(())
    );
    let got = until_report(&mut b, 5000);
    let [SelfTestReport::Flash(r)] = &got[..] else {
        panic!("{got:?}")
    };
    assert_eq!((r.sector, judge_flash(r)), (0, Ok(())), "{r:?}");
    assert_eq!(&b.hw.flash.bytes()[128 * 1024..129 * 1024], &held[..]);
    assert_eq!(b.app.store().run_id(), run);
}

#[test]
fn a_deliberate_act_is_handed_to_the_board_once_after_the_ack() {
    let mut b = Bench::new();
    let (r, msgs) = b.command(HostMsg::SelfTest(SelfTestCheck::Stall));
    assert_eq!(r, Ok(()));
    assert!(msgs.iter().any(|m| matches!(m, DeviceMsg::Ack { .. })));
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Panic)).0,
        Err(ErrorCode::Busy),
        "the stall is still to be carried out"
    );
    assert_eq!(b.app.take_deliberate(), Some(Deliberate::Stall));
    assert_eq!(b.app.take_deliberate(), None);
    b.run_for(10);
    assert_eq!(b.app.take_deliberate(), None);
}

#[test]
fn filler_frames_wait_for_a_link_that_has_no_room_and_none_is_lost() {
    let mut b = Bench::new();
    let check = SelfTestCheck::Throughput {
        frames: 60,
        len: 200,
    };
    assert_eq!(b.command(HostMsg::SelfTest(check)).0, Ok(()));
    b.run_for(2);
    b.hw.connected = false;
    b.run_for(20);
    b.hw.connected = true;
    let got = until_report(&mut b, 1000);
    let mut next = 0;
    for r in &got {
        match r {
            SelfTestReport::Filler { index, data } => {
                assert_eq!(*index, next);
                assert_eq!(data.len(), 200);
                assert!(data
                    .iter()
                    .enumerate()
                    .all(|(i, &x)| x == filler_byte(*index, i)));
                next += 1;
            }
            SelfTestReport::FillerDone { frames, refused } => {
                assert_eq!((*frames, next), (60, 60));
                assert!(*refused >= 20, "{refused}");
            }
            other => panic!("{other:?}"),
        }
    }
    assert_eq!(
        b.app.dropped_frames(),
        0,
        "a refused filler is not a dropped frame"
    );
}

#[test]
fn a_deliberate_fault_is_refused_while_the_heater_heats_and_leaves_it_heating() {
    let mut b = Bench::new();
    b.hw.tc = Some(reg(60.0));
    b.run_for(200);
    let sp = HeaterSetpoint {
        setpoint_c: 80.0,
        ramp_c_per_min: 10.0,
    };
    assert_eq!(b.command(HostMsg::SetHeater(sp)).0, Ok(()));
    b.run_for(300);
    assert!(b.hw.heater_duty > 0.0);
    for check in [SelfTestCheck::Panic, SelfTestCheck::Stall] {
        assert_eq!(
            b.command(HostMsg::SelfTest(check)).0,
            Err(ErrorCode::Interlock(Interlock::HeaterOn)),
            "{check:?}"
        );
        assert_eq!(b.app.take_deliberate(), None);
    }
    b.run_for(100);
    assert!(b.hw.heater_duty > 0.0, "the refusal changed nothing");
    // The heater off (the host's safe command): the check goes ahead.
    assert_eq!(b.command(HostMsg::Safe).0, Ok(()));
    b.run_for(100);
    assert_eq!(b.hw.heater_duty, 0.0);
    assert_eq!(b.command(HostMsg::SelfTest(SelfTestCheck::Panic)).0, Ok(()));
    assert_eq!(b.app.take_deliberate(), Some(Deliberate::Panic));
}

#[test]
fn a_deliberate_fault_is_refused_while_the_magnet_holds_and_leaves_it_holding() {
    let mut b = Bench::new();
    // Configured and armed, heater off: the magnet holds the pin.
    b.ready();
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    assert_eq!(b.hw.heater_duty, 0.0);
    for check in [SelfTestCheck::Panic, SelfTestCheck::Stall] {
        assert_eq!(
            b.command(HostMsg::SelfTest(check)).0,
            Err(ErrorCode::Busy),
            "{check:?}"
        );
        assert_eq!(b.app.take_deliberate(), None);
    }
    b.run_for(100);
    assert!(
        matches!(b.hw.magnet(), MagnetDrive::Hold { .. }),
        "the refusal changed nothing"
    );
    // Disarmed: the coil still holds the pin (until its budget runs out), and the reset would
    // drop it: still refused.
    assert_eq!(b.command(HostMsg::Disarm).0, Ok(()));
    b.run_for(100);
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Panic)).0,
        Err(ErrorCode::Busy)
    );
    assert_eq!(b.app.take_deliberate(), None);
    // The host's safe command lets the coil go: the check goes ahead.
    assert_eq!(b.command(HostMsg::Safe).0, Ok(()));
    b.run_for(100);
    assert_eq!(b.hw.magnet(), MagnetDrive::Off);
    assert_eq!(b.command(HostMsg::SelfTest(SelfTestCheck::Stall)).0, Ok(()));
    assert_eq!(b.app.take_deliberate(), Some(Deliberate::Stall));
}

#[test]
fn an_accepted_deliberate_fault_first_sets_the_ecr_source_to_zero_and_keeps_it_there() {
    let mut b = Bench::new();
    b.run_for(500);
    // Idle, the ECR controller measures the contact: its source is on.
    assert!(b.hw.ecr_source > 0.0, "{}", b.hw.ecr_source);
    assert_eq!(b.command(HostMsg::SelfTest(SelfTestCheck::Stall)).0, Ok(()));
    assert_eq!(b.hw.ecr_source, 0.0, "off before the acknowledgement");
    assert_eq!(b.app.take_deliberate(), Some(Deliberate::Stall));
    // A stalled task takes the watchdog's ~300 ms: the controller does not switch it on again.
    b.run_for(1000);
    assert_eq!(b.hw.ecr_source, 0.0);
}

/// Runs an outputs check to its report.
fn outputs_check(b: &mut Bench) -> crate::wire::OutputsReport {
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Outputs)).0,
        Ok(())
    );
    let got = until_report(b, 100);
    let [SelfTestReport::Outputs(r)] = &got[..] else {
        panic!("{got:?}")
    };
    *r
}

#[test]
fn an_outputs_check_walks_the_patterns_reads_them_back_and_restores_the_ecr_front_end() {
    use crate::selftest::{judge_output, OUTPUT_NAMES, RANGE_PATTERNS};
    let mut b = Bench::new();
    b.run_for(500);
    let before = (b.hw.ecr_range, b.hw.ecr_source);
    let r = outputs_check(&mut b);
    assert_eq!(r.steps as usize, RANGE_PATTERNS.len());
    for (i, name) in OUTPUT_NAMES.iter().enumerate() {
        assert_eq!(judge_output(&r, i), Some(Ok(())), "{name}: {r:?}");
    }
    // The last step drove range 0b011, lamps 0b111, the start source: read back as driven.
    assert_eq!((r.outputs[3].driven, r.outputs[3].read), (0b011, 0b011));
    assert_eq!((r.outputs[4].driven, r.outputs[4].read), (0b111, 0b111));
    assert_eq!(
        b.hw.ecr_range, before.0,
        "the range as the controller left it"
    );
    assert_eq!(b.hw.ecr_source, before.1);
    assert_eq!(
        b.hw.lamps,
        b.app.lamps(b.hw.now_us),
        "lamps back to the state's"
    );
}

#[test]
fn a_stuck_range_pin_fails_only_the_range_output_and_a_live_heater_or_magnet_refuses_the_check() {
    use crate::selftest::judge_output;
    let mut b = Bench::new();
    b.hw.range_bit1_stuck_low = true;
    let r = outputs_check(&mut b);
    assert_eq!(judge_output(&r, 3).map(|v| v.is_err()), Some(true), "{r:?}");
    // Patterns 0b010 and 0b011 drive PG1 high: two mismatches, the first at 0b010.
    assert_eq!(r.outputs[3].mismatches, 2);
    assert_eq!((r.outputs[3].driven, r.outputs[3].read), (0b010, 0b000));
    for i in [0, 1, 2, 4] {
        assert_eq!(judge_output(&r, i), Some(Ok(())), "{i}: {r:?}");
    }
    // Armed, the magnet holds: refused, and the magnet still holds.
    let mut b = Bench::new();
    b.ready();
    assert_eq!(b.command(HostMsg::Disarm).0, Ok(()));
    b.run_for(10);
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Outputs)).0,
        Err(ErrorCode::Busy)
    );
    assert!(matches!(b.hw.magnet(), MagnetDrive::Hold { .. }));
}

#[test]
fn an_arm_during_an_outputs_check_gives_the_ecr_front_end_back_to_its_controller() {
    let mut b = Bench::new();
    assert_eq!(
        b.command(HostMsg::Configure(Configure::real_rig(0.3))).0,
        Ok(())
    );
    b.run_for(300);
    let before = (b.hw.ecr_range, b.hw.ecr_source);
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Outputs)).0,
        Ok(())
    );
    // Two polls: the probe drives range 0b001 and the 2 mV source.
    b.run_for(1);
    assert_eq!(b.hw.ecr_range, 1);
    assert_ne!((b.hw.ecr_range, b.hw.ecr_source), before);
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    assert!(!b.app.selftest_running());
    assert_eq!((b.hw.ecr_range, b.hw.ecr_source), before);
}

/// Runs a clock check of `n` intervals to its report.
fn clock_check(b: &mut Bench, n: u16) -> crate::wire::ClockReport {
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Clock { intervals: n }))
            .0,
        Ok(())
    );
    let got = until_report(b, 100);
    let [SelfTestReport::Clock(r)] = &got[..] else {
        panic!("{got:?}")
    };
    *r
}

#[test]
fn a_clock_check_measures_the_lsi_one_interval_per_poll_and_stops_the_timer() {
    use crate::selftest::{judge_clock, ClockProblem};
    let mut b = Bench::new();
    let r = clock_check(&mut b, 16);
    assert!(r.available && r.lsi_ready, "{r:?}");
    assert_eq!((r.intervals, r.overcaptures, r.timeouts), (16, 0, 0));
    assert_eq!((r.ticks_min, r.ticks_max), (6250, 6250));
    let f = judge_clock(&r).unwrap();
    assert!((f.lsi_hz - 32_000.0).abs() < 1e-6, "{f:?}");
    assert!(!b.hw.lsi_running, "the timer stopped after the report");
    // The HSE 10 % fast: the LSI reads 29.09 kHz through it, below its 29.76 kHz minimum.
    b.hw.lsi_hse_ratio = Some(1.10);
    let r = clock_check(&mut b, 4);
    assert!(
        matches!(judge_clock(&r), Err(ClockProblem::OutOfRange(_))),
        "{r:?}"
    );
    // No timer input on the LSI: reported at once, not measurable.
    b.hw.lsi_hse_ratio = None;
    let r = clock_check(&mut b, 4);
    assert!(!r.available);
    assert_eq!(judge_clock(&r), Err(ClockProblem::NotAvailable));
}

#[test]
fn arming_during_a_clock_check_stops_its_timer() {
    let mut b = Bench::new();
    let mut c = Configure::real_rig(0.3);
    c.max_duration_s = 2.0;
    assert_eq!(b.command(HostMsg::Configure(c)).0, Ok(()));
    assert_eq!(
        b.command(HostMsg::SelfTest(SelfTestCheck::Clock { intervals: 1000 }))
            .0,
        Ok(())
    );
    b.run_for(5);
    assert!(b.hw.lsi_running);
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    assert!(
        !b.hw.lsi_running,
        "the check gave way to the run and stopped its timer"
    );
}
