//! What a run's session reports as it goes (for a progress display).

use std::path::Path;
use std::time::Duration;
use tribo_wire::{Gap, RunEnd, RunHeader, SampleBlock, SampleClock};

/// What happens during a run, for a progress display.
#[derive(Debug)]
pub enum Progress<'a> {
    Heating {
        temp_c: f32,
        setpoint_c: f32,
        elapsed_s: f64,
    },
    WaitingForButton,
    Started {
        header: &'a RunHeader,
        dir: &'a Path,
    },
    /// A block arrived; `envelope_m` is the Mark & Crandall amplitude at its last sample.
    Block {
        block: &'a SampleBlock,
        envelope_m: f64,
        samples: u64,
        expected: u64,
    },
    Gap {
        from: u32,
        to: u32,
    },
    Pulling {
        from_block: u32,
    },
    /// A pull round: `blocks` missing blocks asked for (from `first`), and the run's end from
    /// `tail_from` on.
    PullRound {
        round: u32,
        first: Option<u32>,
        blocks: u32,
        missing: usize,
        tail_from: u32,
    },
    /// A pull round brought nothing (or was not answered): waiting before the next one.
    Backoff {
        wait: Duration,
        why: String,
    },
    /// The rig lost these samples (an acquisition gap); the run goes on.
    Lost(&'a Gap),
    /// The rig's sample clock is not exactly the rate asked for (the timer cannot make it).
    RateUsed {
        asked_hz: u32,
        clock: SampleClock,
    },
    Warning(String),
    Ended(&'a RunEnd),
}
