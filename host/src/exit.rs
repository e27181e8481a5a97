//! The exit statuses of `tribo`, one contract for every command (documented in the README):
//!
//! | status | meaning |
//! |---|---|
//! | 0 | done, and the data is whole |
//! | 1 | error: nothing usable was produced (the message says what to do next) |
//! | 2 | usage: the command line was wrong (clap's own status, or a value the rig would refuse) |
//! | 3 | finished, but the data is incomplete or not analysable: the output says exactly what is missing |
//! | 130, 143, 129 | interrupted by Ctrl-C (SIGINT), SIGTERM or SIGHUP (128 + the signal's number): stopped cleanly, the rig made safe, what was received kept |
//!
//! A library function that finished with incomplete data returns [`Incomplete`] as its error (after
//! printing or storing everything it has); `main` maps it to status 3. Any other error is status 1.

use crate::signals::Signal;
use std::fmt;

/// The statuses `tribo` exits with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Status {
    Ok,
    Error,
    Usage,
    Incomplete,
    /// Stopped by this signal: 128 + its number (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP).
    Interrupted(Signal),
}

impl Status {
    pub const fn code(self) -> u8 {
        match self {
            Status::Ok => 0,
            Status::Error => 1,
            Status::Usage => 2,
            Status::Incomplete => 3,
            Status::Interrupted(s) => s.status(),
        }
    }
}

/// A command finished but what it produced is incomplete (missing blocks, a gap, a record that cannot
/// be analysed). The message says what is missing; everything usable was already kept.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Incomplete(pub String);

impl fmt::Display for Incomplete {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Incomplete {}

/// The command was interrupted (Ctrl-C, SIGTERM, SIGHUP) and stopped cleanly: the message says
/// what was done before (how many runs were taken, what the interrupted one kept). Its status
/// names the signal received ([`crate::signals::received`]; Ctrl-C's when none was).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Interrupted(pub String);

impl fmt::Display for Interrupted {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Interrupted {}

/// A command line clap accepted but a value of which the rig would refuse (an out-of-range
/// setpoint, load or rate), caught before anything is sent: status 2, as for clap's own errors.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Usage(pub String);

impl fmt::Display for Usage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Usage {}

/// The status an error from a command maps to.
pub fn status_of(e: &anyhow::Error) -> Status {
    if e.chain().any(|c| c.downcast_ref::<Interrupted>().is_some()) {
        Status::Interrupted(crate::signals::received().unwrap_or(Signal::Interrupt))
    } else if e.chain().any(|c| {
        c.downcast_ref::<Incomplete>().is_some()
            || c.downcast_ref::<crate::load::LoadError>()
                .is_some_and(|l| l.is_incomplete())
    }) {
        Status::Incomplete
    } else if e.chain().any(|c| {
        c.downcast_ref::<Usage>().is_some()
            || c.downcast_ref::<tribo_store::StoreError>()
                .is_some_and(|s| s.kind == tribo_store::ErrorKind::Usage)
    }) {
        Status::Usage
    } else {
        Status::Error
    }
}

/// An error and its causes on one line, `: `-joined (for a message stored or wrapped as text).
pub fn chain_text(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        text.push_str(": ");
        text.push_str(&c.to_string());
        cause = c.source();
    }
    text
}
