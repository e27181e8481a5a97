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
    b.run_for(300);
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

/// The power goes just after a release, before the run's header reached flash: the host holds the
/// header of run 2, the flash shows run 1 only. The next run must not be called 2 again (two runs
/// of one rig under one number: the soak found it, the run reused by the next one).
#[test]
fn a_run_number_the_power_took_before_it_reached_flash_is_not_given_again() {
    let mut b = Bench::new();
    full_run(&mut b);
    settle_flash(&mut b);
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.poll();
    let sent = b.msgs();
    assert!(
        sent.iter()
            .any(|m| matches!(m, DeviceMsg::RunStarted(h) if h.run_id == 2)),
        "{sent:?}"
    );
    power_cut(&mut b);
    let held = b.app.status().run_id;
    assert!(held <= 2, "the rig holds run {held}");
    let next = release_and_number(&mut b);
    assert!(next > 2, "run number {next} given again");
}

/// The power cut and back: a new application (its RAM gone), the flash as the cut left it.
fn power_cut(b: &mut Bench) {
    b.hw.flash.power_cut();
    b.app = App::new(AppConfig::new(42), store(256 * 1024));
    b.poll();
}

/// Arms, releases, and returns the number of the run that started.
fn release_and_number(b: &mut Bench) -> u32 {
    b.ready();
    b.take();
    b.send(HostMsg::Release);
    b.run_for(20);
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

/// Two runs in a row lost to the power before their headers reached flash: the flash shows run 1
/// after both, so the rig alone, skipping one number after each boot, gives 2, 3 and then 3 again.
/// The host holds both headers and tells the rig (`RunFloor`): the next run is numbered above them.
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
        b.poll();
        lost.extend(b.msgs().iter().filter_map(|m| match m {
            DeviceMsg::RunStarted(h) => Some(h.run_id),
            _ => None,
        }));
        power_cut(&mut b);
    }
    assert_eq!(lost, [2, 3]);
    b.send(HostMsg::RunFloor { run_id: 3 });
    assert_eq!(release_and_number(&mut b), 4);
}
