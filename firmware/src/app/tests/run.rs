//! A run from release to its end: contiguous blocks, gaps, bounded polls, the sample clock, ECR
//! range changes, heater faults, abort, unloaded runs, lamps, the end-of-run fit.

use super::*;

#[test]
fn a_run_streams_contiguous_blocks_then_result_and_end() {
    let mut b = Bench::new();
    let frames = full_run(&mut b);
    assert_eq!(b.app.state(), RigState::Finished);
    let msgs: Vec<_> = frames.iter().map(|f| &f.1.msg).collect();
    let header = msgs
        .iter()
        .find_map(|m| {
            if let DeviceMsg::RunStarted(h) = m {
                Some(*h)
            } else {
                None
            }
        })
        .unwrap();
    let blocks = sample_blocks(msgs.iter().copied());
    let end = run_end(&msgs).unwrap();
    let result = onboard_result(&msgs).unwrap();
    assert_eq!(
        end.reason,
        EndReason::Stopped,
        "the pin stops after 0.5 s; the analysis must see it"
    );
    assert!(result.cycles >= 5, "{result:?}");
    assert!((result.frequency_hz - 26.0).abs() < 0.5, "{result:?}");
    let mut next_sample = 0;
    for (k, blk) in blocks.iter().enumerate() {
        assert!(blk.is_consistent());
        assert_eq!(
            (blk.run_id, blk.block, blk.first_sample),
            (header.run_id, k as u32, next_sample)
        );
        assert_eq!(blk.t_us, header.t_us + blk.first_sample as u64 * 100);
        // The autoranger starts cold at arming (least gain, low source): it climbs a range per block
        // and waits out each change's settling (20 ms on the highest range, three blocks), so
        // a dozen blocks go by before it reads.
        if k >= 14 {
            assert!(
                (blk.log10_ecr_ohm - 7.0).abs() < 0.01,
                "ECR of a 1e7 Ω contact read as {}",
                blk.log10_ecr_ohm
            );
            assert_eq!(
                blk.ecr_range, 3,
                "1e7 Ω at 2 mV: 0.2 nA, 3 % of full scale on the 5e8 V/A range"
            );
        }
        next_sample += blk.samples() as u32;
    }
    assert_eq!(
        (end.blocks as usize, end.samples),
        (blocks.len(), next_sample)
    );
    assert_eq!(end.overruns, 0);
    // Result and end close the run, in that order, after every block.
    let pos = |f: &dyn Fn(&DeviceMsg) -> bool| msgs.iter().position(|m| f(m)).unwrap();
    let last_block = msgs.iter().rposition(|m| is_block(m)).unwrap();
    assert!(last_block < pos(&|m| matches!(m, DeviceMsg::Result(_))));
    assert!(
        pos(&|m| matches!(m, DeviceMsg::Result(_))) < pos(&|m| matches!(m, DeviceMsg::RunEnded(_)))
    );
    // The released pin read x0 = 667 µm at release.
    let x = header.config.calibration[0].to_si(blocks[0].sample(0).unwrap()[0]);
    assert!((x - 667e-6).abs() < 5e-6, "{x}");
}

#[test]
fn heater_fault_during_a_run_cuts_the_heater_and_ends_the_run() {
    let mut b = Bench::new();
    b.hw.tc = Some(reg(60.0));
    b.run_for(200);
    assert_eq!(
        b.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 80.0,
            ramp_c_per_min: 10.0
        }))
        .0,
        Ok(())
    );
    b.run_for(300);
    assert!(b.hw.heater_duty > 0.0);
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(100);
    b.hw.tc = Some(reg(111.0));
    b.run_for(150);
    let msgs = b.msgs();
    assert!(faults(&msgs).contains(&FaultReason::Heater(HeaterFault::OverTemperature)));
    assert_eq!(b.hw.heater_duty, 0.0);
    let end = run_end(&msgs).unwrap();
    assert_eq!(end.reason, EndReason::Fault(HeaterFault::OverTemperature));
    assert_eq!(
        b.app.status().heater_fault,
        Some(HeaterFault::OverTemperature)
    );
    assert!(
        b.hw.lamps.red || {
            b.run_for(250);
            b.hw.lamps.red
        }
    );
    // Shorted thermocouple while idle: reported, heater stays off, until a new setpoint once fixed.
    b.hw.tc = Some(bad(crate::thermocouple::sr::OVUV));
    assert_eq!(
        b.command(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 50.0,
            ramp_c_per_min: 10.0
        }))
        .0,
        Ok(())
    );
    b.run_for(TC_FAULT_MS);
    assert!(faults(&b.msgs()).contains(&FaultReason::Heater(HeaterFault::ShortedThermocouple)));
    assert_eq!(b.hw.heater_duty, 0.0);
}

#[test]
fn a_reader_stall_is_a_gap_frame_with_the_exact_missing_samples_and_the_run_goes_on() {
    let mut b = Bench::new();
    b.hw.stop_s = 1.0;
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(100);
    // Every sample due so far was read; the reader then stops for 300 ms (3000 samples, for a
    // ring of 2048), while the converter goes on.
    let stall_from = b.hw.adc.next_index();
    b.hw.adc.stall_reader(b.hw.now_us + 300_000);
    b.run_for(299);
    let before_resume = b.hw.adc.next_index();
    b.run_for(1);
    // At the poll that resumed reading, the ring held the last RING_SCANS samples.
    let resumed_at = b.hw.adc.next_index() - crate::acquisition::RING_SCANS as u64;
    assert!(before_resume < b.hw.adc.next_index());
    b.run_for(1500);
    let msgs = b.msgs();
    let base = b.app.run_base;
    let gaps: Vec<Gap> = msgs
        .iter()
        .filter_map(|m| match m {
            DeviceMsg::Gap(g) => Some(*g),
            _ => None,
        })
        .collect();
    assert_eq!(
        gaps,
        [Gap {
            run_id: 1,
            first_sample: (stall_from - base) as u32,
            count: (resumed_at - stall_from) as u32,
        }]
    );
    let end = run_end(&msgs).unwrap();
    assert_eq!(end.reason, EndReason::Stopped, "the run went on to its end");
    assert_eq!(end.overruns, gaps[0].count);
    assert_eq!(b.app.status().overruns, gaps[0].count);
    // Blocks: numbered on, each of consecutive samples, the one after the gap starting at its end,
    // and every sample holding the displacement of its own instant.
    let blocks = sample_blocks(&msgs);
    assert_eq!(
        blocks.iter().map(|k| k.block).collect::<Vec<_>>(),
        (0..blocks.len() as u32).collect::<Vec<_>>()
    );
    let mut next = 0;
    for k in &blocks {
        if k.first_sample != next {
            assert_eq!(
                (next, k.first_sample),
                (gaps[0].first_sample, gaps[0].first_sample + gaps[0].count)
            );
        }
        next = k.first_sample + k.samples() as u32;
        b.hw.check_block(k, base);
    }
    assert_eq!(next, end.samples + end.overruns);
}

#[test]
fn a_poll_takes_a_bounded_number_of_samples_and_a_backlog_drains_over_the_next_polls() {
    let mut b = Bench::new();
    b.hw.stop_s = 3.0;
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(50);
    // 100 ms without reading: 1000 samples wait in the 2048-scan ring (none lost).
    b.hw.adc.stall_reader(b.hw.now_us + 100_000);
    b.run_for(100);
    let taken = |b: &Bench| b.app.builder.as_ref().unwrap().samples();
    let per_poll = b.app.samples_per_poll() as u32;
    assert_eq!(
        per_poll, 16,
        "twice the 5 samples (at least 8) that arrive per 500 µs poll"
    );
    // Each poll takes what arrived and, when no block waits to be packed, up to that many again:
    // the backlog drains over the next polls (packing a block takes 6 of the 12.8 polls its samples
    // span), and nothing is lost.
    let mut polls = 0;
    while b.app.next_index < b.hw.adc.next_index() && polls < 2000 {
        let before = taken(&b);
        b.hw.now_us += 500;
        b.poll();
        let t = taken(&b) - before;
        assert!((5..=per_poll).contains(&t), "a poll took {t} samples");
        polls += 1;
    }
    assert_eq!(b.app.next_index, b.hw.adc.next_index(), "caught up");
    assert!(
        polls > 100,
        "{polls} polls: faster than the packing allows?"
    );
    let msgs = b.msgs();
    assert!(!msgs.iter().any(|m| matches!(m, DeviceMsg::Gap(_))));
    assert_eq!(b.app.status().overruns, 0);
}

#[test]
fn an_adc_overrun_restarts_the_converter_and_is_a_gap_not_a_shift() {
    let mut b = Bench::new();
    b.hw.stop_s = 0.6;
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(200);
    let at = b.hw.adc.next_index();
    b.hw.adc.inject_overrun();
    b.run_for(1000);
    let msgs = b.msgs();
    let base = b.app.run_base;
    let gaps: Vec<Gap> = msgs
        .iter()
        .filter_map(|m| match m {
            DeviceMsg::Gap(g) => Some(*g),
            _ => None,
        })
        .collect();
    // The scan the overrun struck and those converted until the next read (one 1 ms poll: ten).
    assert_eq!(gaps.len(), 1);
    assert_eq!(gaps[0].first_sample as u64, at - base);
    assert!((1..=11).contains(&gaps[0].count), "{:?}", gaps);
    // After it, the samples are those of their own instants: nothing shifted by the lost ones.
    for k in &sample_blocks(&msgs) {
        b.hw.check_block(k, base);
    }
    assert_eq!(run_end(&msgs).unwrap().overruns, gaps[0].count);
}

#[test]
fn a_rate_the_timer_cannot_make_is_run_at_the_nearest_and_recorded() {
    let mut b = Bench::new();
    let mut cfg = Configure::real_rig(0.3);
    cfg.sample_rate_hz = 9_999;
    assert_eq!(b.command(HostMsg::Configure(cfg)).0, Ok(()));
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    b.run_for(300);
    let (r, mut msgs) = b.command(HostMsg::Release);
    assert_eq!(r, Ok(()));
    b.run_for(700);
    msgs.extend(b.msgs());
    let header = msgs
        .iter()
        .find_map(|m| match m {
            DeviceMsg::RunStarted(h) => Some(*h),
            _ => None,
        })
        .unwrap();
    // 200 MHz / 20 002 = 9 999.0001 S/s: the rate used, not the one asked for.
    assert_eq!(
        header.clock,
        SampleClock {
            timer_hz: 200_000_000,
            ticks_per_sample: 20_002
        }
    );
    assert_eq!(header.config.sample_rate_hz, 9_999);
    let base = b.app.run_base;
    for k in &sample_blocks(&msgs) {
        assert_eq!(
            k.t_us,
            header.t_us + header.clock.time_us(k.first_sample as u64)
        );
        b.hw.check_block(k, base);
    }
}

#[test]
fn ecr_range_changes_flag_exactly_the_settling_samples_and_no_reading_uses_them() {
    let mut b = Bench::new();
    b.hw.stop_s = 1.0;
    b.hw.ecr_settles = true;
    b.ready();
    // Armed long enough for the autoranger to find 1e7 Ω (range 3) and settle.
    b.run_for(1500);
    assert_eq!(b.app.ecr.range(), 3);
    let (r, mut msgs) = b.command(HostMsg::Release);
    assert_eq!(r, Ok(()));
    b.run_for(100);
    // The contact drops to 10 Ω: the autoranger steps down to range 0, one change per block.
    b.hw.ecr_r = 10.0;
    b.run_for(1400);
    msgs.extend(b.msgs());
    let clock = msgs
        .iter()
        .find_map(|m| match m {
            DeviceMsg::RunStarted(h) => Some(h.clock),
            _ => None,
        })
        .unwrap();
    let changes: Vec<EcrRangeChange> = msgs
        .iter()
        .filter_map(|m| match m {
            DeviceMsg::EcrRange(e) => Some(*e),
            _ => None,
        })
        .collect();
    let ranges: Vec<u8> = changes.iter().map(|c| c.range).collect();
    assert_eq!(ranges, [3, 2, 1, 0], "{changes:?}");
    // The run starts settled on range 3; each change settles for its range's stated time.
    assert_eq!((changes[0].first_sample, changes[0].settling), (0, 0));
    for c in &changes[1..] {
        assert_eq!(c.settling, crate::ecr::settling_samples(c.range, clock));
    }
    assert!(changes
        .windows(2)
        .all(|w| w[0].first_sample < w[1].first_sample));
    // What the frames say about sample i: its range and whether it settles.
    let range_of = |i: u32| changes.iter().rev().find(|c| c.first_sample <= i).unwrap();
    let settling = |i: u32| {
        let c = range_of(i);
        i < c.first_sample + c.settling as u32
    };
    let blocks = sample_blocks(&msgs);
    let pos = Channel::Ecr.index() - 1; // after displacement and velocity; force is counted too
    let pos = blocks[0].channels.position(Channel::Ecr).unwrap_or(pos);
    let garbage = b.hw.cal[3].to_count(SETTLING_V);
    let mut flagged_garbage = 0;
    for k in &blocks {
        // The range a block declares is the one its first sample was converted on.
        assert_eq!(
            k.ecr_range,
            range_of(k.first_sample).range,
            "block {}",
            k.block
        );
        for i in 0..k.samples() {
            let idx = k.first_sample + i as u32;
            if k.sample(i).unwrap()[pos] == garbage {
                // Every sample taken while the amplifier settled is flagged as settling.
                assert!(settling(idx), "sample {idx} unsettled but not flagged");
                flagged_garbage += 1;
            }
        }
        // No reading is made of settling samples or of samples from two ranges: each one is the
        // contact's resistance before or after the step.
        let l = k.log10_ecr_ohm;
        assert!(
            l.is_nan() || (l - 7.0).abs() < 0.01 || (l - 1.0).abs() < 0.01,
            "block {}: log10 R = {l}",
            k.block
        );
    }
    assert!(flagged_garbage > 0, "the settling was exercised");
    let last = blocks.last().unwrap();
    assert!((last.log10_ecr_ohm - 1.0).abs() < 0.01);
}

#[test]
fn abort_keeps_the_run_and_marks_it() {
    let mut b = Bench::new();
    b.ready();
    assert_eq!(b.command(HostMsg::Release).0, Ok(()));
    b.run_for(100);
    let (r, mut msgs) = b.command(HostMsg::Abort);
    assert_eq!(r, Ok(()));
    b.run_for(50);
    msgs.extend(b.msgs());
    let end = run_end(&msgs).unwrap();
    let res = onboard_result(&msgs).unwrap();
    assert_eq!(
        (end.reason, res.verdict),
        (EndReason::Aborted, Verdict::Aborted)
    );
    assert!(!b.hw.adc.is_running());
    assert_eq!(
        b.command(HostMsg::Pull {
            run_id: 1,
            from_block: 0
        })
        .0,
        Ok(())
    );
}

#[test]
fn an_unloaded_run_runs_to_its_maximum_duration_without_onboard_analysis() {
    let mut b = Bench::new();
    let mut c = Configure::real_rig(0.0);
    c.max_duration_s = 0.5;
    assert_eq!(b.command(HostMsg::Configure(c)).0, Ok(()));
    assert_eq!(b.command(HostMsg::Arm).0, Ok(()));
    b.run_for(50);
    b.send(HostMsg::Release);
    b.run_for(700);
    let msgs = b.msgs();
    let end = run_end(&msgs).unwrap();
    let res = onboard_result(&msgs).unwrap();
    assert_eq!((end.reason, end.samples), (EndReason::MaxDuration, 5000));
    assert!(
        res.best.mu0.is_nan() && res.best.mu1.is_nan(),
        "an estimate from no analysis: {res:?}"
    );
    assert_eq!(res.verdict, Verdict::NotAnalysed, "{res:?}");
    assert!((res.duration_s - 0.5).abs() < 1e-6);
}

#[test]
fn lamps_show_idle_armed_running_and_fault() {
    let mut b = Bench::new();
    // Idle: green blinking at 1 Hz, nothing else.
    let mut greens = Vec::new();
    for _ in 0..20 {
        b.run_for(100);
        greens.push(b.hw.lamps.green);
        assert!(!b.hw.lamps.amber && !b.hw.lamps.red);
    }
    assert!(greens.iter().filter(|&&g| g).count() == 10, "{greens:?}");
    b.ready();
    assert_eq!(
        b.hw.lamps,
        Lamps {
            amber: true,
            ..Lamps::default()
        }
    );
    b.send(HostMsg::Release);
    let mut on = 0;
    for _ in 0..400 {
        b.run_for(1);
        on += b.hw.lamps.green as u32;
        assert!(!b.hw.lamps.amber && !b.hw.lamps.red);
    }
    assert_eq!(b.app.state(), RigState::Running);
    assert_eq!(on, 200, "running: green at 5 Hz, half the time on");
    b.hw.tc = Some(bad(crate::thermocouple::sr::OPEN));
    b.run_for(2000);
    let reds: Vec<bool> = (0..8)
        .map(|_| {
            b.run_for(125);
            b.hw.lamps.red
        })
        .collect();
    assert!(
        reds.contains(&true) && reds.contains(&false),
        "fault: red blinking {reds:?}"
    );
    assert!(!b.hw.lamps.green);
}

/// The end-of-run fit is spread over polls: once the pin has stopped the run stays `Running`
/// (no new run can be configured or armed) until the result and end frames exist, some polls
/// later, and the result is the pipeline's one-call result.
#[test]
fn the_end_of_run_fit_is_spread_over_polls() {
    let mut b = Bench::new();
    b.app.cfg.finish_rows_per_poll = 4;
    b.ready();
    b.send(HostMsg::Release);
    let mut analysing_polls = 0;
    for _ in 0..3000 {
        b.run_for(1);
        if b.app.ending.is_some() {
            analysing_polls += 1;
            assert_eq!(b.app.state(), RigState::Running);
            if analysing_polls == 2 {
                let (r, _) = b.command(HostMsg::Configure(Configure::real_rig(0.3)));
                assert_eq!(r, Err(ErrorCode::Busy));
                assert!(b.app.store().end().is_none());
            }
        }
        if b.app.state() == RigState::Finished {
            break;
        }
    }
    let p = b.app.pipeline.as_ref().unwrap();
    let half_cycles = p.half_cycles().len();
    assert!(half_cycles > 10, "{half_cycles}");
    // 4 rows per poll over ~35 passes of the half-cycles
    assert!(analysing_polls > half_cycles, "{analysing_polls} polls");
    let one_call = p.finish(b.app.run_id());
    let stored = b
        .app
        .store()
        .result()
        .map(|f| decode_one::<DeviceMsg>(f).unwrap().msg);
    assert_eq!(stored, Some(DeviceMsg::Result(one_call)));
}

#[test]
fn every_run_states_the_board_s_analog_chain_right_after_its_header() {
    let mut b = Bench::new();
    b.hw.stop_s = 0.3;
    b.ready();
    let (r, mut msgs) = b.command(HostMsg::Release);
    assert_eq!(r, Ok(()));
    b.run_for(1500);
    msgs.extend(b.msgs());
    let at = msgs
        .iter()
        .position(|m| matches!(m, DeviceMsg::RunStarted(_)))
        .expect("a run header");
    let DeviceMsg::RunStarted(h) = &msgs[at] else {
        unreachable!()
    };
    assert_eq!(
        msgs.get(at + 1),
        Some(&DeviceMsg::Chain(AnalogChain {
            run_id: h.run_id,
            force_lowpass: b.hw.force_lowpass(),
        })),
        "{:?}",
        &msgs[at..(at + 3).min(msgs.len())]
    );
    assert!(msgs.iter().any(|m| matches!(m, DeviceMsg::RunEnded(_))));
    let chains = msgs
        .iter()
        .filter(|m| matches!(m, DeviceMsg::Chain(_)))
        .count();
    assert_eq!(chains, 1, "once per run");
}
