//! Finding attached rigs on every system: the serial ports the system lists
//! (`serialport::available_ports`), the rig's among them by USB id (1209:0001), and the firmware
//! version each one announces in its hello.

use super::{Address, Link, LinkError};
use serialport::{SerialPortInfo, SerialPortType};
use std::time::Duration;

/// The rig's USB vendor id (pid.codes, the open-source hardware vendor id).
pub const RIG_VID: u16 = 0x1209;
/// The rig's USB product id.
pub const RIG_PID: u16 = 0x0001;

/// A serial port the system lists.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Port {
    /// Its name, as given to `--port`.
    pub name: String,
    /// USB vendor id (USB ports only).
    pub vid: Option<u16>,
    /// USB product id (USB ports only).
    pub pid: Option<u16>,
    /// USB serial number, when the device gives one.
    pub serial: Option<String>,
    /// USB manufacturer string, when the device gives one.
    pub manufacturer: Option<String>,
    /// USB product string, when the device gives one.
    pub product: Option<String>,
}

impl Port {
    /// Whether the port's USB id is the rig's.
    pub fn is_rig(&self) -> bool {
        self.vid == Some(RIG_VID) && self.pid == Some(RIG_PID)
    }

    /// `vvvv:pppp`, or `—` for a port that is not on USB.
    pub fn usb_id(&self) -> String {
        match (self.vid, self.pid) {
            (Some(v), Some(p)) => format!("{v:04x}:{p:04x}"),
            _ => "—".into(),
        }
    }
}

/// Ports in the order a person reads them: COM2 before COM10, ttyACM2 before ttyACM10.
fn natural_key(name: &str) -> (String, u64, String) {
    let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    let (stem, num) = name.split_at(name.len() - digits);
    (stem.to_string(), num.parse().unwrap_or(0), name.to_string())
}

/// The ports of `infos` (what `serialport::available_ports` found), sorted. On macOS every device
/// is listed twice, as `/dev/tty.X` (dial-in, waits for carrier) and `/dev/cu.X` (call-out): only
/// the call-out one is kept, which is the one to open.
pub fn from_infos(infos: Vec<SerialPortInfo>) -> Vec<Port> {
    let names: std::collections::HashSet<String> =
        infos.iter().map(|i| i.port_name.clone()).collect();
    let mut ports: Vec<Port> = infos
        .into_iter()
        .filter(|i| {
            i.port_name
                .strip_prefix("/dev/tty.")
                .is_none_or(|rest| !names.contains(&format!("/dev/cu.{rest}")))
        })
        .map(|i| {
            let mut p = Port {
                name: i.port_name,
                vid: None,
                pid: None,
                serial: None,
                manufacturer: None,
                product: None,
            };
            if let SerialPortType::UsbPort(u) = i.port_type {
                p.vid = Some(u.vid);
                p.pid = Some(u.pid);
                p.serial = u.serial_number;
                p.manufacturer = u.manufacturer;
                p.product = u.product;
            }
            p
        })
        .collect();
    ports.sort_by_key(|p| natural_key(&p.name));
    ports.dedup_by(|a, b| a.name == b.name);
    ports
}

/// Every serial port the system lists, USB ones with their ids.
pub fn list() -> Result<Vec<Port>, String> {
    // Without libudev, `serialport` reads sysfs on Linux, and panics where it is not mounted.
    #[cfg(target_os = "linux")]
    if !std::path::Path::new("/sys/class/tty").is_dir() {
        return Err(
            "cannot list serial ports: /sys/class/tty is missing (is sysfs mounted?)".into(),
        );
    }
    serialport::available_ports()
        .map(from_infos)
        .map_err(|e| format!("cannot list the serial ports: {e}"))
}

/// The attached rigs: ports with the rig's USB id.
pub fn rigs() -> Result<Vec<Port>, String> {
    Ok(list()?.into_iter().filter(Port::is_rig).collect())
}

/// What a rig at `addr` answers to hello: `Ok((firmware version, rig serial in hex))` or why not.
pub fn probe(addr: &Address) -> Result<(String, String), LinkError> {
    let mut link = Link::open(addr)?;
    link.timeouts.reply = Duration::from_millis(400);
    link.timeouts.attempts = 2;
    let info = link.hello()?;
    Ok((
        super::firmware_version(&info),
        format!("{:016x}", info.serial),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serialport::UsbPortInfo;

    fn usb(name: &str, vid: u16, pid: u16, serial: Option<&str>) -> SerialPortInfo {
        SerialPortInfo {
            port_name: name.into(),
            port_type: SerialPortType::UsbPort(UsbPortInfo {
                vid,
                pid,
                serial_number: serial.map(Into::into),
                manufacturer: Some("tribo".into()),
                product: Some("oscillating tribometer".into()),
            }),
        }
    }

    fn plain(name: &str) -> SerialPortInfo {
        SerialPortInfo {
            port_name: name.into(),
            port_type: SerialPortType::PciPort,
        }
    }

    #[test]
    fn rigs_are_told_apart_by_their_usb_id_on_every_system() {
        // Windows: COM ports, the rig on COM10 beside a USB-serial adapter and a built-in port.
        let ports = from_infos(vec![
            usb("COM10", RIG_VID, RIG_PID, Some("3A0017000B51")),
            plain("COM1"),
            usb("COM3", 0x0403, 0x6001, Some("FTDI1")),
        ]);
        let names: Vec<&str> = ports.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["COM1", "COM3", "COM10"], "in reading order");
        let rigs: Vec<&Port> = ports.iter().filter(|p| p.is_rig()).collect();
        assert_eq!(rigs.len(), 1);
        assert_eq!(rigs[0].name, "COM10");
        assert_eq!(rigs[0].usb_id(), "1209:0001");
        assert_eq!(rigs[0].serial.as_deref(), Some("3A0017000B51"));
        assert_eq!(ports[0].usb_id(), "—");

        // Linux: two rigs on ttyACM*, told apart by serial number.
        let ports = from_infos(vec![
            usb("/dev/ttyACM1", RIG_VID, RIG_PID, Some("B")),
            usb("/dev/ttyACM0", RIG_VID, RIG_PID, Some("A")),
            plain("/dev/ttyS0"),
        ]);
        let rigs: Vec<(&str, Option<&str>)> = ports
            .iter()
            .filter(|p| p.is_rig())
            .map(|p| (p.name.as_str(), p.serial.as_deref()))
            .collect();
        assert_eq!(
            rigs,
            [("/dev/ttyACM0", Some("A")), ("/dev/ttyACM1", Some("B"))]
        );

        // macOS: each device as /dev/tty.X and /dev/cu.X; the call-out one is kept.
        let ports = from_infos(vec![
            usb("/dev/tty.usbmodem1101", RIG_VID, RIG_PID, Some("A")),
            usb("/dev/cu.usbmodem1101", RIG_VID, RIG_PID, Some("A")),
            plain("/dev/tty.Bluetooth-Incoming-Port"),
        ]);
        let names: Vec<&str> = ports.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            ["/dev/cu.usbmodem1101", "/dev/tty.Bluetooth-Incoming-Port"]
        );
    }

    #[test]
    fn listing_the_ports_of_this_machine_does_not_fail() {
        // Whatever is attached (usually nothing on CI): the listing works and keeps its invariants.
        let ports = list().expect("listing serial ports");
        let mut names: Vec<&str> = ports.iter().map(|p| p.name.as_str()).collect();
        let n = names.len();
        names.dedup();
        assert_eq!(names.len(), n, "each port once");
        assert!(ports.iter().all(|p| p.vid.is_some() == p.pid.is_some()));
    }
}
