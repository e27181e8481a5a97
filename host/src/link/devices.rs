//! Finding attached rigs: USB CDC ACM ports under `/sys/class/tty`, with their USB ids, and the
//! firmware version each one announces in its hello.

use super::Link;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A serial port that may be a rig.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Port {
    pub path: PathBuf,
    pub vid: Option<u16>,
    pub pid: Option<u16>,
    pub serial: Option<String>,
    pub product: Option<String>,
}

fn read_attr(dir: &Path, name: &str) -> Option<String> {
    std::fs::read_to_string(dir.join(name))
        .ok()
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
}

/// USB ACM ports (`ttyACM*`) found under `sys_class_tty` (normally `/sys/class/tty`), sorted.
pub fn scan(sys_class_tty: &Path) -> Vec<Port> {
    let Ok(rd) = std::fs::read_dir(sys_class_tty) else {
        return vec![];
    };
    let mut ports: Vec<Port> = rd
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("ttyACM"))
        .map(|e| {
            // .../ttyACM0/device is the USB interface; its parent is the USB device with the ids.
            let usb = e.path().join("device").join("..");
            let hex = |n| read_attr(&usb, n).and_then(|s| u16::from_str_radix(&s, 16).ok());
            Port {
                path: Path::new("/dev").join(e.file_name()),
                vid: hex("idVendor"),
                pid: hex("idProduct"),
                serial: read_attr(&usb, "serial"),
                product: read_attr(&usb, "product"),
            }
        })
        .collect();
    ports.sort_by(|a, b| a.path.cmp(&b.path));
    ports
}

/// What a port answered to hello: `Ok((firmware, serial hex))` or why not.
pub fn probe(path: &Path) -> Result<(String, String), String> {
    let mut link = Link::open(path).map_err(|e| e.msg)?;
    link.timeouts.reply = Duration::from_millis(400);
    link.timeouts.attempts = 2;
    let info = link.hello().map_err(|e| e.msg)?;
    Ok((
        super::firmware_version(&info),
        format!("{:016x}", info.serial),
    ))
}
