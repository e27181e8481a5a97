//! Serving the virtual rig to a host: over one byte stream ([`serve`]), to successive TCP
//! connections ([`TcpRig`], what `tribo rig --virtual` runs), or in-process ([`in_process`], what
//! `tribo demo` uses). In every case the simulation follows the wall clock (times
//! [`ServeOptions::speed`]) and a simulated hand may work the rig's load knob and button.
//!
//! The rig behind a [`TcpRig`] lives on between connections, as a real rig does when its cable is
//! pulled: its clock runs, a run in progress goes on and waits in its memory, and the next host to
//! connect can `Pull` it. It serves one host at a time.

use crate::{RigError, VirtualRig};
use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender, TryRecvError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tribo_wire::{Decoder, Frame, HostMsg, RigState};

/// How the rig is served.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServeOptions {
    /// Device seconds per wall-clock second (1 = real time; `f64::INFINITY` = as fast as possible).
    pub speed: f64,
    /// Longest wait for host bytes before the simulation moves on, wall-clock.
    pub max_wait: Duration,
    /// The load knob follows the load of each `Configure` received while no run is in progress (a
    /// virtual rig has no hand on its knob): the rig is rebuilt at the new load, as if
    /// power-cycled, keeping the plate's temperature.
    pub follow_load: bool,
    /// A finger on the rig's button: pressed this many device seconds after each arming, held 50 ms.
    pub button_after_s: Option<f64>,
    /// Print the rig's console ([`VirtualRig::take_events`]: commands that change its state,
    /// faults, resets) on standard output, one line each.
    pub log_events: bool,
}

impl Default for ServeOptions {
    /// Real time, knob and button left alone.
    fn default() -> Self {
        ServeOptions {
            speed: 1.0,
            max_wait: Duration::from_millis(2),
            follow_load: false,
            button_after_s: None,
            log_events: false,
        }
    }
}

impl ServeOptions {
    /// Refuses options under which the rig would never advance or the button never be pressed.
    pub fn validate(&self) -> Result<(), RigError> {
        if self.speed.is_nan() || self.speed <= 0.0 {
            return Err(RigError::Setting {
                name: "speed",
                rule: "> 0 (1 = real time, inf = as fast as possible)",
                value: self.speed,
            });
        }
        if let Some(b) = self.button_after_s {
            if !(b.is_finite() && b >= 0.0) {
                return Err(RigError::Setting {
                    name: "the button's delay after arming, s,",
                    rule: "finite and ≥ 0",
                    value: b,
                });
            }
        }
        Ok(())
    }

    fn invalid(&self) -> Option<io::Error> {
        self.validate()
            .err()
            .map(|e| io::Error::new(io::ErrorKind::InvalidInput, e))
    }
}

/// The rig on its bench: its clock tied to the wall clock, a hand on its knob and button.
struct Bench<'r> {
    rig: &'r mut VirtualRig,
    opts: ServeOptions,
    /// Host frames, watched for the load they configure (`follow_load`).
    decoder: Decoder<HostMsg>,
    /// Wall-clock instant and device time that correspond.
    anchor: (Instant, u64),
    armed_since: Option<u64>,
    pressed_at: Option<u64>,
}

impl<'r> Bench<'r> {
    fn new(rig: &'r mut VirtualRig, opts: ServeOptions) -> Bench<'r> {
        // Served faster than real time, the firmware's lease is stretched by the speed, so that a
        // host talking in real time keeps it as it would with the real rig.
        rig.set_host_lease_ms(crate::lease_for_speed(opts.speed));
        let anchor = (Instant::now(), rig.now_us());
        Bench {
            rig,
            opts,
            decoder: Decoder::new(),
            anchor,
            armed_since: None,
            pressed_at: None,
        }
    }

    fn fast(&self) -> bool {
        !self.opts.speed.is_finite()
    }

    /// How long to wait for host bytes before the next step.
    fn wait(&self) -> Duration {
        if self.fast() {
            Duration::ZERO
        } else {
            self.opts.max_wait
        }
    }

    /// A new host: forget a half-received frame.
    fn reset_link(&mut self) {
        self.decoder.reset();
        self.rig.app.link_reset();
    }

    /// Bytes from the host (the knob turned first, when they configure another load).
    fn input(&mut self, bytes: &[u8]) {
        if self.opts.follow_load {
            let mut load = None;
            self.decoder.feed(bytes, |f| {
                if let Ok(Frame {
                    msg: HostMsg::Configure(c),
                    ..
                }) = f
                {
                    load = Some(c.rig.load_n as f64);
                }
            });
            let idle = !matches!(self.rig.app().state(), RigState::Running);
            let current = self.rig.config().load_n;
            if let Some(l) = load.filter(|l| idle && (*l - current).abs() > 1e-6) {
                // A load the simulated rig refuses leaves the knob where it is; the firmware then
                // answers the Configure itself.
                let _ = self.rig.turn_load_knob(l);
            }
        }
        self.rig.input(bytes);
    }

    /// Advances the rig to the wall clock (10 ms per step when as fast as possible), works the
    /// button, and returns the bytes for the host.
    fn step(&mut self) -> Vec<u8> {
        let target = if self.fast() {
            self.rig.now_us() + 10_000
        } else {
            let (wall, dev) = self.anchor;
            dev + (wall.elapsed().as_secs_f64() * self.opts.speed * 1e6) as u64
        };
        self.rig.advance_to(target);
        crate::print_events(self.rig, &self.opts);
        if let Some(after) = self.opts.button_after_s {
            let now = self.rig.now_us();
            if matches!(self.rig.app().state(), RigState::Armed) {
                let since = *self.armed_since.get_or_insert(now);
                if self.pressed_at.is_none() && now.saturating_sub(since) as f64 >= after * 1e6 {
                    self.rig.set_button(true);
                    self.pressed_at = Some(now);
                }
            } else {
                self.armed_since = None;
            }
            if self
                .pressed_at
                .is_some_and(|t| now.saturating_sub(t) >= 50_000)
            {
                self.rig.set_button(false);
                self.pressed_at = None;
            }
        }
        self.rig.take_output()
    }
}

/// Reads `reader` on a thread of its own into a channel, until end of file, a read error or
/// `stop`. Reads that time out (`TimedOut`, `WouldBlock`) are retried, so a reader with a read
/// timeout lets the thread notice `stop`.
fn spawn_reader(
    mut reader: impl Read + Send + 'static,
    stop: Arc<AtomicBool>,
) -> Receiver<Vec<u8>> {
    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    std::thread::Builder::new()
        .name("tribo-virtual-rig-input".into())
        .spawn(move || {
            let mut buf = [0u8; 4096];
            while !stop.load(Ordering::Relaxed) {
                match reader.read(&mut buf) {
                    Ok(0) => return,
                    Ok(n) => {
                        if tx.send(buf[..n].to_vec()).is_err() {
                            return;
                        }
                    }
                    Err(e)
                        if matches!(
                            e.kind(),
                            io::ErrorKind::Interrupted
                                | io::ErrorKind::TimedOut
                                | io::ErrorKind::WouldBlock
                        ) => {}
                    Err(_) => return,
                }
            }
        })
        .expect("spawning a thread");
    rx
}

/// Waits at most `wait` for host bytes and takes all that came; `Err(())` once the stream ended.
fn receive(rx: &Receiver<Vec<u8>>, wait: Duration) -> Result<Vec<u8>, ()> {
    let mut input = match rx.recv_timeout(wait) {
        Ok(b) => b,
        Err(RecvTimeoutError::Timeout) => return Ok(vec![]),
        Err(RecvTimeoutError::Disconnected) => return Err(()),
    };
    loop {
        match rx.try_recv() {
            Ok(more) => input.extend(more),
            Err(TryRecvError::Empty) => return Ok(input),
            // What came before the end is still the host's.
            Err(TryRecvError::Disconnected) => return Ok(input),
        }
    }
}

/// Serves the rig over a byte stream: host frames are read from `reader` (on a thread of its own),
/// device frames written to `writer`, and the simulation advances with the wall clock times
/// `opts.speed`. Returns `Ok(())` when `reader` reaches end of file or fails (the cable is pulled),
/// and an error when `writer` fails or `opts` are invalid. The rig keeps its state, stored run
/// included: call `serve` again on the same rig to reconnect (its clock stood still in between;
/// [`TcpRig`] keeps it running).
///
/// For a stream that is both (a socket, a serial port), pass `s.try_clone()?` and `s`. Reads that
/// time out are retried; the reader thread ends at end of file, or at its next read after `serve`
/// returned.
pub fn serve<R, W>(
    rig: &mut VirtualRig,
    reader: R,
    mut writer: W,
    opts: &ServeOptions,
) -> io::Result<()>
where
    R: Read + Send + 'static,
    W: Write,
{
    if let Some(e) = opts.invalid() {
        return Err(e);
    }
    let stop = Arc::new(AtomicBool::new(false));
    let rx = spawn_reader(reader, stop.clone());
    let mut bench = Bench::new(rig, *opts);
    bench.reset_link();
    let result = loop {
        let (input, closed) = match receive(&rx, bench.wait()) {
            Ok(b) => (b, false),
            Err(()) => (vec![], true),
        };
        if !input.is_empty() {
            bench.input(&input);
        }
        let out = bench.step();
        if !out.is_empty() {
            if let Err(e) = writer.write_all(&out).and_then(|_| writer.flush()) {
                break Err(e);
            }
        }
        if closed {
            break Ok(());
        }
    };
    stop.store(true, Ordering::Relaxed);
    result
}

/// What happened to a [`TcpRig`]'s connections (for its console).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HostEvent {
    /// A host connected.
    Connected(SocketAddr),
    /// The host went (closed the connection, or stopped reading for longer than the write timeout).
    Disconnected(SocketAddr, String),
    /// A second host was turned away: the rig serves one host at a time.
    Refused(SocketAddr),
}

/// How long a new host waits for the one being served to go before it is turned away.
pub const HANDOVER: Duration = Duration::from_secs(1);
/// A host that takes no bytes for this long is disconnected (the rig does not wait for it).
const WRITE_TIMEOUT: Duration = Duration::from_secs(2);
/// Read timeout of a connection, so that its reader notices the rig letting go of it.
const READ_TIMEOUT: Duration = Duration::from_millis(50);

/// The connection of the host being served.
struct Conn {
    peer: SocketAddr,
    stream: TcpStream,
    rx: Receiver<Vec<u8>>,
    stop: Arc<AtomicBool>,
}

impl Conn {
    fn open(stream: TcpStream, peer: SocketAddr) -> io::Result<Conn> {
        stream.set_nonblocking(false)?;
        stream.set_nodelay(true)?;
        stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
        let reader = stream.try_clone()?;
        reader.set_read_timeout(Some(READ_TIMEOUT))?;
        let stop = Arc::new(AtomicBool::new(false));
        let rx = spawn_reader(reader, stop.clone());
        Ok(Conn {
            peer,
            stream,
            rx,
            stop,
        })
    }

    fn close(self) {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.stream.shutdown(Shutdown::Both);
    }
}

/// A virtual rig served on a TCP listener, on a thread of its own, until stopped ([`TcpRig::stop`],
/// which hands the rig back) or dropped (the rig goes with it).
pub struct TcpRig {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<VirtualRig>>,
}

impl TcpRig {
    /// Serves `rig` to the hosts that connect to `listener`, one at a time, until the returned
    /// value is stopped or dropped. The rig runs between connections; `events` hears of each host (on the
    /// rig's thread: keep it short).
    pub fn spawn(
        rig: VirtualRig,
        listener: TcpListener,
        opts: ServeOptions,
        events: impl FnMut(HostEvent) + Send + 'static,
    ) -> io::Result<TcpRig> {
        if let Some(e) = opts.invalid() {
            return Err(e);
        }
        let addr = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::Builder::new()
            .name("tribo-virtual-rig".into())
            .spawn(move || serve_tcp(rig, listener, opts, s, events))?;
        Ok(TcpRig {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    /// The address hosts connect to.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Serves until the process ends.
    pub fn wait(mut self) {
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }

    /// Stops serving and hands the rig back, as it is now: the host being served (if any) is
    /// disconnected and one waiting is turned away, the rig's cable is out, its run and its clock
    /// are as they were (a test can then take it on, or serve it again). A panic of the rig's
    /// thread is passed on.
    pub fn stop(mut self) -> VirtualRig {
        self.stop.store(true, Ordering::Relaxed);
        let t = self
            .thread
            .take()
            .expect("the rig's thread is joined only once");
        match t.join() {
            Ok(rig) => rig,
            Err(panic) => std::panic::resume_unwind(panic),
        }
    }
}

impl Drop for TcpRig {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Serves the host that waits (if any) on a rig that serves none.
fn admit(
    bench: &mut Bench<'_>,
    waiting: Option<(TcpStream, SocketAddr, Instant)>,
    events: &mut impl FnMut(HostEvent),
) -> Option<Conn> {
    let (s, peer, _) = waiting?;
    match Conn::open(s, peer) {
        Ok(c) => {
            bench.rig.set_connected(true);
            bench.reset_link();
            events(HostEvent::Connected(peer));
            Some(c)
        }
        Err(e) => {
            events(HostEvent::Disconnected(peer, e.to_string()));
            None
        }
    }
}

fn serve_tcp(
    mut rig: VirtualRig,
    listener: TcpListener,
    opts: ServeOptions,
    stop: Arc<AtomicBool>,
    mut events: impl FnMut(HostEvent),
) -> VirtualRig {
    let mut bench = Bench::new(&mut rig, opts);
    // No host yet: the cable is out.
    bench.rig.set_connected(false);
    let mut conn: Option<Conn> = None;
    // A host waiting for the one being served to go.
    let mut pending: Option<(TcpStream, SocketAddr, Instant)> = None;
    while !stop.load(Ordering::Relaxed) {
        // Knocks at the door. A free rig takes the host that knocked first before the next knock
        // is heard, so that two hosts knocking at once are one served and one waiting its turn
        // (not one turned away at once).
        loop {
            if conn.is_none() {
                conn = admit(&mut bench, pending.take(), &mut events);
            }
            match listener.accept() {
                Ok((s, peer)) => {
                    if pending.is_none() {
                        pending = Some((s, peer, Instant::now()));
                    } else {
                        let _ = s.shutdown(Shutdown::Both);
                        events(HostEvent::Refused(peer));
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                // WouldBlock: nobody else; other errors (a connection reset while queued, out of
                // descriptors) concern that connection only.
                Err(_) => break,
            }
        }
        if conn.is_none() {
            conn = admit(&mut bench, pending.take(), &mut events);
        } else if pending.as_ref().is_some_and(|p| p.2.elapsed() > HANDOVER) {
            let (s, peer, _) = pending.take().expect("checked");
            let _ = s.shutdown(Shutdown::Both);
            events(HostEvent::Refused(peer));
        }
        let mut lost: Option<String> = None;
        match &conn {
            Some(c) => match receive(&c.rx, bench.wait()) {
                Ok(input) if !input.is_empty() => bench.input(&input),
                Ok(_) => {}
                Err(()) => lost = Some("the host closed the connection".into()),
            },
            None => std::thread::sleep(opts.max_wait.max(Duration::from_millis(1))),
        }
        let out = bench.step();
        if let Some(c) = conn.as_mut() {
            if !out.is_empty() {
                if let Err(e) = c.stream.write_all(&out) {
                    lost.get_or_insert_with(|| match e.kind() {
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => {
                            "the host stopped reading".into()
                        }
                        _ => format!("writing to the host failed: {e}"),
                    });
                }
            }
        }
        if let Some(why) = lost {
            if let Some(c) = conn.take() {
                let peer = c.peer;
                c.close();
                bench.rig.set_connected(false);
                events(HostEvent::Disconnected(peer, why));
            }
        }
    }
    if let Some(c) = conn.take() {
        c.close();
    }
    if let Some((s, _, _)) = pending.take() {
        let _ = s.shutdown(Shutdown::Both);
    }
    bench.rig.set_connected(false);
    rig
}

/// The host's end of an in-process rig: bytes from the rig. Reads block until the rig sends or
/// stops (then end of file).
pub struct PipeReader {
    rx: Receiver<Vec<u8>>,
    buf: Vec<u8>,
    pos: usize,
}

impl Read for PipeReader {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        if self.pos == self.buf.len() {
            match self.rx.recv() {
                Ok(b) => {
                    self.buf = b;
                    self.pos = 0;
                }
                Err(_) => return Ok(0),
            }
        }
        let n = out.len().min(self.buf.len() - self.pos);
        out[..n].copy_from_slice(&self.buf[self.pos..self.pos + n]);
        self.pos += n;
        Ok(n)
    }
}

/// The host's end of an in-process rig: bytes to the rig. Dropping it is pulling the cable.
pub struct PipeWriter {
    tx: Sender<Vec<u8>>,
}

impl Write for PipeWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.tx
            .send(buf.to_vec())
            .map_err(|_| io::Error::new(io::ErrorKind::BrokenPipe, "the virtual rig stopped"))?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// A one-way in-memory byte pipe.
fn pipe() -> (PipeWriter, PipeReader) {
    let (tx, rx) = mpsc::channel();
    (
        PipeWriter { tx },
        PipeReader {
            rx,
            buf: Vec::new(),
            pos: 0,
        },
    )
}

/// Serves `rig` in this process, on a thread of its own, through in-memory pipes: no socket, no
/// terminal. Returns the host's ends (read the rig's frames from the first, write commands to the
/// second) and the serving thread, which ends when the host drops its writer (the run's frames
/// stay in the rig's memory, which goes with it).
pub fn in_process(
    mut rig: VirtualRig,
    opts: ServeOptions,
) -> io::Result<(PipeReader, PipeWriter, JoinHandle<io::Result<()>>)> {
    if let Some(e) = opts.invalid() {
        return Err(e);
    }
    let (to_rig, rig_in) = pipe();
    let (rig_out, from_rig) = pipe();
    let thread = std::thread::Builder::new()
        .name("tribo-virtual-rig".into())
        .spawn(move || serve(&mut rig, rig_in, rig_out, &opts))?;
    Ok((from_rig, to_rig, thread))
}
