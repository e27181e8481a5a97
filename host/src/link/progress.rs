//! What a run's session reports as it goes (for a progress display).

use std::path::Path;
use std::time::Duration;
use tribo_wire::{Gap, RunEnd, RunHeader, SampleBlock, SampleClock};

/// What happens during a run, for a progress display.
#[derive(Debug)]
pub enum Progress<'a> {
    /// The plate is heating toward its setpoint.
    Heating {
        /// The plate's temperature now (°C).
        temp_c: f32,
        /// The setpoint (°C).
        setpoint_c: f32,
        /// Time since heating began (s).
        elapsed_s: f64,
    },
    /// Armed: waiting for the operator to press the rig's button.
    WaitingForButton,
    /// The run started: its header arrived and its folder was made.
    Started {
        /// The run's header (rig constants, rate, run id).
        header: &'a RunHeader,
        /// The run's folder in the store.
        dir: &'a Path,
    },
    /// A block arrived; `envelope_m` is the Mark & Crandall amplitude at its last sample.
    Block {
        /// The block.
        block: &'a SampleBlock,
        /// Mark & Crandall amplitude at the block's last sample (m).
        envelope_m: f64,
        /// Samples received so far.
        samples: u64,
        /// Samples the run will hold at most.
        expected: u64,
    },
    /// Blocks missing from the live stream (they are pulled at the end).
    Gap {
        /// First missing block.
        from: u32,
        /// Block after the last missing one.
        to: u32,
    },
    /// Pulling the run from the rig.
    Pulling {
        /// From this block on.
        from_block: u32,
    },
    /// A pull round: `blocks` missing blocks asked for (from `first`), and the run's end from
    /// `tail_from` on.
    PullRound {
        /// The round's number (from 1).
        round: u32,
        /// The first missing block asked for, if any.
        first: Option<u32>,
        /// Missing blocks asked for.
        blocks: u32,
        /// Blocks missing when the round began.
        missing: usize,
        /// The run's end asked for from this block on.
        tail_from: u32,
    },
    /// A pull round brought nothing (or was not answered): waiting before the next one.
    Backoff {
        /// How long before the next round.
        wait: Duration,
        /// Why the round brought nothing.
        why: String,
    },
    /// The rig lost these samples (an acquisition gap); the run goes on.
    Lost(&'a Gap),
    /// The rig's sample clock is not exactly the rate asked for (the timer cannot make it).
    RateUsed {
        /// The rate asked for (Hz).
        asked_hz: u32,
        /// The rate the rig's timer makes.
        clock: SampleClock,
    },
    /// Something the operator should know; the run goes on.
    Warning(String),
    /// The run ended (its end frame: why and how many samples).
    Ended(&'a RunEnd),
}
