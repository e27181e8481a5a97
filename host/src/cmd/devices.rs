//! `tribo devices`: attached rigs (port, USB id, USB serial number, firmware version), found the
//! same way on Windows, macOS and Linux.

use crate::link::devices::{list, probe, Port};
use crate::link::transport::DEFAULT_VIRTUAL_RIG;
use crate::link::Address;

/// Arguments of `tribo devices`.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "A rig is a USB serial port with the id 1209:0001. Other serial ports are \
                        listed with --all but never opened: they may belong to other instruments."
)]
pub struct Args {
    /// Also list the serial ports that are not rigs (not opened).
    #[arg(long)]
    pub all: bool,
    /// Do not open the rigs' ports to ask for their firmware version.
    #[arg(long)]
    pub no_probe: bool,
    /// Also ask this port: a serial port, or tcp://HOST:PORT (a virtual rig). Repeatable.
    #[arg(long, value_name = "PORT")]
    pub port: Vec<Address>,
}

/// A line of the table: where, what the system says of it, and what it answered to hello.
struct Row {
    addr: Address,
    port: Option<Port>,
    note: &'static str,
    answer: Option<Result<(String, String), crate::link::LinkError>>,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let ask = |a: &Address| (!args.no_probe).then(|| probe(a));
    let mut rows: Vec<Row> = list()
        .map_err(|e| anyhow::anyhow!("{e}"))?
        .into_iter()
        .filter(|p| args.all || p.is_rig())
        .map(|p| {
            let addr = Address::Serial(p.name.clone());
            Row {
                answer: if p.is_rig() { ask(&addr) } else { None },
                note: if p.is_rig() { "" } else { "not a rig" },
                addr,
                port: Some(p),
            }
        })
        .collect();
    for a in &args.port {
        rows.push(Row {
            addr: a.clone(),
            port: None,
            note: "",
            answer: ask(a),
        });
    }
    // A virtual rig at the default address, if one runs there.
    if args.port.is_empty() && !args.no_probe {
        let addr = Address::Tcp(DEFAULT_VIRTUAL_RIG.into());
        if let Ok(a) = probe(&addr) {
            rows.push(Row {
                addr,
                port: None,
                note: "virtual rig",
                answer: Some(Ok(a)),
            });
        }
    }
    if rows.is_empty() {
        println!(
            "no rig attached (no USB serial port with the rig's id 1209:0001). Plug the rig's USB cable in \
             (see the README's set-up section for your system; `--all` lists every serial port), or start a \
             virtual rig with `tribo rig --virtual`"
        );
        return Ok(());
    }
    println!(
        "{:<26} {:<10} {:<18} {:<10} rig serial / note",
        "port", "usb id", "usb serial", "firmware"
    );
    for r in rows {
        let product = r.port.as_ref().and_then(|p| p.product.as_deref());
        let (fw, note) = match r.answer {
            Some(Ok((fw, serial))) => (fw, format!("{serial} {}", r.note)),
            Some(Err(e)) => ("—".to_string(), format!("no answer: {e}")),
            None => (
                "—".to_string(),
                format!(
                    "{} {}",
                    r.note,
                    product.map(|p| format!("({p})")).unwrap_or_default()
                ),
            ),
        };
        let (id, usb_serial) = match &r.port {
            Some(p) => (p.usb_id(), p.serial.clone().unwrap_or_else(|| "—".into())),
            None => ("—".into(), "—".into()),
        };
        println!(
            "{:<26} {:<10} {:<18} {:<10} {}",
            r.addr.to_string(),
            id,
            usb_serial,
            fw,
            note.trim()
        );
    }
    Ok(())
}
