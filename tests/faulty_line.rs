//! A faulty line between the host and a virtual rig, for the fault-injection tests: a local TCP
//! connection whose two directions drop or corrupt whole frames (seeded, so a failure can be
//! replayed), drop chosen frames once, or are cut after so many bytes (the cable pulled).
//!
//! [`Bench`] owns the virtual rig and serves it to one host session at a time through such a
//! line; between sessions the rig is the test's (its clock stands still unless the test advances
//! it, with the cable out), so a test can run it on, power-cycle it, and ask it for its own copy of
//! the run over a clean line. [`Bench::lend`] serves it for a while to whoever connects, as
//! `tribo rig --virtual` does ([`TcpRig`]: one host at a time), then takes it back.
#![allow(dead_code)]

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tribo::link::Link;
use tribo_physics::stats::Rng;
use tribo_rig::{serve, HostEvent, ServeOptions, TcpRig, VirtualRig};
use tribo_wire::frame::decode_one;
use tribo_wire::{DeviceMsg, HostMsg, RigState};

/// What goes wrong on the line.
#[derive(Clone, Default)]
pub struct Faults {
    pub seed: u64,
    /// Frames dropped, per 100 000, in each direction.
    pub drop_per_100k: u32,
    /// Frames with one byte changed (their CRC then fails), per 100 000, in each direction.
    pub corrupt_per_100k: u32,
    /// Nothing is damaged either way until the host's `Release` has passed (the commands before
    /// it, `Arm` and `Release` above all, are never repeated blindly: a lost one is an error by
    /// design).
    pub spare_until_release: bool,
    /// Rig frames dropped once each, the first time one matching it passes.
    pub drop_once: Vec<fn(&DeviceMsg) -> bool>,
    /// Rig frames dropped every time.
    pub drop_always: Option<fn(&DeviceMsg) -> bool>,
    /// Host frames after this many never reach the rig (a line dead one way).
    pub deaf_after_host_frames: Option<u64>,
    /// Rig-to-host bytes after which the line is cut (the cable pulled).
    pub cut_after_bytes: Option<u64>,
    /// Rig-to-host bytes after which the rig loses its power (then comes back: a power cycle at
    /// that instant of its clock); the line goes with it. Mid-run, the run is cut short.
    pub power_cut_after_bytes: Option<u64>,
}

impl Faults {
    /// A line that drops and corrupts `per_100k` / 100 000 of the frames each way (half each).
    pub fn lossy(seed: u64, per_100k: u32) -> Faults {
        Faults {
            seed,
            drop_per_100k: per_100k / 2,
            corrupt_per_100k: per_100k - per_100k / 2,
            spare_until_release: true,
            ..Faults::default()
        }
    }
}

/// What the line did.
#[derive(Debug, Default)]
pub struct LineStats {
    pub rig_frames: AtomicU64,
    pub rig_dropped: AtomicU64,
    pub rig_corrupted: AtomicU64,
    pub host_frames: AtomicU64,
    pub host_dropped: AtomicU64,
    pub host_corrupted: AtomicU64,
    /// Every frame the rig sent, as it sent it (before the line's faults).
    pub sent: Mutex<Vec<Vec<u8>>>,
}

impl LineStats {
    pub fn damaged_rig_frames(&self) -> u64 {
        self.rig_dropped.load(Ordering::Relaxed) + self.rig_corrupted.load(Ordering::Relaxed)
    }
    pub fn damaged_host_frames(&self) -> u64 {
        self.host_dropped.load(Ordering::Relaxed) + self.host_corrupted.load(Ordering::Relaxed)
    }
}

enum Fate {
    Pass,
    Drop,
    Corrupt,
}

struct Shared {
    faults: Faults,
    stats: Arc<LineStats>,
    rng: Mutex<Rng>,
    /// The spared host frames went through: faults from now on.
    live: AtomicBool,
    dropped_once: Mutex<Vec<bool>>,
    cut: AtomicBool,
    stream: TcpStream,
}

impl Shared {
    fn fate(&self) -> Fate {
        if !self.live.load(Ordering::Relaxed) {
            return Fate::Pass;
        }
        let r = self.rng.lock().unwrap().next_u64() % 100_000;
        let f = &self.faults;
        if r < f.drop_per_100k as u64 {
            Fate::Drop
        } else if r < (f.drop_per_100k + f.corrupt_per_100k) as u64 {
            Fate::Corrupt
        } else {
            Fate::Pass
        }
    }

    /// Changes one byte of a frame (not its closing zero, never into a zero).
    fn corrupt(&self, frame: &mut [u8]) {
        if frame.len() < 2 {
            return;
        }
        let mut rng = self.rng.lock().unwrap();
        let at = (rng.next_u64() % (frame.len() as u64 - 1)) as usize;
        let mut x = (rng.next_u64() % 255 + 1) as u8;
        if frame[at] ^ x == 0 {
            x ^= 0x80;
        }
        frame[at] ^= x;
    }

    fn cut(&self) {
        self.cut.store(true, Ordering::Relaxed);
        let _ = self.stream.shutdown(Shutdown::Both);
    }
}

/// The rig's output, which fails (the power gone) once so many bytes went out: the rig's serving
/// loop stops at that instant of the rig's clock.
struct PowerCut {
    inner: TcpStream,
    left: Option<u64>,
    cut: bool,
}

impl Write for PowerCut {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if let Some(left) = self.left.as_mut() {
            if (buf.len() as u64) >= *left {
                self.cut = true;
                let _ = self.inner.shutdown(Shutdown::Both);
                return Err(io::Error::new(io::ErrorKind::BrokenPipe, "the power went"));
            }
            *left -= buf.len() as u64;
        }
        self.inner.write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// The rig-to-host direction.
struct Down {
    inner: TcpStream,
    shared: Arc<Shared>,
    cur: Vec<u8>,
    out: VecDeque<u8>,
    bytes: u64,
}

impl Read for Down {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let mut tmp = [0u8; 4096];
        while self.out.is_empty() {
            if self.shared.cut.load(Ordering::Relaxed) {
                return Ok(0);
            }
            let n = self.inner.read(&mut tmp)?;
            if n == 0 {
                return Ok(0);
            }
            for &b in &tmp[..n] {
                if let Some(limit) = self.shared.faults.cut_after_bytes {
                    if self.bytes >= limit {
                        self.shared.cut();
                        break;
                    }
                }
                self.bytes += 1;
                self.cur.push(b);
                if b != 0 {
                    continue;
                }
                let mut frame = std::mem::take(&mut self.cur);
                let s = &self.shared;
                s.stats.rig_frames.fetch_add(1, Ordering::Relaxed);
                s.stats.sent.lock().unwrap().push(frame.clone());
                if let Ok(f) = decode_one::<DeviceMsg>(&frame) {
                    if s.faults.drop_always.is_some_and(|d| d(&f.msg)) {
                        s.stats.rig_dropped.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    let mut once = s.dropped_once.lock().unwrap();
                    if let Some(i) = (0..s.faults.drop_once.len())
                        .find(|&i| !once[i] && (s.faults.drop_once[i])(&f.msg))
                    {
                        once[i] = true;
                        s.stats.rig_dropped.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                }
                match s.fate() {
                    Fate::Pass => {}
                    Fate::Drop => {
                        s.stats.rig_dropped.fetch_add(1, Ordering::Relaxed);
                        continue;
                    }
                    Fate::Corrupt => {
                        s.stats.rig_corrupted.fetch_add(1, Ordering::Relaxed);
                        s.corrupt(&mut frame);
                    }
                }
                self.out.extend(frame);
            }
        }
        let n = buf.len().min(self.out.len());
        for (d, s) in buf.iter_mut().zip(self.out.drain(..n)) {
            *d = s;
        }
        Ok(n)
    }
}

/// The host-to-rig direction.
struct Up {
    inner: TcpStream,
    shared: Arc<Shared>,
    cur: Vec<u8>,
}

impl Write for Up {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        if self.shared.cut.load(Ordering::Relaxed) {
            return Err(io::Error::new(
                io::ErrorKind::BrokenPipe,
                "the cable was pulled",
            ));
        }
        for &b in buf {
            self.cur.push(b);
            if b != 0 {
                continue;
            }
            let mut frame = std::mem::take(&mut self.cur);
            let s = &self.shared;
            let n = s.stats.host_frames.fetch_add(1, Ordering::Relaxed) + 1;
            if s.faults.deaf_after_host_frames.is_some_and(|k| n > k) {
                s.stats.host_dropped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            let fate = s.fate();
            if !s.live.load(Ordering::Relaxed)
                && matches!(
                    decode_one::<HostMsg>(&frame).map(|f| f.msg),
                    Ok(HostMsg::Release)
                )
            {
                s.live.store(true, Ordering::Relaxed);
            }
            match fate {
                Fate::Pass => {}
                Fate::Drop => {
                    s.stats.host_dropped.fetch_add(1, Ordering::Relaxed);
                    continue;
                }
                Fate::Corrupt => {
                    s.stats.host_corrupted.fetch_add(1, Ordering::Relaxed);
                    s.corrupt(&mut frame);
                }
            }
            self.inner.write_all(&frame)?;
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

/// A virtual rig on the bench, served to one host session at a time.
pub struct Bench {
    rig: Option<VirtualRig>,
    pub opts: ServeOptions,
}

impl Bench {
    /// Serves `rig` as fast as the simulation goes.
    pub fn new(rig: VirtualRig) -> Bench {
        Bench {
            rig: Some(rig),
            opts: ServeOptions {
                speed: f64::INFINITY,
                ..ServeOptions::default()
            },
        }
    }

    /// The rig, between sessions.
    pub fn rig(&mut self) -> &mut VirtualRig {
        self.rig.as_mut().expect("not in a session")
    }

    /// A host session through a line with `faults`: `f` gets the link (with short reply timeouts);
    /// the session ends (the host hangs up) when `f` returns. Returns what `f` returned and what
    /// the line did.
    pub fn session<T>(
        &mut self,
        faults: Faults,
        f: impl FnOnce(&mut Link) -> T,
    ) -> (T, Arc<LineStats>) {
        let mut rig = self.rig.take().expect("one session at a time");
        rig.set_connected(true);
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let host = TcpStream::connect(l.local_addr().unwrap()).unwrap();
        let (rig_end, _) = l.accept().unwrap();
        host.set_nodelay(true).unwrap();
        let opts = self.opts;
        let power_cut = faults.power_cut_after_bytes;
        let serving = std::thread::spawn(move || {
            let reader = rig_end.try_clone().unwrap();
            let mut out = PowerCut {
                inner: rig_end,
                left: power_cut,
                cut: false,
            };
            let _ = serve(&mut rig, reader, &mut out, &opts);
            if out.cut {
                rig.power_cycle();
            }
            rig
        });
        let reader = host.try_clone().unwrap();
        reader
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let stats = Arc::new(LineStats::default());
        let shared = Arc::new(Shared {
            rng: Mutex::new(Rng::new(faults.seed)),
            live: AtomicBool::new(!faults.spare_until_release),
            dropped_once: Mutex::new(vec![false; faults.drop_once.len()]),
            faults,
            stats: stats.clone(),
            cut: AtomicBool::new(false),
            stream: host.try_clone().unwrap(),
        });
        let mut link = Link::from_stream(
            "faulty line",
            Down {
                inner: reader,
                shared: shared.clone(),
                cur: vec![],
                out: VecDeque::new(),
                bytes: 0,
            },
            Up {
                inner: host,
                shared: shared.clone(),
                cur: vec![],
            },
        );
        link.timeouts.reply = Duration::from_millis(250);
        link.timeouts.stream_idle = Duration::from_millis(600);
        let out = f(&mut link);
        drop(link);
        let _ = shared.stream.shutdown(Shutdown::Both);
        let mut rig = serving.join().expect("the rig's thread");
        rig.set_connected(false);
        self.rig = Some(rig);
        (out, stats)
    }

    /// Lends the rig to a [`TcpRig`] (served with [`Bench::opts`], over clean local TCP, one host
    /// at a time, the next one waiting up to its hand-over time) while `f` runs with its address;
    /// then stops it and takes the rig back. Returns what `f` returned and what the rig's console
    /// heard of the hosts.
    pub fn lend<T>(&mut self, f: impl FnOnce(SocketAddr) -> T) -> (T, Vec<HostEvent>) {
        let rig = self.rig.take().expect("one session at a time");
        let events = Arc::new(Mutex::new(Vec::new()));
        let heard = events.clone();
        let tcp = TcpRig::spawn(
            rig,
            TcpListener::bind("127.0.0.1:0").unwrap(),
            self.opts,
            move |e| heard.lock().unwrap().push(e),
        )
        .expect("serving the rig on TCP");
        let out = f(tcp.addr());
        self.rig = Some(tcp.stop());
        let events = std::mem::take(&mut *events.lock().unwrap());
        (out, events)
    }

    /// Runs the rig on with nobody connected (the cable out) for `seconds` of its time, or until
    /// its run has ended.
    pub fn run_on(&mut self, seconds: f64) {
        let rig = self.rig();
        rig.set_connected(false);
        let end = rig.now_us() + (seconds * 1e6) as u64;
        while rig.now_us() < end {
            let t = (rig.now_us() + 100_000).min(end);
            rig.advance_to(t);
            if rig.app().state() != RigState::Running {
                break;
            }
        }
    }

    /// The rig's own copy of run `run_id`, byte for byte: a `Pull` from block 0 over a clean line,
    /// every run frame until the end (or, for a run without one, until the rig falls silent).
    pub fn rig_frames(&mut self, run_id: u32) -> Vec<Vec<u8>> {
        self.session(Faults::default(), |link| {
            // A clean line: a late answer is a busy machine, not a fault under test.
            link.timeouts.reply = Duration::from_secs(3);
            link.hello().expect("hello");
            rig_copy(link, run_id)
        })
        .0
    }
}

/// The rig's own copy of its run `run_id`, byte for byte, over `link` (a clean line, hello said):
/// a `Pull` from block 0, every run frame until the end (or, for a run without one, until the rig
/// falls silent). Panics when the line fails or the rig no longer holds the run.
pub fn rig_copy(link: &mut Link, run_id: u32) -> Vec<Vec<u8>> {
    // A clean line: a late answer is a busy machine (CI runs tests side by side), not a fault
    // under test.
    link.timeouts.reply = Duration::from_secs(3);
    // A rig reconnected first sends the rest of its live stream (what the cable's absence held
    // back): let it pass, then ask.
    while link.drain(Duration::from_millis(200)).expect("clean line") > 0 {}
    link.command(HostMsg::Pull {
        run_id,
        from_block: 0,
    })
    .expect("the rig holds the run");
    let mut frames = vec![];
    let mut last = Instant::now();
    // Silent for longer than a sector erase (2.2 s at most): the rig erases the next run's first
    // sector ahead after a run and after a boot, and a run held in flash only waits for it.
    while last.elapsed() < Duration::from_millis(2500) {
        let Some(f) = link.next(Duration::from_millis(50)).expect("clean line") else {
            continue;
        };
        last = Instant::now();
        if f.msg().is_run_frame() {
            let end = matches!(f.msg(), DeviceMsg::RunEnded(_));
            frames.push(f.raw);
            if end {
                break;
            }
        }
    }
    frames
}
