//! The exit contract for an interrupted recording: SIGTERM (or Ctrl-C) during a run stops it
//! cleanly with status 130, keeps what was received as an aborted run, and `--repeat` says how many
//! runs were taken. (Before, an interrupted recording exited 0, and `--repeat 3` interrupted in its
//! first run never said that none of the three was taken.)
#![cfg(unix)]

mod support;

use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use support::{RigProcess, TRIBO};

#[test]
fn sigterm_during_a_recording_exits_130_and_says_how_many_runs_were_taken() {
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
    let mut seen = String::new();
    loop {
        let mut line = String::new();
        if err.read_line(&mut line).unwrap() == 0 {
            panic!("tribo ended before recording: {seen}");
        }
        seen.push_str(&line);
        if line.contains("recording run") {
            break;
        }
    }
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).unwrap();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130), "{seen}{rest}");
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
