//! Runs the on-target test binary under QEMU and judges the outcome.
//!
//! `qemu-system-arm -machine mps2-an500 -cpu cortex-m7 -nographic
//! -semihosting-config enable=on,target=native -icount shift=0 -kernel ELF [-append FILTER]`: the
//! binary prints over semihosting and exits with 0 only when every test passed. The run passes when
//! QEMU exits 0 *and* printed the runner's `test result: ok.` line (a binary that exits early for any
//! other reason fails), within the time limit (a hung test is killed).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The QEMU binary.
pub const QEMU: &str = "qemu-system-arm";
/// Longest a run may take (it takes a few seconds).
pub const TIMEOUT: Duration = Duration::from_secs(60);

/// `qemu-system-arm` on the PATH, or what to install.
pub fn find() -> Result<PathBuf, String> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .map(|d| d.join(QEMU))
        .find(|p| p.is_file())
        .ok_or_else(|| {
            format!(
                "{QEMU} not found on the PATH.\n  → on Debian/Ubuntu: `sudo apt-get install -y \
                 qemu-system-arm`, then run this again"
            )
        })
}

/// The QEMU command for `elf` (with the test filter, if any, on the semihosting command line).
pub fn command(qemu: &Path, elf: &Path, filter: &str) -> Command {
    let mut c = Command::new(qemu);
    c.args([
        "-machine",
        "mps2-an500",
        "-cpu",
        "cortex-m7",
        "-nographic",
        "-semihosting-config",
        "enable=on,target=native",
        "-icount",
        "shift=0",
        "-kernel",
    ])
    .arg(elf);
    if !filter.is_empty() {
        c.args(["-append", filter]);
    }
    c
}

/// Runs the binary, echoing its output; `Ok` when every test passed.
pub fn run(qemu: &Path, elf: &Path, filter: &str) -> Result<(), String> {
    let mut cmd = command(qemu, elf, filter);
    eprintln!("$ {}", crate::show(&cmd));
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|e| format!("cannot start {QEMU}: {e}"))?;
    let stdout = child.stdout.take().ok_or("no stdout from QEMU")?;
    let reader = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            println!("{line}");
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let start = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) if start.elapsed() > TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                let _ = reader.join();
                return Err(format!(
                    "the on-target tests did not finish within {} s and were stopped: the last \
                     `test NAME ...` line above is the test that hung",
                    TIMEOUT.as_secs()
                ));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(format!("waiting for {QEMU}: {e}")),
        }
    };
    let output = reader.join().unwrap_or_default();
    let elapsed = start.elapsed().as_secs_f64();
    let summary = output.lines().rev().find(|l| l.starts_with("test result:"));
    match summary {
        Some(l) if status.success() && l.starts_with("test result: ok.") => {
            eprintln!("xtask: on-target tests passed under QEMU in {elapsed:.1} s");
            Ok(())
        }
        Some(l) => Err(format!(
            "on-target tests failed ({status}): {l}\n  → the failures are listed above; run one \
             alone with `cargo xtask target-test NAME`"
        )),
        None => Err(format!(
            "the on-target test binary ended without a summary ({status}): it panicked or \
             faulted before the end (see above)"
        )),
    }
}
