//! Serial ports: a tty (USB CDC ACM, or a pseudo-terminal) opened in raw mode, exclusively.

use super::{LinkError, LinkErrorKind};
use nix::fcntl::{Flock, FlockArg, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{self, BaudRate, FlushArg, SetArg, SpecialCharacterIndices};
use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::sync::Arc;

/// Puts a terminal in raw mode: no echo, no line editing, no CR/LF translation, 8 bits.
pub fn make_raw(fd: impl AsFd) -> nix::Result<()> {
    let mut t = termios::tcgetattr(&fd)?;
    termios::cfmakeraw(&mut t);
    // Ignored by USB CDC and ptys; a sane value for a real UART.
    let _ = termios::cfsetspeed(&mut t, BaudRate::B115200);
    t.control_chars[SpecialCharacterIndices::VMIN as usize] = 1;
    t.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
    termios::tcsetattr(&fd, SetArg::TCSANOW, &t)
}

/// The reading half: waits at most 100 ms per read (then `TimedOut`), reports a hang-up as end of
/// stream.
pub struct SerialReader {
    file: Arc<Flock<File>>,
}

impl Read for SerialReader {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let f: &File = &self.file;
        let mut fds = [PollFd::new(f.as_fd(), PollFlags::POLLIN)];
        let n = poll(&mut fds, PollTimeout::from(100u16)).map_err(io::Error::from)?;
        if n == 0 {
            return Err(io::ErrorKind::TimedOut.into());
        }
        let ev = fds[0].revents().unwrap_or(PollFlags::empty());
        if ev.contains(PollFlags::POLLIN) {
            let mut f: &File = f;
            return f.read(buf);
        }
        if ev.intersects(PollFlags::POLLHUP | PollFlags::POLLERR | PollFlags::POLLNVAL) {
            return Ok(0);
        }
        Err(io::ErrorKind::TimedOut.into())
    }
}

/// The writing half.
pub struct SerialWriter {
    file: Arc<Flock<File>>,
}

impl Write for SerialWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut f: &File = &self.file;
        f.write(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// Opens `path` as a serial port: exclusive lock, raw mode, stale input discarded.
pub fn open(path: &Path) -> Result<(SerialReader, SerialWriter), LinkError> {
    let err = |msg: String| LinkError::new(LinkErrorKind::Open, msg);
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .custom_flags(OFlag::O_NOCTTY.bits())
        .open(path)
        .map_err(|e| {
            err(match e.kind() {
                io::ErrorKind::NotFound => format!(
                    "{}: no such port; list attached rigs with `tribo devices` (or start a virtual one with `tribo \
                     rig --virtual`)",
                    path.display()
                ),
                io::ErrorKind::PermissionDenied => format!(
                    "{}: permission denied; add yourself to the port's group (`sudo usermod -aG dialout $USER`, then \
                     log in again)",
                    path.display()
                ),
                _ => format!("{}: cannot open: {e}", path.display()),
            })
        })?;
    let file = Flock::lock(file, FlockArg::LockExclusiveNonblock).map_err(|(_, e)| {
        err(format!(
            "{}: the port is in use by another program ({e}); close the other `tribo` (or terminal program) first",
            path.display()
        ))
    })?;
    make_raw(&*file).map_err(|e| {
        err(format!("{}: not a serial port ({e}); give the rig's port, e.g. /dev/ttyACM0 (see `tribo devices`)", path.display()))
    })?;
    let _ = termios::tcflush(&*file, FlushArg::TCIOFLUSH);
    let file = Arc::new(file);
    Ok((SerialReader { file: file.clone() }, SerialWriter { file }))
}
