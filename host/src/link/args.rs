//! How the rig commands reach the rig and where they store runs (`--port`, `--store`).

use crate::link::transport::DEFAULT_VIRTUAL_RIG;
use crate::link::{devices, firmware_version, Address, Link, LinkErrorKind};
use anyhow::bail;
use std::path::PathBuf;

/// How to reach the rig and where to store runs.
#[derive(clap::Args, Debug, Clone)]
pub struct LinkArgs {
    /// The rig's port: a serial port as the system names it (Windows: COM3; macOS:
    /// /dev/cu.usbmodem…; Linux: /dev/ttyACM0; `tribo devices` lists them), or tcp://HOST:PORT for
    /// a virtual rig (`tribo rig --virtual` prints it). Default: $TRIBO_PORT, else the only attached
    /// rig, else a virtual rig at tcp://127.0.0.1:7411.
    #[arg(long, short, value_name = "PORT")]
    pub port: Option<Address>,
    /// Run store directory (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
}

impl LinkArgs {
    /// The run store: `--store`, else `$TRIBO_STORE`, else `./runs`.
    pub fn store(&self) -> PathBuf {
        self.store
            .clone()
            .unwrap_or_else(tribo_store::default_store_dir)
    }

    /// The store, checked writable before anything is armed (a file in the way, a read-only
    /// folder): a sphere released with nobody able to record it is a run lost.
    pub fn writable_store(&self) -> anyhow::Result<PathBuf> {
        let store = self.store();
        let fail = |e: std::io::Error| {
            anyhow::anyhow!(
                "the run store {} cannot be written ({e}): nothing was sent to the rig; pass --store with a folder you can write",
                store.display()
            )
        };
        std::fs::create_dir_all(&store).map_err(fail)?;
        let probe = store.join(format!(".tribo-write-test-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(fail)?;
        std::fs::remove_file(&probe).map_err(fail)?;
        Ok(store)
    }

    /// The port to use, and, when no rig was named nor found and the default virtual rig's address
    /// is tried instead, why. An error lists what to do.
    pub fn port(&self) -> anyhow::Result<(Address, Option<String>)> {
        if let Some(p) = &self.port {
            return Ok((p.clone(), None));
        }
        if let Some(p) = std::env::var_os("TRIBO_PORT").filter(|p| !p.is_empty()) {
            let p = Address::parse(&p.to_string_lossy())
                .map_err(|e| anyhow::anyhow!("$TRIBO_PORT: {e}"))?;
            return Ok((p, None));
        }
        let why = match devices::rigs() {
            Ok(rigs) if rigs.len() == 1 => return Ok((Address::Serial(rigs[0].name.clone()), None)),
            Ok(rigs) if rigs.len() > 1 => bail!(
                "several rigs are attached ({}): choose one with --port (`tribo devices` shows their serial numbers)",
                rigs.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(", ")
            ),
            Ok(_) => "no USB serial port with the rig's id 1209:0001".to_string(),
            Err(e) => e,
        };
        Ok((Address::Tcp(DEFAULT_VIRTUAL_RIG.into()), Some(why)))
    }

    /// Opens the link and says hello.
    pub fn connect(&self) -> anyhow::Result<(Link, tribo_wire::DeviceInfo)> {
        let (port, fallback) = self.port()?;
        let mut link = match (Link::open(&port), fallback) {
            (Ok(l), _) => l,
            (Err(e), Some(why)) if e.kind == LinkErrorKind::Open => bail!(
                "no rig found ({why}; no virtual rig at {port}): attach one (see `tribo devices`) and give \
                 --port, or start a virtual rig with `tribo rig --virtual` in another terminal"
            ),
            (Err(e), _) => return Err(e.into()),
        };
        let info = match link.hello() {
            Ok(i) => i,
            // Closed before it said hello: a rig serving another host turns a second one away.
            Err(e) if e.kind == LinkErrorKind::Closed => bail!(
                "the rig on {port} closed the connection before answering: it serves one host at a \
                 time, so another `tribo` is probably connected to it (wait for it, or stop it); \
                 nothing was sent to the rig and nothing was recorded"
            ),
            Err(e) => return Err(e.into()),
        };
        Ok((link, info))
    }

    /// [`LinkArgs::connect`], then says which rig answered (unless `quiet`) and warns when it
    /// reset by itself since a host last spoke to it.
    pub fn connect_and_announce(
        &self,
        quiet: bool,
    ) -> anyhow::Result<(Link, tribo_wire::DeviceInfo)> {
        let (link, info) = self.connect()?;
        if !quiet {
            crate::errln!(
                "rig on {}: firmware {}, serial {:016x}",
                link.name(),
                firmware_version(&info),
                info.serial
            );
        }
        crate::ui::warn_about_reset(&link);
        Ok((link, info))
    }
}
