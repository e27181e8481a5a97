//! A Unix extra: the virtual rig behind a pseudo-terminal, which a host opens exactly as it opens
//! a rig's USB port, so `tribo run --port /dev/pts/N` goes through the serial code path without
//! hardware. (The virtual rig's usual home is a TCP address; see `tribo rig --virtual`.)
//!
//! The rig keeps the terminal's other side open itself, so a host that closes the port (a pulled
//! cable) does not end it. While no host reads, what the rig sends fills the terminal's buffer and
//! the rest is lost, as on a USB line with nobody listening; the next host's open discards what
//! waited, and `Pull` fetches the run again.

use serialport::{SerialPort, TTYPort};
use std::io::{self, Write};
use std::thread::JoinHandle;
use std::time::Duration;
use tribo_rig::{serve, ServeOptions, VirtualRig};

/// A write to the terminal gives up after this long when nobody reads (the bytes are lost).
const WRITE_TIMEOUT: Duration = Duration::from_millis(5);

/// The rig's side of the terminal: writes that find the buffer full drop their bytes instead of
/// stalling the rig.
struct Line(TTYPort);

impl Write for Line {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self.0.write(buf) {
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                ) =>
            {
                Ok(buf.len())
            }
            r => r,
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Serves `rig` on a new pseudo-terminal, on a thread of its own, until the process ends. Returns
/// the terminal's name (the port to give to `--port`).
pub fn spawn(
    mut rig: VirtualRig,
    opts: ServeOptions,
) -> io::Result<(String, JoinHandle<io::Result<()>>)> {
    let (mut master, slave) = TTYPort::pair().map_err(io::Error::from)?;
    let name = slave
        .name()
        .ok_or_else(|| io::Error::other("the pseudo-terminal has no name"))?;
    let reader = master.try_clone_native().map_err(io::Error::from)?;
    master.set_timeout(WRITE_TIMEOUT).map_err(io::Error::from)?;
    let thread = std::thread::Builder::new()
        .name("tribo-virtual-rig".into())
        .spawn(move || {
            let _keep_open = slave;
            serve(&mut rig, reader, Line(master), &opts)
        })?;
    Ok((name, thread))
}
