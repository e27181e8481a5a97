//! The exit contract for an interrupted command: a signal during a recording stops it cleanly with
//! the status of that signal (128 + its number, the shell's convention: 130 for Ctrl-C, 143 for
//! SIGTERM), keeps what was received as an aborted run, and `--repeat` says how many runs were
//! taken; `tribo rig` stopped by a signal exits the same way. (Before, an interrupted recording
//! exited 0, and `--repeat 3` interrupted in its first run never said that none of the three was
//! taken; later, every interruption exited 130, whichever signal it was.)
#![cfg(unix)]

use crate::support::{RigProcess, TRIBO};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};

/// Sends `signal` (`kill -SIGNAL`) to process `pid`.
fn send(signal: &str, pid: u32) {
    let sent = Command::new("kill")
        .args([&format!("-{signal}"), &pid.to_string()])
        .status()
        .unwrap();
    assert!(sent.success(), "kill -{signal} {pid}");
}

/// `tribo run --repeat 3`, sent `signal` while it records its first run: exits `status`, says that
/// none of the three was taken, keeps the interrupted run as aborted.
fn interrupt_a_recording(signal: &str, status: i32) {
    let rig = RigProcess::start(1.0);
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(TRIBO)
        .args(["run", "--load", "0.1", "--repeat", "3", "--port", &rig.addr])
        .arg("--store")
        .arg(dir.path().join("runs"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let seen = wait_for_recording(&mut err);
    send(signal, child.id());
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).unwrap();
    let got = child.wait().unwrap();
    assert_eq!(got.code(), Some(status), "SIG{signal}: {seen}{rest}");
    assert!(rest.contains("interrupted during run 1"), "{rest}");
    assert!(rest.contains("0 of 3 runs taken"), "{rest}");
    // The interrupted run is kept, as aborted.
    let runs: Vec<_> = std::fs::read_dir(dir.path().join("runs"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .collect();
    assert_eq!(runs.len(), 1, "{rest}");
    let meta = std::fs::read_to_string(runs[0].path().join("meta.toml")).unwrap();
    assert!(meta.contains("aborted"), "{meta}");
}

#[test]
fn sigterm_during_a_recording_exits_143_and_says_how_many_runs_were_taken() {
    interrupt_a_recording("TERM", 143);
}

#[test]
fn ctrl_c_during_a_recording_exits_130_and_says_how_many_runs_were_taken() {
    interrupt_a_recording("INT", 130);
}

/// `tribo rig --virtual`, sent `signal` while it serves: says it stopped and exits `status`.
fn stop_the_virtual_rig(signal: &str, status: i32) {
    let mut rig = RigProcess::start(1.0);
    // It serves: a host's hello is answered (or this panics).
    rig.info();
    let got = rig.stop_with(signal);
    assert_eq!(
        got.code(),
        Some(status),
        "tribo rig after SIG{signal}: {got:?}"
    );
}

#[test]
fn sigterm_stops_the_virtual_rig_with_status_143() {
    stop_the_virtual_rig("TERM", 143);
}

#[test]
fn ctrl_c_stops_the_virtual_rig_with_status_130() {
    stop_the_virtual_rig("INT", 130);
}

#[test]
fn sighup_stops_the_virtual_rig_with_status_129() {
    stop_the_virtual_rig("HUP", 129);
}

/// A campaign interrupted by Ctrl-C says how to take it up again with the store and port it was
/// given (the hint dropped `--store`: run as written, it took the campaign up in another store).
#[test]
fn an_interrupted_campaign_says_how_to_resume_it_with_its_own_store() {
    let rig = RigProcess::start(1.0);
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("plan.toml");
    std::fs::write(&plan, "name = \"resume\"\nloads_n = [0.1]\nrepeats = 2\n").unwrap();
    let store = dir.path().join("elsewhere");
    let mut child = Command::new(TRIBO)
        .arg("campaign")
        .arg(&plan)
        .args(["--no-prompt", "--port", &rig.addr, "--store"])
        .arg(&store)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let seen = wait_for_recording(&mut err);
    send("INT", child.id());
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).unwrap();
    let got = child.wait().unwrap();
    assert_eq!(got.code(), Some(130), "{seen}{rest}");
    let again = format!(
        "tribo campaign {} --store {} --port {} --no-prompt",
        plan.display(),
        store.display(),
        rig.addr
    );
    assert!(rest.contains(&again), "no `{again}` in: {rest}");
}

/// Reads `err` until tribo says it is recording a run (returns what it read); panics if it ends
/// first.
fn wait_for_recording(err: &mut impl BufRead) -> String {
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        if err.read_line(&mut line).unwrap() == 0 {
            panic!("tribo ended before recording: {seen}");
        }
        seen.push_str(&line);
        if line.contains("recording run") {
            return seen;
        }
    }
}
