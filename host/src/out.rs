//! Standard output of the commands, written so that a closed pipe ends `tribo` quietly.
//!
//! `println!` panics when stdout is a pipe whose reader has gone (`tribo runs | head -1`): Rust
//! ignores `SIGPIPE`, so the write fails with `EPIPE` and the macro panics. The commands write
//! through [`outln!`](crate::outln) / [`out!`](macro@crate::out) instead, which return the
//! [`std::io::Error`]; `main` recognises a broken pipe anywhere in an error's chain
//! ([`is_broken_pipe`]) and exits with status 0 without a word, as `grep`, `ripgrep` and the
//! coreutils do when their reader has what it wanted. As a last resort for output written with
//! `println!` elsewhere, [`install_pipe_hook`] turns that panic into the same quiet exit. Either
//! way a rig the command holds is left safe (`link::hold`: the hold's drop, or `make_all_safe`
//! before the hook's exit).

/// `writeln!` to standard output, returning `std::io::Result<()>`.
#[macro_export]
macro_rules! outln {
    () => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock())
    }};
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)
    }};
}

/// `eprintln!` that never panics: a closed standard error (`tribo run … 2>&1 | head -2`) loses the
/// message, never the run (`eprintln!` panics on `EPIPE`, which left a released run to the rig).
/// Every message of `tribo` to standard error goes through it.
#[macro_export]
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr().lock(), $($arg)*);
    }};
}

/// `write!` to standard output (then flushed), returning `std::io::Result<()>`.
#[macro_export]
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let mut o = std::io::stdout().lock();
        write!(o, $($arg)*).and_then(|_| o.flush())
    }};
}

/// True if `e` (or any of its causes) is a write to a closed pipe.
pub fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Makes the panic of `println!`/`print!` on a closed standard output (`failed printing to stdout:
/// Broken pipe`) a quiet exit with status 0; any other panic is reported as before.
#[cfg(feature = "cli")]
pub fn install_pipe_hook() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let msg = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        let epipe = format!("{}", std::io::Error::from(std::io::ErrorKind::BrokenPipe));
        if msg.starts_with("failed printing to stdout")
            && (msg.contains("os error 32") || msg.contains(&epipe))
        {
            // Exiting here skips the destructors: a rig this process holds is made safe first.
            crate::link::hold::make_all_safe();
            std::process::exit(0);
        }
        default(info)
    }));
}

static JSON_PRINTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Prints a command's one JSON object (a line), and remembers that it did.
pub fn print_json(v: impl std::fmt::Display) -> std::io::Result<()> {
    JSON_PRINTED.store(true, std::sync::atomic::Ordering::Relaxed);
    crate::outln!("{v}")
}

/// Whether [`print_json`] printed the command's object.
pub fn json_printed() -> bool {
    JSON_PRINTED.load(std::sync::atomic::Ordering::Relaxed)
}

/// Writes to standard output. A closed pipe (`tribo run … | head`) is an error that stops the
/// command, unwinding through its hold on the rig (which sends `Safe`); `main` ends quietly on it
/// (`crate::out`).
pub fn text(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    o.write_all(text.as_bytes())
        .and_then(|_| o.flush())
        .map_err(|e| anyhow::Error::new(e).context("cannot write to standard output"))
}
