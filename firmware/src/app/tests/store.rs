//! The run kept: pulls replay the same bytes, a cable pull loses nothing, runs longer than the RAM
//! ring come back from flash, and after a power cut the rig still offers the last run.

use super::*;

#[test]
fn a_pull_replays_the_same_bytes_from_any_block() {
    let mut b = Bench::new();
    let frames = full_run(&mut b);
    let run_frames: Vec<_> = frames.iter().filter(|f| f.1.msg.is_run_frame()).collect();
    let n_blocks = run_frames.iter().filter(|f| is_block(&f.1.msg)).count();
    assert!(n_blocks > 20);
    assert!(run_frames
        .iter()
        .any(|f| matches!(f.1.msg, DeviceMsg::EcrRange(_))));
    for from in [0, 1, n_blocks / 2, n_blocks - 1, n_blocks + 5] {
        b.send(HostMsg::Pull {
            run_id: 1,
            from_block: from as u32,
        });
        b.run_for(200);
        let mut again = b.take();
        assert!(matches!(again.remove(0).1.msg, DeviceMsg::Ack { .. }));
        // The header, then the live order from just after block `from − 1`: the events between
        // blocks `from − 1` and `from` come along, each in its place (those before were received
        // with the blocks before them).
        let after = run_frames
            .iter()
            .rposition(|f| matches!(&f.1.msg, DeviceMsg::Packed(p) if (p.block as usize) < from))
            .map_or(1, |i| i + 1);
        let expect: Vec<&Vec<u8>> = run_frames[..1]
            .iter()
            .chain(&run_frames[after..])
            .map(|f| &f.0)
            .collect();
        let got: Vec<&Vec<u8>> = again.iter().map(|f| &f.0).collect();
        assert_eq!(got, expect, "pull from block {from}");
    }
}

#[test]
fn a_cable_pulled_mid_run_loses_nothing() {
    let mut b = Bench::new();
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(100);
    let mut seen = b.take();
    b.hw.connected = false;
    b.run_for(150);
    b.hw.connected = true;
    b.app.link_reset();
    for _ in 0..3000 {
        b.run_for(1);
        seen.extend(b.take());
        if b.app.state() == RigState::Finished && b.app.want.is_none() {
            break;
        }
    }
    let blocks: Vec<u32> = block_indices(seen.iter().map(|f| &f.1.msg));
    let end = run_end(&seen.iter().map(|f| &f.1.msg).collect::<Vec<_>>()).unwrap();
    assert_eq!(
        blocks,
        (0..end.blocks).collect::<Vec<_>>(),
        "every block exactly once, in order"
    );
}

#[test]
fn a_run_longer_than_ram_is_pulled_whole_from_flash() {
    // RAM for a few packed blocks; the run has over 60. (RAM this small cannot ride out an erase
    // of the real 1.1 s: the flash here is instant.)
    let mut b = Bench::with_store(2 * 1024);
    b.hw.flash = MemFlash::new(vec![0; 1 << 20], FlashGeometry::H743_BANK2);
    let frames = full_run(&mut b);
    let run_frames: Vec<&Vec<u8>> = frames
        .iter()
        .filter(|f| f.1.msg.is_run_frame())
        .map(|f| &f.0)
        .collect();
    let total = frames.iter().filter(|f| is_block(&f.1.msg)).count() as u32;
    assert!(total > 60);
    settle_flash(&mut b);
    assert!(b.app.store().first_block_in_ram() > total / 2);
    b.take();
    b.send(HostMsg::Pull {
        run_id: 1,
        from_block: 0,
    });
    b.run_for(200);
    let mut again = b.take();
    assert!(matches!(again.remove(0).1.msg, DeviceMsg::Ack { .. }));
    let got: Vec<&Vec<u8>> = again.iter().map(|f| &f.0).collect();
    assert_eq!(got, run_frames, "the very frames first sent, all of them");
    assert_eq!(b.hw.flash.violations(), 0);
}

#[test]
fn after_a_power_cut_the_rig_offers_the_last_run_from_flash() {
    let mut b = Bench::new();
    let frames = full_run(&mut b);
    let run_frames: Vec<Vec<u8>> = frames
        .iter()
        .filter(|f| f.1.msg.is_run_frame())
        .map(|f| f.0.clone())
        .collect();
    settle_flash(&mut b);
    // Power cut: the application and its RAM are gone; the flash (in the hardware) stays.
    b.hw.flash.power_cut();
    b.app = App::new(AppConfig::new(42), store(256 * 1024));
    b.poll();
    assert_eq!(
        b.app.status().run_id,
        1,
        "the recovered run is the rig's last run"
    );
    assert_eq!(b.app.state(), RigState::Idle);
    b.take();
    b.send(HostMsg::Pull {
        run_id: 1,
        from_block: 0,
    });
    // The rig erases the next run's first sector ahead after booting: the flash serves the pull
    // once that erase (1.1 s) is done.
    b.run_for(1500);
    let mut again = b.take();
    assert!(matches!(again.remove(0).1.msg, DeviceMsg::Ack { .. }));
    let got: Vec<Vec<u8>> = again.into_iter().map(|f| f.0).collect();
    assert_eq!(got, run_frames, "bit-identical from flash");
    // The next run skips a number: the one a run released just before the cut may have spent.
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(20);
    let msgs = b.msgs();
    assert!(
        msgs.iter()
            .any(|m| matches!(m, DeviceMsg::RunStarted(h) if h.run_id == 3)),
        "{msgs:?}"
    );
}

/// The power goes just after a release, before the run's header reached flash: `RunStarted` has
/// not left the rig (it waits for the header's flash word), so the number was given to no one.
/// After the cut the next run is numbered above the flash's last run all the same.
#[test]
fn a_run_number_the_power_took_before_it_reached_flash_was_never_sent() {
    let mut b = Bench::new();
    full_run(&mut b);
    settle_flash(&mut b);
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.poll();
    let sent = b.msgs();
    assert!(
        !sent.iter().any(|m| matches!(m, DeviceMsg::RunStarted(_))),
        "{sent:?}"
    );
    assert!(!b.app.store().header_durable());
    b.hw.flash.power_cut();
    b.app = App::new(AppConfig::new(42), store(256 * 1024));
    b.poll();
    let held = b.app.status().run_id;
    assert_eq!(held, 1, "the rig holds run {held}");
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(1200);
    let next = b
        .msgs()
        .iter()
        .find_map(|m| match m {
            DeviceMsg::RunStarted(h) => Some(h.run_id),
            _ => None,
        })
        .expect("a run started");
    assert!(next > 1, "run number {next} given again");
}

/// The power cut and back: a new application (its RAM gone), the flash as the cut left it.
fn power_cut(b: &mut Bench) {
    b.hw.flash.power_cut();
    b.app = App::new(AppConfig::new(42), store(256 * 1024));
    b.poll();
}

/// Arms, releases, and returns the number of the run that started (within 1.2 s: a release
/// soon after a boot waits for the erase ahead the boot began, 1.1 s).
fn release_and_number(b: &mut Bench) -> u32 {
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(1200);
    b.msgs()
        .iter()
        .find_map(|m| match m {
            DeviceMsg::RunStarted(h) => Some(h.run_id),
            _ => None,
        })
        .expect("a run started")
}

#[test]
fn pull_blocks_sends_those_blocks_only_then_the_live_stream_goes_on() {
    let mut b = Bench::new();
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(100);
    let first = b.take();
    let seen = block_indices(first.iter().map(|f| &f.1.msg));
    assert!(seen.len() > 10);
    let (r, msgs) = b.command(HostMsg::PullBlocks {
        run_id: 1,
        first: 2,
        count: 3,
    });
    assert_eq!(r, Ok(()));
    let mut rest = msgs;
    for _ in 0..3000 {
        b.run_for(1);
        rest.extend(b.msgs());
        if b.app.state() == RigState::Finished && !b.app.sending() {
            break;
        }
    }
    let blocks = block_indices(rest.iter());
    assert_eq!(&blocks[..3], &[2, 3, 4], "the asked blocks first");
    let live: Vec<u32> = blocks[3..].to_vec();
    let end = run_end(&rest).unwrap();
    assert_eq!(
        seen.iter().chain(live.iter()).copied().collect::<Vec<_>>(),
        (0..end.blocks).collect::<Vec<_>>(),
        "the live stream resumed where it was"
    );
    // Out of range: nothing but the Ack.
    let (r, msgs) = b.command(HostMsg::PullBlocks {
        run_id: 1,
        first: end.blocks + 10,
        count: u32::MAX,
    });
    assert_eq!(r, Ok(()));
    b.run_for(20);
    assert!(block_indices(msgs.iter().chain(b.msgs().iter())).is_empty());
    assert_eq!(
        b.command(HostMsg::PullBlocks {
            run_id: 2,
            first: 0,
            count: 1
        })
        .0,
        Err(ErrorCode::NoRun)
    );
}

/// The host's `RunFloor` still lifts the next number above every run it holds of this rig (a
/// rig whose flash failed or was replaced holds fewer runs than the host): two runs cut by the
/// power just after `RunStarted` (their headers in flash: 2, then 4 after the skip a boot makes),
/// then a host holding run 9: the next run is 10.
#[test]
fn the_host_s_run_floor_keeps_numbers_the_rig_lost_from_being_given_again() {
    let mut b = Bench::new();
    full_run(&mut b);
    settle_flash(&mut b);
    let mut lost = vec![];
    for _ in 0..2 {
        b.ready();
        b.take();
        b.send(HostMsg::Release);
        for _ in 0..1500 {
            b.run_for(1);
            let got: Vec<u32> = b
                .msgs()
                .iter()
                .filter_map(|m| match m {
                    DeviceMsg::RunStarted(h) => Some(h.run_id),
                    _ => None,
                })
                .collect();
            if !got.is_empty() {
                lost.extend(got);
                break;
            }
        }
        power_cut(&mut b);
    }
    assert_eq!(lost, [2, 4]);
    b.send(HostMsg::RunFloor { run_id: 9 });
    assert_eq!(release_and_number(&mut b), 10);
}

/// Power cuts in a row, each just as `RunStarted` leaves the rig: no PC (the host here keeps
/// nothing and sends no `RunFloor`) is ever given a number twice. Before `RunStarted` waited for
/// the header to reach flash, the second and third runs were both numbered 3 (the flash still
/// showed run 1 only, and the skip after a recovery covers one lost run, not two).
#[test]
fn power_cuts_in_a_row_just_after_run_started_never_repeat_a_number() {
    let mut b = Bench::new();
    full_run(&mut b);
    settle_flash(&mut b);
    let mut given = vec![1u32];
    for cut in 0..4 {
        b.ready();
        b.take();
        b.send(HostMsg::Release);
        let mut started = None;
        for _ in 0..20_000 {
            b.poll();
            started = b.msgs().iter().find_map(|m| match m {
                DeviceMsg::RunStarted(h) => Some(h.run_id),
                _ => None,
            });
            if started.is_some() {
                break;
            }
            b.hw.now_us += b.app.cfg.poll_period_us as u64;
        }
        let n = started.unwrap_or_else(|| panic!("cut {cut}: no RunStarted"));
        assert!(
            !given.contains(&n),
            "cut {cut}: run {n} given again ({given:?})"
        );
        given.push(n);
        b.hw.flash.power_cut();
        b.app = App::new(AppConfig::new(42), store(256 * 1024));
        b.poll();
    }
}

/// Between runs the rig erases the next run's first sector ahead: a release then sends
/// `RunStarted` as soon as the header's flash words are programmed, within 2 ms, not a sector
/// erase (1.1 s) later.
#[test]
fn with_the_sector_erased_ahead_run_started_leaves_within_two_ms_of_the_release() {
    let mut b = Bench::new();
    full_run(&mut b);
    settle_flash(&mut b);
    b.run_for(1200);
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    let t0 = b.hw.now_us;
    let mut waited = None;
    for _ in 0..3000 {
        b.poll();
        if b.msgs()
            .iter()
            .any(|m| matches!(m, DeviceMsg::RunStarted(_)))
        {
            waited = Some(b.hw.now_us - t0);
            break;
        }
        b.hw.now_us += b.app.cfg.poll_period_us as u64;
    }
    let waited = waited.expect("a run started");
    eprintln!("release to RunStarted: {waited} µs");
    assert!(waited <= 2000, "RunStarted {waited} µs after the release");
    assert!(b.app.store().header_durable());
}
