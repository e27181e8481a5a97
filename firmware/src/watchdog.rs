//! When to feed the hardware watchdog: only while every task has shown it is alive.
//!
//! Each periodic task checks in ([`Liveness::check_in`]) every time round its loop; each has its
//! longest allowed silence. The board's watchdog task asks [`Liveness::verdict`] every
//! [`FEED_PERIOD_MS`]: all alive, it feeds the IWDG; one silent, it drives the outputs safe at once,
//! writes which task (the reset record), and stops feeding, so the IWDG resets the chip within
//! [`limits::WATCHDOG_TIMEOUT_MS`]. A core stuck in one task (the watchdog task never runs) is reset
//! by the IWDG the same way. Tasks that only wait for the host (USB) do not check in: their silence
//! is normal.
//!
//! Check-ins are atomic stores, so tasks on any executor or interrupt priority may call them; the
//! times are milliseconds of uptime, wrapping (silences up to 24 days are told apart).

use core::fmt::Write;
use core::sync::atomic::{AtomicU32, Ordering};

use crate::wire::{limits, BOOT_MESSAGE_LEN};

/// How often the watchdog task looks, ms.
pub const FEED_PERIOD_MS: u32 = 50;

/// A task that must check in, and its longest allowed silence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TaskSpec {
    pub name: &'static str,
    pub max_silence_ms: u32,
}

/// The board's periodic tasks: the application (polled every 1 ms; it also reads the sampler's DMA
/// ring, so a stuck reader is a stuck application) and the thermocouple converter (every 100 ms).
pub const BOARD_TASKS: [TaskSpec; 2] = [
    TaskSpec {
        name: "app",
        max_silence_ms: 50,
    },
    TaskSpec {
        name: "thermocouple",
        max_silence_ms: 300,
    },
];

/// Index of each board task in [`BOARD_TASKS`].
pub mod task {
    pub const APP: usize = 0;
    pub const THERMOCOUPLE: usize = 1;
}

// The worst case from a task stopping to the outputs going safe is its silence plus one feed period,
// and to the reset one watchdog timeout more: both must stay well under a second.
const _: () = {
    let mut i = 0;
    while i < BOARD_TASKS.len() {
        assert!(
            BOARD_TASKS[i].max_silence_ms + FEED_PERIOD_MS + limits::WATCHDOG_TIMEOUT_MS <= 1000
        );
        i += 1;
    }
    assert!(FEED_PERIOD_MS < limits::WATCHDOG_TIMEOUT_MS / 2);
};

/// A task that stopped checking in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stuck {
    pub task: usize,
    pub name: &'static str,
    pub silent_ms: u32,
}

impl Stuck {
    /// The line kept in the reset record: "watchdog: task thermocouple silent for 312 ms".
    pub fn message(&self) -> heapless::String<BOOT_MESSAGE_LEN> {
        let mut s = heapless::String::new();
        // Cannot overflow: the longest name and number fit in far fewer than 120 bytes.
        let _ = write!(
            s,
            "watchdog: task {} silent for {} ms",
            self.name, self.silent_ms
        );
        s
    }
}

/// The tasks' latest check-ins.
#[derive(Debug)]
pub struct Liveness<const N: usize> {
    specs: [TaskSpec; N],
    last_ms: [AtomicU32; N],
}

impl<const N: usize> Liveness<N> {
    /// Every task counts as checked in at `now_ms`.
    pub fn new(specs: [TaskSpec; N], now_ms: u32) -> Self {
        Liveness {
            specs,
            last_ms: core::array::from_fn(|_| AtomicU32::new(now_ms)),
        }
    }

    pub fn specs(&self) -> &[TaskSpec; N] {
        &self.specs
    }

    /// Task `task` is alive at `now_ms` (an unknown index is ignored).
    pub fn check_in(&self, task: usize, now_ms: u32) {
        if let Some(t) = self.last_ms.get(task) {
            t.store(now_ms, Ordering::Relaxed);
        }
    }

    /// `Ok` when every task checked in within its allowed silence; else the silent one (the
    /// longest overdue first).
    pub fn verdict(&self, now_ms: u32) -> Result<(), Stuck> {
        let mut worst: Option<Stuck> = None;
        for (i, (spec, last)) in self.specs.iter().zip(&self.last_ms).enumerate() {
            let silent = now_ms.wrapping_sub(last.load(Ordering::Relaxed));
            // A check-in "from the future" (another task's clock read a moment later) is fresh.
            if silent > u32::MAX / 2 {
                continue;
            }
            if silent > spec.max_silence_ms {
                let over = silent - spec.max_silence_ms;
                if worst.is_none_or(|w| over > w.silent_ms - self.specs[w.task].max_silence_ms) {
                    worst = Some(Stuck {
                        task: i,
                        name: spec.name,
                        silent_ms: silent,
                    });
                }
            }
        }
        worst.map_or(Ok(()), Err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fed_only_while_every_task_checks_in() {
        let l = Liveness::new(BOARD_TASKS, 0);
        // Every task on its own period: app 1 ms, thermocouple 100 ms (+ SPI).
        for t in 1..=2_000u32 {
            l.check_in(task::APP, t);
            if t % 100 == 3 {
                l.check_in(task::THERMOCOUPLE, t);
            }
            if t % FEED_PERIOD_MS == 0 {
                assert_eq!(l.verdict(t), Ok(()), "at {t} ms");
            }
        }
        // The thermocouple task hangs (its SPI never completes) at 2000 ms.
        let mut first = None;
        for t in 2_001..=3_000u32 {
            l.check_in(task::APP, t);
            if t % FEED_PERIOD_MS == 0 && first.is_none() {
                if let Err(s) = l.verdict(t) {
                    first = Some((t, s));
                }
            }
        }
        let (t, s) = first.expect("the silent task is found");
        assert_eq!((s.task, s.name), (task::THERMOCOUPLE, "thermocouple"));
        // Last check-in at 1903 ms; overdue past 2203 ms; seen at the next look.
        assert_eq!(t, 2_250);
        assert_eq!(s.silent_ms, 347);
        assert_eq!(
            s.message().as_str(),
            "watchdog: task thermocouple silent for 347 ms"
        );
    }

    #[test]
    fn wrapping_clocks_and_unknown_tasks() {
        let l = Liveness::new(BOARD_TASKS, u32::MAX - 10);
        l.check_in(task::APP, 5);
        l.check_in(task::THERMOCOUPLE, 5);
        l.check_in(7, 5);
        assert_eq!(l.verdict(40), Ok(()));
        // A check-in stamped just after the verdict's clock read.
        l.check_in(task::APP, 41);
        assert_eq!(l.verdict(40), Ok(()));
        assert_eq!(l.verdict(92).unwrap_err().name, "app");
    }
}
