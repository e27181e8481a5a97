//! The link to a rig: frames over a serial port (USB CDC), a TCP connection (a virtual rig), or
//! any byte stream (an in-process virtual rig, a socket in tests).
//!
//! * [`Link`]: hello and protocol check, commands answered by `Ack`/`Error` with timeouts and
//!   retries, and the raw frames as received (the run store logs them byte for byte).
//! * [`transport`]: what `--port` names ([`Address`]: a serial port or `tcp://HOST:PORT`) and the
//!   byte stream each opens; [`serial`]: opening a serial port the way a rig needs;
//!   [`devices`]: finding attached rigs.
//! * [`session`]: a whole run (configure, heat, arm, release, stream, resume with `Pull`) and
//!   `pull` of a run already taken; [`plan`]: what a run asks of the rig; `stream`: a run's frames
//!   filed into the store, and pulls of what is missing.
//! * [`pty`] (Unix): the virtual rig behind a pseudo-terminal.
//! * `meaning`: what the rig's codes mean, in words (errors, faults, reset causes).
//! * [`hold`]: while a session holds the rig, a heartbeat renews its lease, and every exit the host
//!   controls sends `Safe`.

pub mod args;
pub mod devices;
pub mod hold;
mod meaning;
pub mod plan;
mod progress;
#[cfg(unix)]
pub mod pty;
pub mod serial;
pub mod session;
mod stream;
pub mod transport;

use meaning::command_name;
pub use meaning::{
    explain, explain_fault, field_name, firmware_version, heater_fault_text, reset_cause_text,
    state_name, uptime,
};
pub use transport::Address;

use std::collections::VecDeque;
use std::fmt;
use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tribo_wire::frame::{decode_one, encode_vec, MAX_FRAME};
use tribo_wire::{
    check_protocol, BootReport, DeviceError, DeviceInfo, DeviceMsg, ErrorCode, FaultReport, Frame,
    FrameError, HostMsg, Status, PROTOCOL_VERSION,
};

/// A frame from the rig, with its bytes exactly as received (closing zero included).
#[derive(Debug, Clone)]
pub struct Incoming {
    /// The frame's bytes as received, closing zero included.
    pub raw: Vec<u8>,
    /// The frame decoded.
    pub frame: Frame<DeviceMsg>,
}

impl Incoming {
    /// The message the frame carries.
    pub fn msg(&self) -> &DeviceMsg {
        &self.frame.msg
    }
}

enum Event {
    Frame(Box<Incoming>),
    Bad(FrameError),
    Closed(String),
}

/// What kind of link failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkErrorKind {
    /// The port could not be opened.
    Open,
    /// The rig did not answer in time (after the retries).
    NoAnswer,
    /// The stream ended: cable pulled, rig reset, virtual rig stopped.
    Closed,
    /// The rig refused a command.
    Refused,
    /// The rig speaks another protocol version.
    Protocol,
}

/// A link failure. The message says what to do next.
#[derive(Debug, Clone)]
pub struct LinkError {
    /// What kind of failure (it decides what to do next).
    pub kind: LinkErrorKind,
    /// What went wrong and what to do next.
    pub msg: String,
    /// The rig's error code, when it refused a command.
    pub code: Option<ErrorCode>,
}

impl LinkError {
    fn new(kind: LinkErrorKind, msg: impl Into<String>) -> Self {
        LinkError {
            kind,
            msg: msg.into(),
            code: None,
        }
    }
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.msg)
    }
}

impl std::error::Error for LinkError {}

/// Timeouts and retries of a [`Link`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Timeouts {
    /// Wait for an answer to a command.
    pub reply: Duration,
    /// Sends of an idempotent command before giving up.
    pub attempts: u32,
    /// Silence during a run stream after which the rig is asked for its status.
    pub stream_idle: Duration,
}

impl Default for Timeouts {
    fn default() -> Self {
        Timeouts {
            reply: Duration::from_millis(1000),
            attempts: 3,
            stream_idle: Duration::from_secs(3),
        }
    }
}

/// Counters of a link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Bytes received.
    pub bytes_in: u64,
    /// Good frames received.
    pub frames_in: u64,
    /// Frames dropped as bad (CRC, COBS, decoding).
    pub bad_frames: u64,
    /// Frames sent.
    pub frames_out: u64,
}

/// The writing half of a link, shared with the heartbeat thread and the exit paths ([`hold`]).
pub(crate) type SharedWriter = Arc<Mutex<Box<dyn Write + Send>>>;

/// A connection to a rig.
pub struct Link {
    name: String,
    tx: SharedWriter,
    rx: Receiver<Event>,
    backlog: VecDeque<Incoming>,
    /// Sequence numbers of every frame sent on this link, by any thread.
    seq: Arc<AtomicU32>,
    /// The rig's boot report, if its answer to our hello carried one.
    boot: Option<BootReport>,
    /// Faults the rig reported on this link, oldest first.
    faults: Vec<FaultReport>,
    stop: Arc<AtomicBool>,
    bytes_in: Arc<AtomicU64>,
    closed: Option<String>,
    last_bad: Option<FrameError>,
    stats: LinkStats,
    /// Joined on drop when its reads time out by themselves (serial ports, sockets), so that the
    /// port is closed (and unlocked) when the link is dropped.
    reader: Option<std::thread::JoinHandle<()>>,
    /// What to check when the stream ends.
    gone_hint: &'static str,
    /// How long to wait for the rig's answers.
    pub timeouts: Timeouts,
}

impl Drop for Link {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(r) = self.reader.take() {
            let _ = r.join();
        }
    }
}

fn reader_loop(
    mut r: Box<dyn Read + Send>,
    tx: Sender<Event>,
    stop: Arc<AtomicBool>,
    bytes_in: Arc<AtomicU64>,
) {
    let mut buf = vec![0u8; 8192];
    let mut cur: Vec<u8> = Vec::with_capacity(MAX_FRAME);
    let mut overflow = false;
    loop {
        if stop.load(Ordering::Relaxed) {
            return;
        }
        let n = match r.read(&mut buf) {
            Ok(0) => {
                let _ = tx.send(Event::Closed("the rig closed the connection".into()));
                return;
            }
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::Interrupted
                        | std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                ) =>
            {
                continue
            }
            Err(e) => {
                let _ = tx.send(Event::Closed(format!("read failed: {e}")));
                return;
            }
        };
        bytes_in.fetch_add(n as u64, Ordering::Relaxed);
        for &b in &buf[..n] {
            if b == 0 {
                let ev = if overflow {
                    Some(Event::Bad(FrameError::Overflow))
                } else if cur.is_empty() {
                    None
                } else {
                    cur.push(0);
                    Some(match decode_one::<DeviceMsg>(&cur) {
                        Ok(frame) => Event::Frame(Box::new(Incoming {
                            raw: cur.clone(),
                            frame,
                        })),
                        Err(e) => Event::Bad(e),
                    })
                };
                cur.clear();
                overflow = false;
                if let Some(ev) = ev {
                    if tx.send(ev).is_err() {
                        return;
                    }
                }
            } else if cur.len() < MAX_FRAME {
                cur.push(b);
            } else {
                overflow = true;
            }
        }
    }
}

impl Link {
    /// Opens the link to the rig at `addr`: a serial port (raw mode, exclusively) or a TCP
    /// address. The link's reading thread is joined when the link is dropped, so the port is
    /// closed (and free for the next program) once the link is gone.
    pub fn open(addr: &Address) -> Result<Link, LinkError> {
        let (r, w) = transport::open(addr)?;
        let mut link = Link::spawn(addr.to_string(), r, w, true);
        if addr.is_tcp() {
            link.gone_hint =
                "is the virtual rig still running? It serves one host at a time: is another \
                              `tribo` connected to it?";
        }
        Ok(link)
    }

    /// A link over any byte stream. The reader is read on a thread of its own; a read returning 0
    /// is the end of the stream (reads that time out should return `TimedOut`/`WouldBlock`).
    pub fn from_stream(
        name: impl Into<String>,
        reader: impl Read + Send + 'static,
        writer: impl Write + Send + 'static,
    ) -> Link {
        Link::spawn(name.into(), reader, writer, false)
    }

    fn spawn(
        name: String,
        reader: impl Read + Send + 'static,
        writer: impl Write + Send + 'static,
        join_on_drop: bool,
    ) -> Link {
        let (tx, rx) = mpsc::channel();
        let stop = Arc::new(AtomicBool::new(false));
        let bytes_in = Arc::new(AtomicU64::new(0));
        let (s, b) = (stop.clone(), bytes_in.clone());
        let handle = std::thread::Builder::new()
            .name("tribo-link-reader".into())
            .spawn(move || reader_loop(Box::new(reader), tx, s, b))
            .expect("spawning a thread");
        Link {
            reader: join_on_drop.then_some(handle),
            name,
            tx: Arc::new(Mutex::new(Box::new(writer))),
            rx,
            backlog: VecDeque::new(),
            seq: Arc::new(AtomicU32::new(0)),
            boot: None,
            faults: Vec::new(),
            stop,
            bytes_in,
            closed: None,
            last_bad: None,
            gone_hint: "check the cable (or restart the virtual rig)",
            stats: LinkStats::default(),
            timeouts: Timeouts::default(),
        }
    }

    /// The port's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Why the last bad frame was dropped (CRC, COBS…), if any was.
    pub fn last_bad_frame(&self) -> Option<FrameError> {
        self.last_bad
    }

    /// The link's counters so far.
    pub fn stats(&self) -> LinkStats {
        LinkStats {
            bytes_in: self.bytes_in.load(Ordering::Relaxed),
            ..self.stats
        }
    }

    fn closed_error(&self) -> LinkError {
        LinkError::new(
            LinkErrorKind::Closed,
            format!(
                "lost the link to the rig on {} ({}): {}; what was received is saved, and `tribo pull` \
                 fetches the rest",
                self.name,
                self.closed.as_deref().unwrap_or("closed"),
                self.gone_hint
            ),
        )
    }

    /// Sends a command; returns its sequence number.
    pub fn send(&mut self, msg: &HostMsg) -> Result<u32, LinkError> {
        let seq = self.seq.fetch_add(1, Ordering::Relaxed).wrapping_add(1);
        let bytes = encode_vec(seq, msg).map_err(|_| {
            LinkError::new(
                LinkErrorKind::Refused,
                "command too large to frame (a bug in tribo)",
            )
        })?;
        let written = match self.tx.lock() {
            Ok(mut w) => w.write_all(&bytes).and_then(|_| w.flush()),
            Err(_) => Err(std::io::Error::other("the writer was poisoned by a panic")),
        };
        written.map_err(|e| {
            self.closed = Some(format!("write failed: {e}"));
            self.closed_error()
        })?;
        self.stats.frames_out += 1;
        Ok(seq)
    }

    /// The rig's boot report (why it last reset), if it came with the answer to our hello: it is
    /// sent once after each reset, to the first host that says hello.
    pub fn boot_report(&self) -> Option<&BootReport> {
        self.boot.as_ref()
    }

    /// Takes the boot report kept from a hello (the next hello that brings one sets it again).
    pub fn take_boot_report(&mut self) -> Option<BootReport> {
        self.boot.take()
    }

    /// Faults the rig reported on this link so far, oldest first.
    pub fn faults(&self) -> &[FaultReport] {
        &self.faults
    }

    /// Something that can send `Safe` and heartbeats on this link from another thread.
    pub(crate) fn handle(&self) -> hold::SafeHandle {
        hold::SafeHandle::new(self.tx.clone(), self.seq.clone())
    }

    /// Holds the rig for this session: a heartbeat renews its lease from a thread of its own until
    /// the returned guard is dropped, which sends `Safe` (heater and magnet off). Ctrl-C that
    /// quits at once and a panic send it too. A killed program or a lost cable is covered by the
    /// rig's lease.
    pub fn hold(&self) -> hold::Hold {
        hold::Hold::new(self.handle())
    }

    /// The next frame, waiting at most `timeout`; `Ok(None)` on timeout, an error when the stream
    /// ended. Frames that failed their CRC are counted and skipped.
    pub fn next(&mut self, timeout: Duration) -> Result<Option<Incoming>, LinkError> {
        if let Some(f) = self.backlog.pop_front() {
            return Ok(Some(f));
        }
        if self.closed.is_some() {
            return Err(self.closed_error());
        }
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(Event::Frame(f)) => {
                    self.stats.frames_in += 1;
                    if let DeviceMsg::Fault(r) = f.frame.msg {
                        self.faults.push(r);
                    }
                    return Ok(Some(*f));
                }
                Ok(Event::Bad(e)) => {
                    self.stats.bad_frames += 1;
                    self.last_bad = Some(e);
                }
                Ok(Event::Closed(why)) => {
                    self.closed = Some(why);
                    return Err(self.closed_error());
                }
                Err(RecvTimeoutError::Timeout) => return Ok(None),
                Err(RecvTimeoutError::Disconnected) => {
                    self.closed.get_or_insert_with(|| "reader stopped".into());
                    return Err(self.closed_error());
                }
            }
        }
    }

    /// Throws away whatever the rig sent so far (stale frames of an earlier session).
    pub fn drain(&mut self, quiet: Duration) -> Result<usize, LinkError> {
        let mut n = self.backlog.len();
        self.backlog.clear();
        while self.next(quiet)?.is_some() {
            n += 1;
        }
        Ok(n)
    }

    /// Opens the session: says hello, checks the protocol. Retries, then explains.
    pub fn hello(&mut self) -> Result<DeviceInfo, LinkError> {
        for _ in 0..self.timeouts.attempts.max(1) {
            let seq = self.send(&HostMsg::Hello {
                protocol: PROTOCOL_VERSION,
            })?;
            let deadline = Instant::now() + self.timeouts.reply;
            while let Some(left) = deadline.checked_duration_since(Instant::now()) {
                let Some(f) = self.next(left)? else { break };
                match f.frame.msg {
                    DeviceMsg::Hello(info) => {
                        check_protocol(info.protocol).map_err(|e| LinkError {
                            kind: LinkErrorKind::Protocol,
                            msg: e.to_string(),
                            code: None,
                        })?;
                        self.backlog.clear();
                        self.after_hello(seq)?;
                        return Ok(info);
                    }
                    DeviceMsg::Error(DeviceError {
                        code: c @ ErrorCode::ProtocolMismatch { .. },
                        about_seq,
                    }) if about_seq == Some(seq) => {
                        return Err(LinkError {
                            kind: LinkErrorKind::Protocol,
                            msg: explain(c),
                            code: Some(c),
                        });
                    }
                    _ => {} // stale frames of an earlier session
                }
            }
        }
        Err(LinkError::new(
            LinkErrorKind::NoAnswer,
            format!(
                "no answer from {} to hello after {} tries: is it a tribometer with its firmware running? Check the \
                 cable and the port (`tribo devices` lists attached rigs), or start a virtual one with `tribo rig \
                 --virtual`",
                self.name, self.timeouts.attempts
            ),
        ))
    }

    /// After the rig's hello: its boot report, if any, comes before the hello's `Ack`.
    fn after_hello(&mut self, seq: u32) -> Result<(), LinkError> {
        let deadline = Instant::now() + self.timeouts.reply;
        let mut held = Vec::new();
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            let Some(f) = self.rx_only(left)? else { break };
            match f.frame.msg {
                DeviceMsg::Ack { seq: s } if s == seq => break,
                DeviceMsg::Boot(b) => self.boot = Some(b),
                DeviceMsg::Ack { .. } | DeviceMsg::Error(_) => {}
                _ => held.push(f),
            }
        }
        self.backlog.extend(held);
        Ok(())
    }

    /// Sends a command and waits for its `Ack` (or `Error`). Idempotent commands are sent again
    /// when no answer comes; `Arm` and `Release` are not. Frames that are not the answer are kept
    /// for [`Link::next`].
    pub fn command(&mut self, msg: HostMsg) -> Result<(), LinkError> {
        // A self-test check is not sent twice either: it acts (a panic, a stall, an erase).
        let retry = !matches!(msg, HostMsg::Arm | HostMsg::Release | HostMsg::SelfTest(_));
        let attempts = if retry {
            self.timeouts.attempts.max(1)
        } else {
            1
        };
        for _ in 0..attempts {
            let seq = self.send(&msg)?;
            let deadline = Instant::now() + self.timeouts.reply;
            let mut held = Vec::new();
            let answer = loop {
                let left = deadline.saturating_duration_since(Instant::now());
                let f = match self.rx_only(left) {
                    Ok(Some(f)) => f,
                    Ok(None) => break None,
                    Err(e) => {
                        self.backlog.extend(held);
                        return Err(e);
                    }
                };
                match &f.frame.msg {
                    DeviceMsg::Ack { seq: s } if *s == seq => break Some(Ok(())),
                    DeviceMsg::Error(DeviceError {
                        code,
                        about_seq: Some(s),
                    }) if *s == seq => break Some(Err(*code)),
                    // A release answered by the run itself (its Ack lost): the run started.
                    DeviceMsg::RunStarted(_) if matches!(msg, HostMsg::Release) => {
                        held.push(f);
                        break Some(Ok(()));
                    }
                    DeviceMsg::Ack { .. }
                    | DeviceMsg::Error(DeviceError {
                        about_seq: Some(_), ..
                    }) => {}
                    _ => held.push(f),
                }
            };
            self.backlog.extend(held);
            match answer {
                Some(Ok(())) => return Ok(()),
                Some(Err(code)) => {
                    return Err(LinkError {
                        kind: LinkErrorKind::Refused,
                        msg: explain(code),
                        code: Some(code),
                    })
                }
                None => {}
            }
        }
        Err(LinkError::new(
            LinkErrorKind::NoAnswer,
            format!(
                "the rig on {} did not answer {} (after {attempts} tries): check the cable; if it persists, \
                 power-cycle the rig",
                self.name,
                command_name(&msg)
            ),
        ))
    }

    /// Like [`Link::next`] but ignores the backlog (used while waiting for an answer).
    fn rx_only(&mut self, timeout: Duration) -> Result<Option<Incoming>, LinkError> {
        let saved = std::mem::take(&mut self.backlog);
        let r = self.next(timeout);
        self.backlog = saved;
        r
    }

    /// Asks for the rig's status.
    pub fn status(&mut self) -> Result<Status, LinkError> {
        for _ in 0..self.timeouts.attempts.max(1) {
            self.send(&HostMsg::Status)?;
            let deadline = Instant::now() + self.timeouts.reply;
            let mut held = Vec::new();
            let mut got = None;
            while let Some(left) = deadline.checked_duration_since(Instant::now()) {
                match self.rx_only(left)? {
                    Some(f) => match f.frame.msg {
                        DeviceMsg::Status(s) => {
                            got = Some(s);
                            break;
                        }
                        DeviceMsg::Ack { .. } => {}
                        _ => held.push(f),
                    },
                    None => break,
                }
            }
            self.backlog.extend(held);
            if let Some(s) = got {
                return Ok(s);
            }
        }
        Err(LinkError::new(
            LinkErrorKind::NoAnswer,
            format!("the rig on {} does not answer status requests: check the cable, or power-cycle the rig", self.name),
        ))
    }
}
