//! The errors that decide `tribo`'s exit status (the statuses themselves, one contract for every
//! command, are decided in one place: `cmd::exit`):
//!
//! A library function that finished with incomplete data returns [`Incomplete`] as its error (after
//! printing or storing everything it has), one interrupted [`Interrupted`], one given a value out
//! of range [`Usage`]; `cmd::exit::status_of` maps them (and the loader's and the store's typed
//! errors) to a status. Any other error is status 1.

use std::fmt;

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
/// names the signal received (`signals::received`; Ctrl-C's when none was).
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
