//! `tribo devices`: attached rigs (USB VID/PID, serial number, firmware version).

use crate::link::devices::{probe, scan};
use std::path::{Path, PathBuf};

/// Arguments of `tribo devices`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Do not open the ports to ask for the firmware version.
    #[arg(long)]
    pub no_probe: bool,
    /// Also probe this port (e.g. a virtual rig's pseudo-terminal).
    #[arg(long)]
    pub port: Vec<PathBuf>,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let mut ports = scan(Path::new("/sys/class/tty"));
    for p in &args.port {
        ports.push(crate::link::devices::Port {
            path: p.clone(),
            vid: None,
            pid: None,
            serial: None,
            product: None,
        });
    }
    let v = Path::new(super::run::DEFAULT_VIRTUAL_LINK);
    if v.exists() && args.port.is_empty() {
        ports.push(crate::link::devices::Port {
            path: v.to_owned(),
            vid: None,
            pid: None,
            serial: None,
            product: Some("virtual rig".into()),
        });
    }
    if ports.is_empty() {
        println!(
            "no rig attached (no /dev/ttyACM* port). Plug the rig's USB cable in (and check `dmesg`), or start a \
             virtual rig with `tribo rig --virtual`"
        );
        return Ok(());
    }
    println!(
        "{:<24} {:<10} {:<20} {:<10} rig serial / note",
        "port", "usb id", "usb serial", "firmware"
    );
    for p in ports {
        let id = match (p.vid, p.pid) {
            (Some(v), Some(d)) => format!("{v:04x}:{d:04x}"),
            _ => "—".into(),
        };
        let (fw, note) = if args.no_probe {
            ("—".to_string(), p.product.clone().unwrap_or_default())
        } else {
            match probe(&p.path) {
                Ok((fw, serial)) => (fw, serial),
                Err(e) => ("—".to_string(), format!("not a rig? {e}")),
            }
        };
        println!(
            "{:<24} {:<10} {:<20} {:<10} {}",
            p.path.display(),
            id,
            p.serial.as_deref().unwrap_or("—"),
            fw,
            note
        );
    }
    Ok(())
}
