//! The `tribo` program itself, as a lab user runs it, against a virtual rig served by this test:
//! `kill -9` of `tribo run` in the middle of a run, then `tribo pull` (the fault-injection row
//! that needs a real process); and the exit statuses of commands that leave or find a run
//! incomplete (status 3, saying "incomplete: N of M blocks"), against those that do not.

use crate::support::{tribo, TRIBO};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use tribo::link::{Address, Link};
use tribo::virtual_rig::VirtualArgs;
use tribo_store::Run;
use tribo_wire::{DeviceMsg, HostMsg};

/// A virtual rig on a free local port, at `speed`× real time; it stops when dropped.
fn rig(mu0: f64, speed: f64) -> (tribo_rig::TcpRig, Address) {
    let args = VirtualArgs {
        mu0: Some(mu0),
        mu1: Some(0.004),
        seed: Some(9),
        speed,
        ..Default::default()
    };
    let (tcp, _) = args.listen("127.0.0.1:0", |_| {}).unwrap();
    let addr = Address::from(tcp.addr());
    (tcp, addr)
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `tribo run` in a child process; returns it once its run folder's log holds `bytes` bytes, with
/// the folder.
// The child is returned to the caller, which kills or waits for it.
#[allow(clippy::zombie_processes)]
fn spawn_run(port: &Address, store: &Path, bytes: u64) -> (std::process::Child, PathBuf) {
    let mut child = Command::new(TRIBO)
        .args([
            "run",
            "--load",
            "0.3",
            "--max-duration",
            "8",
            "-q",
            "--port",
        ])
        .arg(port.to_string())
        .arg("--store")
        .arg(store)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the child never recorded");
        }
        if let Some(d) = tribo_store::run::list_run_dirs(store).unwrap().first() {
            let len = std::fs::metadata(d.join("frames.log")).map_or(0, |m| m.len());
            if len > bytes {
                return (child, d.clone());
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// The rig's own copy of run `run_id`: a `Pull` from block 0, every run frame to the end.
fn rig_frames(port: &Address, run_id: u32) -> Vec<Vec<u8>> {
    let mut link = Link::open(port).unwrap();
    link.hello().unwrap();
    while link.drain(Duration::from_millis(200)).unwrap() > 0 {}
    link.command(HostMsg::Pull {
        run_id,
        from_block: 0,
    })
    .unwrap();
    let mut frames = vec![];
    loop {
        let f = link
            .next(Duration::from_secs(2))
            .unwrap()
            .expect("the rig sends the run");
        if f.msg().is_run_frame() {
            let end = matches!(f.msg(), DeviceMsg::RunEnded(_));
            frames.push(f.raw);
            if end {
                return frames;
            }
        }
    }
}

#[test]
fn kill_9_of_tribo_run_mid_run_then_tribo_pull_stores_the_run_bit_identical() {
    // Real time: a light contact rings for about 2 s; the recorder is killed 0.2 s in.
    let (_rig, port) = rig(0.01, 1.0);
    let store = tempfile::tempdir().unwrap();
    let (mut child, dir) = spawn_run(&port, store.path(), 40 * 180);
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let killed = Run::open(&dir).expect("a killed recorder leaves a readable run");
    assert!(!killed.is_complete());
    let held = killed.block_count();
    assert!(held >= 30, "{held} blocks");
    let run_id = killed.header().unwrap().run_id;
    // Give the rig its run's end, then fetch the rest.
    std::thread::sleep(Duration::from_millis(2500));
    let o = tribo(&[
        "pull",
        "-q",
        "--port",
        &port.to_string(),
        "--store",
        store.path().to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains(&format!("complete: {0} of {0} blocks", {
            Run::open(&dir).unwrap().block_count()
        })),
        "{}",
        text(&o)
    );
    let run = Run::open(&dir).unwrap();
    let truth = rig_frames(&port, run_id);
    assert!(run.is_complete(), "{}", run.completeness().summary());
    let got = run.frames();
    assert_eq!(got.len(), truth.len());
    assert!(
        got.iter().zip(&truth).all(|(a, b)| *a == &b[..]),
        "bit-identical to the rig's run"
    );
    // Nothing around the crash point was lost or doubled: each frame logged once.
    let log = tribo_store::LogReader::read(&dir.join("frames.log"), false).unwrap();
    assert_eq!(log.records.len(), truth.len());
    assert_eq!(
        tribo_store::run::list_run_dirs(store.path()).unwrap().len(),
        1
    );
}

#[test]
fn a_run_cut_short_exits_3_and_report_replay_and_reindex_say_incomplete() {
    let (rig_tcp, port) = rig(0.01, 1.0);
    let store = tempfile::tempdir().unwrap();
    // The rig goes away mid-run (its program stopped, the cable pulled): `tribo run` keeps what
    // came, says the run is incomplete, and exits 3.
    let (child, dir) = spawn_run(&port, store.path(), 30 * 180);
    drop(rig_tcp);
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("incomplete: ") && t.contains("tribo pull") && !t.contains("(complete: "),
        "{t}"
    );
    let run = Run::open(&dir).unwrap();
    let n = run.block_count();
    let summary = format!("incomplete: {n} of at least {n} blocks");
    assert!(t.contains(&summary), "{t}");

    // `tribo report` of it: the page is written, and says so; exit 3.
    let out = store.path().join("report");
    let o = tribo(&[
        "report",
        dir.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--no-png",
        "--laws",
        "coulomb-viscous",
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).contains(&summary), "{}", text(&o));
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains(&summary), "the page says it");
    assert!(!html.contains(">complete<"));

    // `tribo replay`: replays what is there, says what it lacks, exit 3.
    let o = tribo(&["replay", dir.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));
    assert!(text(&o).contains(&summary), "{}", text(&o));

    // The catalog re-index lists it as incomplete (exit 0: listing is not incomplete work).
    let o = tribo(&[
        "runs",
        "--reindex",
        "--store",
        store.path().to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let t = text(&o);
    assert!(
        t.contains("1 of them incomplete") && t.contains(&summary),
        "{t}"
    );
    assert!(t.contains(&format!("{n}/?")), "{t}");

    // A truncated log of a run its metadata calls complete is not shown complete either.
    let mut meta = std::fs::read_to_string(dir.join("meta.toml")).unwrap();
    meta = meta.replace("status = \"incomplete\"", "status = \"complete\"");
    std::fs::write(dir.join("meta.toml"), meta).unwrap();
    let o = tribo(&["replay", dir.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(3), "{}", text(&o));

    // No rig to pull from: an error (1), not "incomplete".
    let o = tribo(&[
        "pull",
        dir.to_str().unwrap(),
        "--port",
        &port.to_string(),
        "--store",
        store.path().to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
}
