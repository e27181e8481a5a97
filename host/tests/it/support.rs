//! What the host's integration tests share: the `tribo` binary spawned ([`tribo`], [`command`]),
//! and a virtual rig as a process of its own (`tribo rig --virtual --listen 127.0.0.1:0`), for the
//! tests where the rig must outlive the host or serve several hosts in turn.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::time::{Duration, Instant};
use tribo::link::{Address, Link};

pub const TRIBO: &str = env!("CARGO_BIN_EXE_tribo");

/// `tribo ARGS` as a command: no standard input, and none of the environment's `TRIBO_PORT`,
/// `TRIBO_STORE` or `TRIBO_CATALOG` (a test says what it means).
pub fn command(args: &[&str]) -> Command {
    let mut c = Command::new(TRIBO);
    c.args(args)
        .env_remove("TRIBO_PORT")
        .env_remove("TRIBO_STORE")
        .env_remove("TRIBO_CATALOG")
        .stdin(Stdio::null());
    c
}

/// `tribo ARGS` run to its end ([`command`]).
pub fn tribo(args: &[&str]) -> Output {
    command(args).output().expect("run tribo")
}

/// A `tribo rig --virtual` process and the lines of its console, with when they were read.
pub struct RigProcess {
    child: Child,
    lines: Receiver<(Instant, String)>,
    seen: Vec<(Instant, String)>,
    /// What `--port` takes to reach it (printed by the rig: "virtual rig listening on …").
    pub addr: String,
}

impl RigProcess {
    pub fn start(speed: f64) -> RigProcess {
        RigProcess::start_with(speed, &[])
    }

    /// [`RigProcess::start`] with more `tribo rig` flags (`--mu0 0.003`…).
    pub fn start_with(speed: f64, extra: &[&str]) -> RigProcess {
        let mut child = Command::new(TRIBO)
            .args([
                "rig",
                "--virtual",
                "--listen",
                "127.0.0.1:0",
                "--speed",
                &speed.to_string(),
            ])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("tribo rig starts");
        let out = child.stdout.take().unwrap();
        let (tx, lines) = mpsc::channel();
        std::thread::spawn(move || {
            for l in BufReader::new(out).lines() {
                let Ok(l) = l else { return };
                if tx.send((Instant::now(), l)).is_err() {
                    return;
                }
            }
        });
        let mut r = RigProcess {
            child,
            lines,
            seen: Vec::new(),
            addr: String::new(),
        };
        let (_, line) = r.wait_for("listening on", Duration::from_secs(20));
        r.addr = line
            .split("listening on ")
            .nth(1)
            .and_then(|s| s.split_whitespace().next())
            .unwrap_or_else(|| panic!("no address in {line:?}"))
            .to_string();
        r
    }

    /// Waits for a console line containing `text` (seen before or new); returns it and when.
    pub fn wait_for(&mut self, text: &str, timeout: Duration) -> (Instant, String) {
        if let Some(l) = self.seen.iter().find(|(_, l)| l.contains(text)) {
            return l.clone();
        }
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok(l) => {
                    self.seen.push(l.clone());
                    if l.1.contains(text) {
                        return l;
                    }
                }
                Err(_) => panic!(
                    "no console line with {text:?} within {timeout:?}; console so far:\n{}",
                    self.console()
                ),
            }
        }
    }

    /// Reads the console for `d` more.
    pub fn drain(&mut self, d: Duration) {
        let deadline = Instant::now() + d;
        while let Ok(l) = self
            .lines
            .recv_timeout(deadline.saturating_duration_since(Instant::now()))
        {
            self.seen.push(l);
        }
    }

    /// Kills the rig's process (`kill -9`: the cable pulled, the rig gone).
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Sends the rig's process `signal` (`kill -SIGNAL`: `TERM`, `INT`…) and waits for it to end.
    pub fn stop_with(&mut self, signal: &str) -> std::process::ExitStatus {
        let sent = Command::new("kill")
            .args([&format!("-{signal}"), &self.child.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(sent.success(), "kill -{signal}");
        self.child.wait().expect("the rig's process ends")
    }

    pub fn console(&self) -> String {
        self.seen
            .iter()
            .map(|(_, l)| l.as_str())
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// The rig's hello (its serial, firmware).
    pub fn info(&self) -> tribo_wire::DeviceInfo {
        let addr = Address::parse(&self.addr).expect("the rig's address");
        let mut link = Link::open(&addr).expect("the rig's port opens");
        link.hello().expect("hello")
    }

    /// A fresh host's look at the rig (this renews the lease, so only once the test is done).
    pub fn status(&self) -> tribo_wire::Status {
        let addr = Address::parse(&self.addr).expect("the rig's address");
        let mut link = Link::open(&addr).expect("the rig's port opens");
        link.hello().expect("hello");
        link.status().expect("status")
    }
}

impl Drop for RigProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
