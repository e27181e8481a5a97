//! Serial ports, through the `serialport` crate on Linux, macOS and Windows: the rig's USB CDC-ACM
//! port opened the way it needs, raw (8 data bits, no parity, one stop bit, no flow control, no
//! echo, no line editing, no CR/LF translation), exclusively (the crate's default on Unix; Windows
//! opens a port for one program only), with DTR asserted (the rig's USB
//! stack then knows a host opened the port), stale input discarded, and reads that time out.

use super::{LinkError, LinkErrorKind};
use serialport::{ClearBuffer, DataBits, FlowControl, Parity, SerialPort, StopBits};
use std::io;
use std::time::Duration;

/// Longest a read waits. Short: on Windows a write waits for a read in progress on the same port.
pub const READ_TIMEOUT: Duration = Duration::from_millis(50);

/// Ignored by USB CDC-ACM (the bytes go at USB speed), a sane value for a real UART.
const BAUD: u32 = 115_200;

/// The reading and the writing half of an open port (two handles on it).
pub type Halves = (Box<dyn SerialPort>, Box<dyn SerialPort>);

/// Opens the serial port `name` (`COM3`, `/dev/ttyACM0`, `/dev/cu.usbmodem…`): the reading half
/// and the writing half. Reads return `TimedOut` after [`READ_TIMEOUT`] without data, and an error
/// once the port is gone (cable pulled).
pub fn open(name: &str) -> Result<Halves, LinkError> {
    let port = serialport::new(name, BAUD)
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        .dtr_on_open(true)
        .timeout(READ_TIMEOUT)
        .open()
        .map_err(|e| LinkError::new(LinkErrorKind::Open, open_error(name, &e)))?;
    // Bytes an earlier session left in the buffers are not this session's.
    let _ = port.clear(ClearBuffer::All);
    let reader = port.try_clone().map_err(|e| {
        LinkError::new(
            LinkErrorKind::Open,
            format!("{name}: cannot share the port between reading and writing: {e}"),
        )
    })?;
    Ok((reader, port))
}

/// What went wrong opening `name`, and what to do.
fn open_error(name: &str, e: &serialport::Error) -> String {
    use serialport::ErrorKind as K;
    match e.kind() {
        K::Io(io::ErrorKind::NotFound) => format!(
            "{name}: no such port; list attached rigs with `tribo devices` (or start a virtual rig \
             with `tribo rig --virtual` and give its tcp:// address)"
        ),
        K::Io(io::ErrorKind::PermissionDenied) => {
            format!("{name}: permission denied; {}", PERMISSION_HINT)
        }
        // Windows says the same for a port that does not exist and one another program holds.
        K::NoDevice if cfg!(windows) => format!(
            "{name}: no such port, or another program has it open ({e}); `tribo devices` lists \
             attached rigs; close any other program using the port (another `tribo`, a terminal)"
        ),
        K::NoDevice => format!(
            "{name}: the port is in use by another program ({e}); close the other `tribo` (or \
             terminal program) first"
        ),
        K::InvalidInput => format!(
            "{name}: not a port name the system understands ({e}); give the rig's port as \
             `tribo devices` lists it"
        ),
        _ => format!(
            "{name}: cannot open it as a serial port ({e}); is it the rig's port? `tribo devices` \
             lists attached rigs"
        ),
    }
}

#[cfg(target_os = "linux")]
const PERMISSION_HINT: &str =
    "add yourself to the port's group (`sudo usermod -aG dialout $USER`, then \
                               log in again), or install the udev rule from the README";
#[cfg(target_os = "macos")]
const PERMISSION_HINT: &str = "check the port's owner and mode (`ls -l`), and use the /dev/cu.* \
                               name of the port";
#[cfg(not(any(target_os = "linux", target_os = "macos")))]
const PERMISSION_HINT: &str = "close any other program using the port, or ask your administrator \
                               for access to it";
