//! The signals that stop `tribo` cleanly: Ctrl-C (SIGINT), SIGTERM and SIGHUP. A handler hears
//! which one came; the process's exit status then says it (128 + the signal's number, the shell's
//! convention: 130, 143, 129; [`crate::exit`]). On Windows, Ctrl-C, Ctrl-Break and closing the
//! console all count as Ctrl-C.

use std::io;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering};

/// A signal that stops a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// SIGHUP: the terminal went away.
    Hangup = 1,
    /// SIGINT: Ctrl-C.
    Interrupt = 2,
    /// SIGTERM: asked to stop (`kill`, a service manager, a batch system's time limit).
    Terminate = 15,
}

impl Signal {
    /// The exit status of a process this signal stopped: 128 + its number.
    pub const fn status(self) -> u8 {
        128 + self as u8
    }

    /// Its usual name.
    pub const fn name(self) -> &'static str {
        match self {
            Signal::Hangup => "SIGHUP",
            Signal::Interrupt => "SIGINT",
            Signal::Terminate => "SIGTERM",
        }
    }

    fn from_number(n: u8) -> Option<Signal> {
        match n {
            1 => Some(Signal::Hangup),
            2 => Some(Signal::Interrupt),
            15 => Some(Signal::Terminate),
            _ => None,
        }
    }
}

/// The last signal received (its number), 0 before any.
static RECEIVED: AtomicU8 = AtomicU8::new(0);
static INSTALLED: AtomicBool = AtomicBool::new(false);

/// The last stopping signal this process received, if any.
pub fn received() -> Option<Signal> {
    Signal::from_number(RECEIVED.load(Ordering::SeqCst))
}

/// Calls `handler`, on a thread of its own, with each Ctrl-C, SIGTERM or SIGHUP this process
/// receives (after noting it for [`received`]). Once per process: a second call is an error.
pub fn set_handler(mut handler: impl FnMut(Signal) + Send + 'static) -> io::Result<()> {
    if INSTALLED.swap(true, Ordering::SeqCst) {
        return Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            "a signal handler is already installed",
        ));
    }
    let mut note = move |s: Signal| {
        RECEIVED.store(s as u8, Ordering::SeqCst);
        handler(s)
    };
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP])?;
        std::thread::Builder::new()
            .name("tribo-signals".into())
            .spawn(move || {
                for s in signals.forever() {
                    note(match s {
                        SIGHUP => Signal::Hangup,
                        SIGTERM => Signal::Terminate,
                        _ => Signal::Interrupt,
                    });
                }
            })?;
        Ok(())
    }
    #[cfg(not(unix))]
    {
        ctrlc::set_handler(move || note(Signal::Interrupt)).map_err(io::Error::other)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_status_is_128_plus_the_signals_number() {
        assert_eq!(Signal::Interrupt.status(), 130);
        assert_eq!(Signal::Terminate.status(), 143);
        assert_eq!(Signal::Hangup.status(), 129);
        for s in [Signal::Hangup, Signal::Interrupt, Signal::Terminate] {
            assert_eq!(Signal::from_number(s as u8), Some(s));
        }
    }
}
