//! `tribo rig --virtual`: the firmware's application against the physics simulator, served on a
//! local TCP address (or, on Unix, a pseudo-terminal), so that `tribo run --port tcp://…` reaches
//! it through the link a USB rig uses. One rig process serves successive hosts, one at a time, and
//! runs on between them. `tribo demo` runs the same rig in-process.

use crate::link::transport::DEFAULT_VIRTUAL_RIG;
use crate::link::Address;
use anyhow::{bail, Context};
use tribo_rig::{HostEvent, VirtualRigConfig};

use crate::virtual_rig::VirtualArgs;

/// Arguments of `tribo rig`.
#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:
  tribo rig --virtual                        listen on tcp://127.0.0.1:7411
  tribo run --port tcp://127.0.0.1:7411 --load 0.3      (in another terminal)
  tribo rig --virtual --listen 127.0.0.1:0 --speed 10 --mu0 0.015
  tribo rig --virtual --fault stuck:v        a converter input stuck: `tribo selftest` names it")]
pub struct Args {
    /// Run the virtual rig (the only kind this command can start).
    #[arg(long = "virtual")]
    pub virtual_rig: bool,
    /// The virtual rig's constants, faults and speed.
    #[command(flatten)]
    pub rig: VirtualArgs,
    /// Address to listen on, HOST:PORT (port 0: any free port; the address is printed). The rig
    /// has no password: keep it on 127.0.0.1 unless the network is trusted.
    #[arg(long, default_value = DEFAULT_VIRTUAL_RIG, value_name = "ADDR")]
    pub listen: String,
    /// Unix only: serve the rig on a pseudo-terminal instead, opened by hosts as a serial port
    /// (through the same code as a USB rig); its name is printed.
    #[arg(long, conflicts_with = "listen")]
    pub pty: bool,
}

/// The rig's settings, one line.
fn describe(cfg: &VirtualRigConfig, a: &VirtualArgs) -> String {
    let mut faults: String = a
        .faults
        .iter()
        .map(|(c, f)| format!(", input {} {f:?}", ["x", "v", "f", "ecr"][*c]))
        .collect();
    if let Some(f) = a.tc_fault {
        faults.push_str(&format!(", thermocouple {f:?}"));
    }
    if let Some(ppm) = a.hse_error_ppm {
        faults.push_str(&format!(", HSE {ppm:+.0} ppm"));
    }
    format!(
        "m = {} kg, k = {} N/m, load {} N{}, contact {}, apparatus μ1 {}, seed {}, speed ×{}{faults}",
        cfg.mass_kg,
        cfg.stiffness_n_per_m,
        cfg.load_n,
        if a.fixed_load {
            " (fixed)"
        } else {
            " (follows each run's --load)"
        },
        cfg.law,
        cfg.apparatus_mu1,
        cfg.seed,
        a.speed
    )
}

/// Says which rig constants the configuration file leaves to the thesis's rig.
fn print_defaults(a: &VirtualArgs) {
    if let Some(p) = &a.config {
        // The file was read and checked before; were it gone since, there is nothing to say.
        let d = std::fs::read_to_string(p)
            .ok()
            .and_then(|t| VirtualRigConfig::defaulted(&t).ok())
            .unwrap_or_default();
        if !d.is_empty() {
            println!(
                "  {} does not give {}: the thesis's rig stands in (values above)",
                p.display(),
                d.join(", ")
            );
        }
    }
}

/// Runs the subcommand (until Ctrl-C).
pub fn run(mut args: Args) -> anyhow::Result<()> {
    // The rig's console (commands, faults, resets) follows on standard output.
    args.rig.log_events = true;
    if !args.virtual_rig {
        return Err(crate::exit::Usage(
            "`tribo rig` starts the virtual rig: add --virtual (a real rig needs no command: plug it in and use --port)".into(),
        )
        .into());
    }
    // Stopped by a signal, it exits with that signal's status (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP),
    // as every command does.
    crate::signals::set_handler(|signal| {
        crate::errln!("\nvirtual rig stopped");
        std::process::exit(signal.status().into());
    })
    .context("cannot install the Ctrl-C handler")?;
    if args.pty {
        return run_pty(&args);
    }
    let listen = args
        .listen
        .strip_prefix("tcp://")
        .unwrap_or(&args.listen)
        .to_string();
    check_listen(&listen)?;
    let (tcp, cfg) = args.rig.listen(&listen, |e| match e {
        HostEvent::Connected(a) => crate::errln!("host {a} connected"),
        HostEvent::Disconnected(a, why) => crate::errln!("host {a} gone: {why}"),
        HostEvent::Refused(a) => crate::errln!(
            "host {a} turned away: another host is connected (the rig serves one at a time)"
        ),
    })?;
    let addr = Address::from(tcp.addr());
    println!("virtual rig listening on {addr}");
    println!("  {}", describe(&cfg, &args.rig));
    print_defaults(&args.rig);
    println!("  try: tribo run --port {addr} --load {}", cfg.load_n);
    println!("  Ctrl-C stops it; the rig's console follows (commands, faults, resets)");
    tcp.wait();
    Ok(())
}

/// `--listen HOST:PORT` as a person can get it wrong: no port, or a port that is not 0–65535
/// (`127.0.0.1:80000`): a usage error (status 2) before anything is bound.
fn check_listen(listen: &str) -> anyhow::Result<()> {
    let bad = |why: &str| -> anyhow::Result<()> {
        Err(crate::exit::Usage(format!(
            "--listen {listen}: {why}; write HOST:PORT, e.g. 127.0.0.1:7411 (port 0: any free one)"
        ))
        .into())
    };
    let Some((host, port)) = listen.rsplit_once(':') else {
        return bad("no port");
    };
    if host.is_empty() {
        return bad("no host");
    }
    match port.parse::<u16>() {
        Ok(_) => Ok(()),
        Err(_) => bad(&format!(
            "the port {port:?} is not a number from 0 to 65535"
        )),
    }
}

#[cfg(unix)]
fn run_pty(args: &Args) -> anyhow::Result<()> {
    let (rig, opts) = args.rig.build()?;
    let cfg = rig.config().clone();
    let (name, thread) =
        crate::link::pty::spawn(rig, opts).context("cannot open a pseudo-terminal")?;
    println!("virtual rig on the pseudo-terminal {name}");
    println!("  {}", describe(&cfg, &args.rig));
    print_defaults(&args.rig);
    println!("  try: tribo run --port {name} --load {}", cfg.load_n);
    println!("  Ctrl-C stops it; the rig's console follows (commands, faults, resets)");
    match thread.join() {
        Ok(r) => r.context("virtual rig: the pseudo-terminal failed"),
        Err(_) => bail!("virtual rig: its thread panicked"),
    }
}

#[cfg(not(unix))]
fn run_pty(_: &Args) -> anyhow::Result<()> {
    bail!("--pty is a Unix extra: serve the rig on TCP instead (leave --pty out) and give its tcp:// address to --port")
}
