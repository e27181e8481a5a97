//! The panel's link thread: it alone owns the link, polls the rig's status, runs the page's commands
//! through the same library calls as `tribo run` (configure, heater, arm, [`release`],
//! [`stream_run`]), and files what it sees into the [`Shared`] state the pages read.

use super::state::{Shared, Trace};
use crate::link::args::LinkArgs;
use crate::link::hold::SafeHandle;
use crate::link::session::{release, stream_run, HeaterPlan, Progress, RunPlan};
use crate::link::{explain_fault, firmware_version, Link, LinkError, LinkErrorKind};
use crate::ui::result_table;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tribo_wire::{Configure, HeaterSetpoint, HostMsg};

/// A command from the controlling page.
#[derive(Debug, Clone)]
pub enum Cmd {
    Heater {
        setpoint_c: f32,
        ramp_c_per_min: f32,
    },
    HeaterOff,
    Configure {
        load_n: f32,
        rate_hz: u32,
        max_duration_s: f32,
    },
    Arm,
    Release,
}

impl Cmd {
    pub fn name(&self) -> &'static str {
        match self {
            Cmd::Heater { .. } => "heater",
            Cmd::HeaterOff => "heater off",
            Cmd::Configure { .. } => "configure",
            Cmd::Arm => "arm",
            Cmd::Release => "release",
        }
    }
}

/// The answer to a command: done (with what to say), or refused (with the rig's reason).
pub type Reply = Result<String, String>;

/// What the link thread is given.
pub struct LinkThread {
    pub link: LinkArgs,
    pub store: PathBuf,
    pub shared: Arc<Mutex<Shared>>,
    pub cmds: Receiver<(Cmd, Sender<Reply>)>,
    /// `Safe` from any thread, whatever the link thread is doing (set while connected).
    pub safe: Arc<Mutex<Option<SafeHandle>>>,
    /// Stops a run's stream (the page's "safe", Ctrl-C).
    pub abort: Arc<AtomicBool>,
    /// The panel is closing: drop the link (which sends `Safe`) and return.
    pub quit: Arc<AtomicBool>,
}

const POLL: Duration = Duration::from_millis(250);

impl LinkThread {
    fn with<R>(&self, f: impl FnOnce(&mut Shared) -> R) -> R {
        let mut s = match self.shared.lock() {
            Ok(s) => s,
            Err(p) => p.into_inner(),
        };
        let r = f(&mut s);
        s.changed();
        r
    }

    /// Runs until `quit`: connects (again and again while the rig is away), then serves.
    pub fn run(self) {
        while !self.quit.load(Ordering::Relaxed) {
            match self.link.connect() {
                Ok((link, info)) => {
                    let why = self.serve(link, info);
                    if let Ok(mut g) = self.safe.lock() {
                        *g = None;
                    }
                    self.with(|s| s.disconnected(why));
                }
                Err(e) => {
                    let why = format!("{e:#}");
                    self.with(|s| s.disconnected(why));
                    self.refuse_pending(Duration::from_millis(700));
                }
            }
        }
    }

    /// While no rig is connected: every command is refused, saying so.
    fn refuse_pending(&self, wait: Duration) {
        let deadline = Instant::now() + wait;
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            if self.quit.load(Ordering::Relaxed) {
                return;
            }
            if let Ok((cmd, reply)) = self.cmds.recv_timeout(left.min(POLL)) {
                let _ = reply.send(Err(format!(
                    "{}: no rig is connected (see the rig line at the top); nothing was sent",
                    cmd.name()
                )));
            }
        }
    }

    /// Holds the connected rig until the link is lost or the panel quits; returns why it ended.
    fn serve(&self, mut link: Link, info: tribo_wire::DeviceInfo) -> String {
        // While the panel is connected it holds the rig as `tribo run` does: heartbeats keep the
        // lease, and every exit the panel controls sends `Safe` (a killed panel: the lease expires).
        let hold = link.hold();
        if let Ok(mut g) = self.safe.lock() {
            *g = Some(link.handle());
        }
        let boot = link.boot_report().map(|b| {
            let text = crate::link::reset_cause_text(b.cause);
            if b.message.is_empty() {
                text.to_string()
            } else {
                format!("{text}: {}", b.message)
            }
        });
        let (port, serial, fw) = (
            link.name().to_string(),
            format!("{:016x}", info.serial),
            firmware_version(&info),
        );
        self.with(|s| s.connected(port, serial, fw, boot));
        let mut plan: Option<RunPlan> = None;
        let mut previous_run: Option<u32> = None;
        let mut last_poll = Instant::now() - POLL;
        let why = loop {
            if self.quit.load(Ordering::Relaxed) {
                break "the panel is closing".to_string();
            }
            if last_poll.elapsed() >= POLL {
                last_poll = Instant::now();
                match link.status() {
                    Ok(st) => {
                        let fault = st.last_fault.map(|f| explain_fault(&f));
                        self.with(|s| s.status(st, fault));
                    }
                    Err(e) => break gone(&e),
                }
            }
            match self.cmds.recv_timeout(Duration::from_millis(40)) {
                Ok((cmd, reply)) => {
                    let r = self.command(&mut link, &info, cmd, &mut plan, &mut previous_run);
                    match r {
                        Ok((text, released)) => {
                            let _ = reply.send(Ok(text));
                            if let Some((p, before)) = released {
                                self.record(&mut link, &info, p, before);
                            }
                        }
                        Err(Fail::Refused(text)) => {
                            let _ = reply.send(Err(text));
                        }
                        Err(Fail::Gone(e)) => {
                            let _ = reply.send(Err(e.msg.clone()));
                            break gone(&e);
                        }
                    }
                }
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                    break "the panel is closing".to_string()
                }
            }
            // Frames nobody asked for (a fault, a late ack) are read and dropped; the status shows
            // their effect.
            match link.next(Duration::ZERO) {
                Ok(_) => {}
                Err(e) => break gone(&e),
            }
        };
        drop(hold);
        why
    }

    fn command(
        &self,
        link: &mut Link,
        info: &tribo_wire::DeviceInfo,
        cmd: Cmd,
        plan: &mut Option<RunPlan>,
        previous_run: &mut Option<u32>,
    ) -> Result<(String, Released), Fail> {
        match cmd {
            Cmd::Heater {
                setpoint_c,
                ramp_c_per_min,
            } => {
                // Sent as it is: the rig checks it with its own limits (`tribo_wire::limits`) and
                // its refusal is what the page shows.
                link.command(HostMsg::SetHeater(HeaterSetpoint {
                    setpoint_c,
                    ramp_c_per_min,
                }))?;
                self.with(|s| s.settle_reset());
                Ok((
                    format!("heater: heating to {setpoint_c:.1} °C at {ramp_c_per_min:.1} °C/min"),
                    None,
                ))
            }
            Cmd::HeaterOff => {
                link.command(HostMsg::HeaterOff)?;
                Ok(("heater off".into(), None))
            }
            Cmd::Configure {
                load_n,
                rate_hz,
                max_duration_s,
            } => {
                let mut c = Configure::real_rig(load_n);
                c.sample_rate_hz = rate_hz;
                c.max_duration_s = max_duration_s;
                link.command(HostMsg::Configure(c))?;
                let mut p = RunPlan::new(c);
                p.label = Some("panel".into());
                p.keep_heater = true;
                *plan = Some(p);
                Ok((
                    format!(
                        "configured: load {load_n} N, {rate_hz} S/s, at most {max_duration_s} s"
                    ),
                    None,
                ))
            }
            Cmd::Arm => {
                if plan.is_none() {
                    return Err(Fail::Refused(
                        "arm: configure the run first (load, rate, duration)".into(),
                    ));
                }
                let before = crate::link::session::arm(link, info, &self.store)?;
                *previous_run = Some(before);
                Ok((
                    "armed: the magnet holds the pin; release when ready".into(),
                    None,
                ))
            }
            Cmd::Release => {
                let (Some(p), Some(before)) = (plan.clone(), previous_run.take()) else {
                    return Err(Fail::Refused("release: arm the rig first".into()));
                };
                release(link)?;
                Ok(("released: recording".into(), Some((p, before))))
            }
        }
    }

    /// Streams the run just released into the store, as `tribo run` does, showing its blocks as
    /// they arrive; then the result and the report.
    fn record(
        &self,
        link: &mut Link,
        info: &tribo_wire::DeviceInfo,
        mut plan: RunPlan,
        before: u32,
    ) {
        self.abort.store(false, Ordering::Relaxed);
        let sp = self.with(|s| {
            s.busy = Some("recording".into());
            s.trace = None;
            s.result = None;
            s.status_snapshot().and_then(|st| st.heater_setpoint_c)
        });
        plan.heater = sp.map(|t| HeaterPlan::new(t, 10.0));
        let shared = self.shared.clone();
        let mut obs = |p: Progress<'_>| {
            let mut s = match shared.lock() {
                Ok(s) => s,
                Err(p) => p.into_inner(),
            };
            match p {
                Progress::Started { header, dir } => {
                    s.trace = Some(Trace::new(header, dir));
                    // No status polls while the run streams: its frames say where it is.
                    s.run_state(tribo_wire::RigState::Running);
                }
                Progress::Block {
                    block,
                    envelope_m,
                    expected,
                    ..
                } => {
                    if let Some(t) = s.trace.as_mut() {
                        t.block(block, envelope_m, expected);
                    }
                }
                Progress::Gap { from, to } => {
                    if let Some(t) = s.trace.as_mut() {
                        t.line_gap(from, to);
                    }
                }
                Progress::Lost(g) => {
                    if let Some(t) = s.trace.as_mut() {
                        t.lost(g);
                    }
                }
                Progress::Ended(e) => {
                    if let Some(t) = s.trace.as_mut() {
                        t.ended = Some(format!("{:?}", e.reason));
                    }
                    s.run_state(tribo_wire::RigState::Finished);
                }
                Progress::Warning(w) => s.say(false, format!("warning: {w}")),
                _ => {}
            }
            s.changed();
        };
        let o = stream_run(
            link,
            info,
            &self.store,
            &plan,
            before,
            &self.abort,
            &mut obs,
        );
        match o {
            Ok(o) => {
                let table = result_table(&o.run);
                let incomplete = o.incomplete().map(|e| e.0);
                let dir = o.run.dir().to_path_buf();
                let id = o.run.id().to_string();
                self.with(|s| {
                    s.finish_run(&o.run, table, incomplete, o.aborted);
                    s.busy = None;
                });
                super::state::write_report(self.shared.clone(), id, dir);
            }
            Err(e) => self.with(|s| {
                s.busy = None;
                s.say(false, format!("the run failed: {e:#}"));
            }),
        }
    }
}

/// After a release: the plan and the rig's run id before arming, for [`stream_run`].
type Released = Option<(RunPlan, u32)>;

/// Why a command did not happen.
enum Fail {
    /// The rig (or the panel's own order of steps) refused it: the link is fine.
    Refused(String),
    /// The link is gone.
    Gone(LinkError),
}

impl From<LinkError> for Fail {
    fn from(e: LinkError) -> Fail {
        match e.kind {
            LinkErrorKind::Refused => Fail::Refused(e.msg),
            _ => Fail::Gone(e),
        }
    }
}

fn gone(e: &LinkError) -> String {
    e.msg.clone()
}
