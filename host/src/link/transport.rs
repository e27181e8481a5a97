//! Where a rig is reached, as given to `--port`: a serial port (a rig on USB) or a TCP address (a
//! virtual rig started with `tribo rig --virtual`), and the byte stream each one opens.

use super::{serial, LinkError, LinkErrorKind};
use std::fmt;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::str::FromStr;
use std::time::Duration;

/// Where `tribo rig --virtual` listens unless told otherwise, and where the rig commands look for
/// a virtual rig when no rig is attached.
pub const DEFAULT_VIRTUAL_RIG: &str = "127.0.0.1:7411";

/// Wait for a TCP connection to be accepted.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(2);
/// Read timeout of the link's reading thread (it checks whether the link was dropped in between).
const READ_TIMEOUT: Duration = Duration::from_millis(50);
/// A rig that takes no bytes for this long is treated as gone.
const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// The forms `--port` takes (one line each for `--help`).
pub const PORT_FORMS: &str = "a serial port as the system names it (Windows: COM3; macOS: \
                              /dev/cu.usbmodem…; Linux: /dev/ttyACM0; see `tribo devices`), or \
                              tcp://HOST:PORT for a virtual rig (`tribo rig --virtual` prints it)";

/// Where a rig is reached.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Address {
    /// A serial port by its system name: `COM3`, `/dev/ttyACM0`, `/dev/cu.usbmodem1101`.
    Serial(String),
    /// A TCP address `HOST:PORT` (written `tcp://HOST:PORT`), e.g. a virtual rig.
    Tcp(String),
}

impl Address {
    /// Parses what `--port` (or `$TRIBO_PORT`) says: `tcp://HOST:PORT` is a TCP address, anything
    /// else a serial port name. The error says which forms are understood.
    pub fn parse(s: &str) -> Result<Address, String> {
        let t = s.trim();
        if t.is_empty() {
            return Err(format!("no port given: give {PORT_FORMS}"));
        }
        let scheme = t.find("://").map(|i| &t[..i]);
        match scheme {
            Some(sc) if sc.eq_ignore_ascii_case("tcp") => {
                let rest = t[6..].trim_end_matches('/');
                let Some((host, port)) = rest.rsplit_once(':') else {
                    return Err(format!(
                        "`{t}`: a TCP address needs a port number: tcp://HOST:PORT, e.g. tcp://{DEFAULT_VIRTUAL_RIG}"
                    ));
                };
                if host.is_empty() {
                    return Err(format!(
                        "`{t}`: no host before the port: tcp://HOST:PORT, e.g. tcp://{DEFAULT_VIRTUAL_RIG}"
                    ));
                }
                if host.contains(':') && !(host.starts_with('[') && host.ends_with(']')) {
                    return Err(format!(
                        "`{t}`: write an IPv6 host in brackets, e.g. tcp://[::1]:7411"
                    ));
                }
                match port.parse::<u16>() {
                    Ok(p) if p > 0 => Ok(Address::Tcp(format!("{host}:{p}"))),
                    _ => Err(format!(
                        "`{t}`: `{port}` is not a port number (1–65535): tcp://HOST:PORT"
                    )),
                }
            }
            Some(sc) => Err(format!(
                "`{t}`: unknown scheme `{sc}://`; give {PORT_FORMS}"
            )),
            None if t.parse::<SocketAddr>().is_ok() => Err(format!(
                "`{t}` looks like a network address: write it tcp://{t} (a serial port is named \
                 like COM3 or /dev/ttyACM0)"
            )),
            None => Ok(Address::Serial(t.to_string())),
        }
    }

    /// Whether this is a TCP address (a virtual rig).
    pub fn is_tcp(&self) -> bool {
        matches!(self, Address::Tcp(_))
    }
}

impl FromStr for Address {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Address::parse(s)
    }
}

impl fmt::Display for Address {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Address::Serial(name) => f.write_str(name),
            Address::Tcp(addr) => write!(f, "tcp://{addr}"),
        }
    }
}

impl From<SocketAddr> for Address {
    fn from(a: SocketAddr) -> Self {
        Address::Tcp(a.to_string())
    }
}

/// The two halves of an open byte stream to a rig. Reads time out now and then (`TimedOut` or
/// `WouldBlock`), so that a reading thread can notice it is no longer wanted.
pub type Halves = (Box<dyn Read + Send>, Box<dyn Write + Send>);

/// Opens the byte stream to `addr`. The error says what to do.
pub fn open(addr: &Address) -> Result<Halves, LinkError> {
    match addr {
        Address::Serial(name) => {
            let (r, w) = serial::open(name)?;
            Ok((Box::new(r), Box::new(w)))
        }
        Address::Tcp(a) => {
            let s = connect(a)?;
            let err = |e: io::Error| {
                LinkError::new(
                    LinkErrorKind::Open,
                    format!("tcp://{a}: cannot set up the connection: {e}"),
                )
            };
            s.set_nodelay(true).map_err(err)?;
            s.set_write_timeout(Some(WRITE_TIMEOUT)).map_err(err)?;
            let r = s.try_clone().map_err(err)?;
            r.set_read_timeout(Some(READ_TIMEOUT)).map_err(err)?;
            Ok((Box::new(r), Box::new(s)))
        }
    }
}

fn connect(a: &str) -> Result<TcpStream, LinkError> {
    let err = |msg: String| LinkError::new(LinkErrorKind::Open, msg);
    let addrs: Vec<SocketAddr> = a
        .to_socket_addrs()
        .map_err(|e| {
            err(format!(
                "tcp://{a}: cannot resolve the host ({e}); check the address"
            ))
        })?
        .collect();
    let mut last = None;
    for sa in &addrs {
        match TcpStream::connect_timeout(sa, CONNECT_TIMEOUT) {
            Ok(s) => return Ok(s),
            Err(e) => last = Some(e),
        }
    }
    let e = last.unwrap_or_else(|| io::Error::new(io::ErrorKind::NotFound, "no address"));
    Err(err(match e.kind() {
        io::ErrorKind::ConnectionRefused => format!(
            "tcp://{a}: nothing listens there; start a virtual rig with `tribo rig --virtual` (it prints \
             the address to give to --port), or give the rig's serial port (`tribo devices`)"
        ),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock => format!(
            "tcp://{a}: no answer within {} s; check the address (and that the rig's computer is \
             reachable)",
            CONNECT_TIMEOUT.as_secs()
        ),
        _ => format!("tcp://{a}: cannot connect: {e}"),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn port_forms() {
        let ok = |s: &str| Address::parse(s).unwrap();
        assert_eq!(ok("COM3"), Address::Serial("COM3".into()));
        assert_eq!(ok(" /dev/ttyACM0 "), Address::Serial("/dev/ttyACM0".into()));
        assert_eq!(
            ok("/dev/cu.usbmodem1101"),
            Address::Serial("/dev/cu.usbmodem1101".into())
        );
        assert_eq!(ok(r"\\.\COM12"), Address::Serial(r"\\.\COM12".into()));
        assert_eq!(
            ok("tcp://127.0.0.1:7411"),
            Address::Tcp("127.0.0.1:7411".into())
        );
        assert_eq!(
            ok("TCP://localhost:80/"),
            Address::Tcp("localhost:80".into())
        );
        assert_eq!(ok("tcp://[::1]:7411"), Address::Tcp("[::1]:7411".into()));
        // What is printed is what parses back.
        for s in [
            "COM3",
            "/dev/ttyACM0",
            "tcp://127.0.0.1:7411",
            "tcp://[::1]:9",
        ] {
            assert_eq!(ok(s).to_string(), s);
            assert_eq!(ok(&ok(s).to_string()), ok(s));
        }
        for (bad, says) in [
            ("", "tcp://HOST:PORT"),
            ("  ", "COM3"),
            ("tcp://127.0.0.1", "needs a port"),
            ("tcp://:7411", "no host"),
            ("tcp://localhost:0", "not a port number"),
            ("tcp://localhost:70000", "not a port number"),
            ("tcp://localhost:x", "not a port number"),
            ("tcp://::1:7411", "brackets"),
            ("udp://127.0.0.1:7411", "unknown scheme"),
            ("127.0.0.1:7411", "tcp://127.0.0.1:7411"),
        ] {
            let e = Address::parse(bad).unwrap_err();
            assert!(e.contains(says), "{bad:?}: {e}");
        }
    }

    #[test]
    fn a_tcp_address_where_nothing_listens_says_how_to_start_a_virtual_rig() {
        // A port that was free a moment ago.
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = Address::from(l.local_addr().unwrap());
        drop(l);
        let e = open(&addr).err().expect("nothing listens");
        assert_eq!(e.kind, LinkErrorKind::Open);
        assert!(e.msg.contains("tribo rig --virtual"), "{e}");
    }
}
