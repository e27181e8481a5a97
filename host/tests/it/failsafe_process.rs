//! The host-process rows of the fail-safe table: `tribo` as its own process against a
//! virtual rig that is a process of its own (`tribo rig --virtual`), so the rig outlives the host.
//! What the rig did is read from its console (standard output: commands, faults, with device time).
//!
//! * `kill -9` of `tribo run` while it heats: the rig's lease expires and it drives heater and magnet
//!   off by itself, within the lease of the last frame it heard (real time, default lease).
//! * `tribo run --temp 40 --repeat 2 | true`: the closed pipe stops `tribo` (quietly, status 0, as
//!   `grep` would), which sends `Safe` on its way out: the heater is off before any lease runs out.
//! * SIGTERM while heating: a clean stop, `Safe` sent.
//! * A rig that resets (HardFault) while `tribo` settles the heater: settling stops with the reason.
//! * A held session (in-process rig, real time): the heartbeat thread alone keeps the lease through
//!   a silence longer than it; dropping the hold sends `Safe`; without it the lease expires.

use crate::support::{RigProcess, TRIBO};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use tribo::link::{Address, Link};
use tribo_wire::{limits, FaultReason};

fn tribo_run(rig: &RigProcess, store: &Path, extra: &[&str]) -> Command {
    let mut c = Command::new(TRIBO);
    c.args(["run", "--load", "0.3", "--quiet", "--port", &rig.addr])
        .arg("--store")
        .arg(store)
        .args(extra);
    c
}

#[test]
fn tribo_killed_while_heating_leaves_the_rig_safe_within_the_lease() {
    // Real time and the real lease: the one end-to-end check of the default numbers.
    let dir = tempfile::tempdir().unwrap();
    let mut rig = RigProcess::start(1.0);
    let mut host = tribo_run(&rig, &dir.path().join("runs"), &["--temp", "40"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    rig.wait_for("host: heater to 40.0 °C", Duration::from_secs(20));
    // Heating (and heartbeating): let it go on a moment, then kill -9.
    std::thread::sleep(Duration::from_millis(1500));
    host.kill().unwrap();
    let killed = Instant::now();
    host.wait().unwrap();
    let (at, line) = rig.wait_for("FAULT LeaseExpired", Duration::from_secs(10));
    let after = at.duration_since(killed);
    // The rig counts the lease from the last frame it heard, at most one heartbeat period (or
    // a settle status poll) before the kill.
    assert!(
        after <= Duration::from_millis(limits::HOST_LEASE_MS as u64 + 1000),
        "safe {after:?} after the kill: {line}"
    );
    let silence: u64 = line
        .split("last host command ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    assert!(
        (limits::HOST_LEASE_MS as u64..=limits::HOST_LEASE_MS as u64 + 2).contains(&silence),
        "{line}"
    );
    assert!(!rig.console().contains("host: safe"), "nobody sent safe");
    let s = rig.status();
    assert_eq!(s.heater_setpoint_c, None);
    assert_eq!(s.heater_duty, 0.0);
    assert!(!s.magnet_on);
    assert_eq!(
        s.last_fault.map(|f| f.reason),
        Some(FaultReason::LeaseExpired)
    );
    // `tribo status` tells a technician the same.
    let out = Command::new(TRIBO)
        .args(["status", "--port", &rig.addr])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("heater off"), "{text}");
    assert!(text.contains("no word from the host"), "{text}");
    assert!(text.contains("last reset   power-on"), "{text}");
}

#[test]
fn tribo_run_into_a_closed_pipe_makes_the_rig_safe_on_its_way_out() {
    // `tribo run --temp 40 --repeat 2 | true`: the first result line meets a closed pipe.
    let dir = tempfile::tempdir().unwrap();
    let mut rig = RigProcess::start(20.0);
    let cmd = format!(
        "set -o pipefail; '{TRIBO}' run --port '{}' --store '{}' --load 0.3 --temp 40 --ramp 30 \
         --settle-secs 2 --repeat 2 --quiet | true",
        rig.addr,
        dir.path().join("runs").display()
    );
    let out = Command::new("bash")
        .args(["-c", &cmd])
        .stdout(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    // A reader that ended is not an error (as with grep): quiet, status 0.
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked") && !err.contains("error"), "{err}");
    // Heated, recorded one run, then stopped: the rig heard `Safe`, and before its lease ran out.
    rig.wait_for("host: heater to 40.0 °C", Duration::from_secs(5));
    rig.wait_for("host: release", Duration::from_secs(5));
    rig.wait_for("host: safe", Duration::from_secs(5));
    rig.drain(Duration::from_millis(500));
    assert!(
        !rig.console().contains("FAULT"),
        "no fault: {}",
        rig.console()
    );
    assert_eq!(
        rig.console().matches("host: release").count(),
        1,
        "the second repetition never started"
    );
    let s = rig.status();
    assert_eq!((s.heater_setpoint_c, s.heater_duty), (None, 0.0));
    assert!(!s.magnet_on);
    assert_eq!(s.last_fault, None);
}

#[test]
fn sigterm_while_heating_stops_cleanly_and_makes_the_rig_safe() {
    let dir = tempfile::tempdir().unwrap();
    let mut rig = RigProcess::start(1.0);
    let mut host = tribo_run(&rig, &dir.path().join("runs"), &["--temp", "40"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    rig.wait_for("host: heater to 40.0 °C", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(300));
    let term = Instant::now();
    assert!(Command::new("kill")
        .args(["-TERM", &host.id().to_string()])
        .status()
        .unwrap()
        .success());
    let status = host.wait().unwrap();
    let (at, _) = rig.wait_for("host: safe", Duration::from_secs(5));
    assert!(
        at.duration_since(term) < Duration::from_millis(limits::HOST_LEASE_MS as u64 / 2),
        "safe {:?} after SIGTERM",
        at.duration_since(term)
    );
    let mut err = String::new();
    std::io::Read::read_to_string(&mut host.stderr.take().unwrap(), &mut err).unwrap();
    assert_eq!(
        status.code(),
        Some(143),
        "interrupted by SIGTERM: status 143 (128 + 15)\n{err}"
    );
    assert!(err.contains("interrupted while heating"), "{err}");
    rig.drain(Duration::from_millis(200));
    assert!(!rig.console().contains("FAULT"), "{}", rig.console());
}

#[test]
fn a_held_session_keeps_the_lease_through_silence_and_leaves_the_rig_safe() {
    // In-process rig at real time and the real lease: the session says nothing for longer than
    // the lease while the heater is on; only the heartbeat thread speaks.
    let rig = tribo_rig::VirtualRig::new(tribo_rig::VirtualRigConfig::default()).unwrap();
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let tcp = tribo_rig::TcpRig::spawn(rig, l, tribo_rig::ServeOptions::default(), |_| {}).unwrap();
    let mut link = Link::open(&Address::from(tcp.addr())).unwrap();
    link.hello().unwrap();
    let hold = link.hold();
    link.command(tribo_wire::HostMsg::SetHeater(tribo_wire::HeaterSetpoint {
        setpoint_c: 40.0,
        ramp_c_per_min: 30.0,
    }))
    .unwrap();
    std::thread::sleep(Duration::from_millis(
        limits::HOST_LEASE_MS as u64 + limits::HEARTBEAT_MS as u64,
    ));
    assert!(hold.heartbeats() >= 3, "{}", hold.heartbeats());
    let s = link.status().unwrap();
    assert_eq!(s.last_fault, None, "the lease held");
    assert_eq!(s.heater_setpoint_c, Some(40.0));
    assert!(s.heater_duty > 0.0);
    // The session ends: Safe, at once.
    drop(hold);
    let s = link.status().unwrap();
    assert_eq!((s.heater_setpoint_c, s.heater_duty), (None, 0.0));
    assert_eq!(
        s.last_fault, None,
        "made safe by the host, not by the lease"
    );
    // Without the heartbeat, the same silence expires the lease.
    link.command(tribo_wire::HostMsg::SetHeater(tribo_wire::HeaterSetpoint {
        setpoint_c: 40.0,
        ramp_c_per_min: 30.0,
    }))
    .unwrap();
    std::thread::sleep(Duration::from_millis(
        limits::HOST_LEASE_MS as u64 + limits::HEARTBEAT_MS as u64,
    ));
    let s = link.status().unwrap();
    assert_eq!(
        s.last_fault.map(|f| f.reason),
        Some(FaultReason::LeaseExpired)
    );
    assert_eq!(s.heater_setpoint_c, None);
    assert!(link
        .faults()
        .iter()
        .any(|f| f.reason == FaultReason::LeaseExpired));
}

#[test]
fn a_rig_that_resets_while_heating_stops_the_settling_with_the_reason() {
    use std::io::{Read, Write};
    use std::os::unix::net::UnixStream;
    // A rig served in real time on a socket pair, which takes a HardFault one second in.
    let (host_end, mut rig_end) = UnixStream::pair().unwrap();
    rig_end
        .set_read_timeout(Some(Duration::from_millis(2)))
        .unwrap();
    std::thread::spawn(move || {
        let mut rig = tribo_rig::VirtualRig::new(tribo_rig::VirtualRigConfig::default()).unwrap();
        let start = Instant::now();
        let mut faulted = false;
        let mut buf = [0u8; 4096];
        loop {
            match rig_end.read(&mut buf) {
                Ok(0) => return,
                Ok(n) => rig.input(&buf[..n]),
                Err(_) => {}
            }
            rig.advance_to(start.elapsed().as_micros() as u64);
            if !faulted && start.elapsed() > Duration::from_secs(1) {
                rig.inject_cpu_fault();
                faulted = true;
            }
            if rig_end.write_all(&rig.take_output()).is_err() {
                return;
            }
        }
    });
    let mut link = Link::from_stream("socket", host_end.try_clone().unwrap(), host_end);
    link.hello().unwrap();
    let _hold = link.hold();
    let plan = tribo::link::session::HeaterPlan::new(40.0, 10.0);
    let t0 = Instant::now();
    let e = tribo::link::session::settle(
        &mut link,
        &plan,
        &std::sync::atomic::AtomicBool::new(false),
        &mut |_| {},
    )
    .unwrap_err();
    let msg = format!("{e:#}");
    assert!(
        msg.contains("reset itself") && msg.contains("CPU fault"),
        "{msg}"
    );
    assert!(t0.elapsed() < Duration::from_secs(3), "{:?}", t0.elapsed());
}
