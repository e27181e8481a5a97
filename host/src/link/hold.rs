//! While a session holds the rig: a heartbeat renews the rig's lease, and every exit the host
//! controls leaves the rig safe.
//!
//! The rig keeps heating and holding its magnet only while a host renews its lease
//! ([`limits::HOST_LEASE_MS`]): commands that act on the rig do, queries (status polls) do not, so
//! the heartbeat thread of a [`Hold`] sends [`HostMsg::Heartbeat`] every [`limits::HEARTBEAT_MS`]
//! for as long as the session holds the rig (long fits, prompts, settling included). The exits:
//!
//! | exit | what makes the rig safe |
//! |---|---|
//! | the command returns, fails, or stops on a closed pipe | [`Hold`]'s drop sends [`HostMsg::Safe`] |
//! | a panic | the unwinding drops the [`Hold`]: `Safe` |
//! | Ctrl-C, SIGTERM, SIGHUP | the command stops cleanly (drop: `Safe`); a second Ctrl-C quits at once after [`make_all_safe`] |
//! | `kill -9`, a crash, a lost cable, a hung host | no heartbeat: the rig's lease expires and it goes safe by itself |

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tribo_wire::frame::encode_vec;
use tribo_wire::{limits, HostMsg};

use super::SharedWriter;

/// Sends frames on a link from any thread, without waiting for answers.
#[derive(Clone)]
pub struct SafeHandle {
    tx: SharedWriter,
    seq: Arc<AtomicU32>,
}

impl SafeHandle {
    pub(crate) fn new(tx: SharedWriter, seq: Arc<AtomicU32>) -> Self {
        SafeHandle { tx, seq }
    }

    /// Sends `msg` with the link's next sequence number. Gives up (false) if the link's writer stays
    /// busy for `patience` (a port that takes nothing), or the write fails.
    fn send(&self, msg: &HostMsg, patience: Duration) -> bool {
        let seq = self.seq.fetch_add(1, Ordering::Relaxed).wrapping_add(1);
        let Ok(bytes) = encode_vec(seq, msg) else {
            return false;
        };
        let deadline = Instant::now() + patience;
        loop {
            match self.tx.try_lock() {
                Ok(mut w) => return w.write_all(&bytes).and_then(|_| w.flush()).is_ok(),
                Err(std::sync::TryLockError::Poisoned(p)) => {
                    let mut w = p.into_inner();
                    return w.write_all(&bytes).and_then(|_| w.flush()).is_ok();
                }
                Err(std::sync::TryLockError::WouldBlock) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(2));
                }
                Err(std::sync::TryLockError::WouldBlock) => return false,
            }
        }
    }

    /// Heater and magnet off, now (best effort: the rig's lease covers a link that is gone).
    pub fn send_safe(&self) -> bool {
        self.send(&HostMsg::Safe, Duration::from_millis(500))
    }

    fn heartbeat(&self) -> bool {
        self.send(
            &HostMsg::Heartbeat,
            Duration::from_millis(limits::HEARTBEAT_MS as u64),
        )
    }
}

/// The sessions holding a rig in this process, for the exits that skip destructors.
fn held() -> &'static Mutex<Vec<(u64, SafeHandle)>> {
    static HELD: OnceLock<Mutex<Vec<(u64, SafeHandle)>>> = OnceLock::new();
    HELD.get_or_init(|| Mutex::new(Vec::new()))
}

/// Sends `Safe` on every link a session holds: for exits that do not unwind (`process::exit`).
pub fn make_all_safe() {
    let handles: Vec<SafeHandle> = match held().lock() {
        Ok(h) => h.iter().map(|(_, s)| s.clone()).collect(),
        Err(p) => p.into_inner().iter().map(|(_, s)| s.clone()).collect(),
    };
    for h in handles {
        h.send_safe();
    }
}

/// A session's hold on the rig (see the module docs): heartbeats while it lives, `Safe` when it
/// goes.
pub struct Hold {
    id: u64,
    handle: SafeHandle,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    beats: Arc<AtomicU64>,
}

impl Hold {
    pub(crate) fn new(handle: SafeHandle) -> Hold {
        let period = Duration::from_millis(limits::HEARTBEAT_MS as u64);
        static NEXT: AtomicU64 = AtomicU64::new(1);
        let id = NEXT.fetch_add(1, Ordering::Relaxed);
        let stop = Arc::new(AtomicBool::new(false));
        let beats = Arc::new(AtomicU64::new(0));
        let (h, st, b) = (handle.clone(), stop.clone(), beats.clone());
        let thread = std::thread::Builder::new()
            .name("tribo-heartbeat".into())
            .spawn(move || {
                let mut next = Instant::now();
                while !st.load(Ordering::Relaxed) {
                    if Instant::now() >= next {
                        // A failed write (cable out) is the lease's business; keep trying.
                        if h.heartbeat() {
                            b.fetch_add(1, Ordering::Relaxed);
                        }
                        next += period;
                    }
                    std::thread::sleep(Duration::from_millis(10).min(period));
                }
            })
            .ok();
        if let Ok(mut v) = held().lock() {
            v.push((id, handle.clone()));
        }
        Hold {
            id,
            handle,
            stop,
            thread,
            beats,
        }
    }

    /// Heartbeats sent so far.
    pub fn heartbeats(&self) -> u64 {
        self.beats.load(Ordering::Relaxed)
    }
}

impl Drop for Hold {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        if let Ok(mut v) = held().lock() {
            v.retain(|(id, _)| *id != self.id);
        }
        self.handle.send_safe();
    }
}
