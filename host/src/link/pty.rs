//! The virtual rig behind a pseudo-terminal: the client opens the slave side exactly as it opens a
//! USB port, so `tribo run --port <slave>` goes through the very code path used with hardware.
//!
//! The server keeps a handle on the slave side itself, so the terminal's raw settings persist and a
//! client that closes the port (a pulled cable) does not end the rig: its frames wait in the
//! terminal's buffer (and the rig blocks when it is full) until a client opens the port again, which
//! discards them; what they carried is fetched with `Pull`.

use super::serial::make_raw;
use anyhow::Context;
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};
use tribo_rig::{serve, ServeOptions, VirtualRig, VirtualRigConfig};
use tribo_wire::{Decoder, Frame, HostMsg, RigState};

/// A pseudo-terminal with a virtual rig on its master side.
pub struct VirtualPort {
    slave_path: PathBuf,
    master: OwnedFd,
    _slave: OwnedFd,
}

impl VirtualPort {
    /// Opens a new pseudo-terminal in raw mode.
    pub fn open() -> anyhow::Result<VirtualPort> {
        let pty = nix::pty::openpty(None, None)
            .context("cannot open a pseudo-terminal (is /dev/ptmx available?)")?;
        make_raw(&pty.slave).context("cannot set the pseudo-terminal to raw mode")?;
        let slave_path =
            nix::unistd::ttyname(&pty.slave).context("cannot name the pseudo-terminal")?;
        Ok(VirtualPort {
            slave_path,
            master: pty.master,
            _slave: pty.slave,
        })
    }

    /// The port to give to `tribo run --port`.
    pub fn path(&self) -> &Path {
        &self.slave_path
    }

    /// Serves a virtual rig built from `cfg` on this port on a new thread, until the process ends.
    ///
    /// With `follow_load`, the simulated load knob follows the load of each `Configure` the rig
    /// receives while no run is in progress (a virtual rig has no hand on its knob): the rig is
    /// rebuilt at the new load, as if power-cycled, keeping the plate's temperature. With
    /// `button_after_s`, the rig's button is pressed that long (device time) after it was armed.
    pub fn spawn_with(
        self,
        cfg: VirtualRigConfig,
        opts: ServeOptions,
        follow_load: bool,
        button_after_s: Option<f64>,
    ) -> anyhow::Result<JoinHandle<anyhow::Result<()>>> {
        let mut rig =
            VirtualRig::new(cfg.clone()).map_err(|e| anyhow::anyhow!("virtual rig: {e}"))?;
        rig.set_host_lease_ms(tribo_rig::lease_for_speed(opts.speed));
        let mut reader = File::from(self.master.try_clone()?);
        let mut writer = File::from(self.master.try_clone()?);
        let (tx, rx) = mpsc::channel::<Vec<u8>>();
        std::thread::Builder::new()
            .name("tribo-virtual-rig-input".into())
            .spawn(move || {
                let mut buf = [0u8; 4096];
                loop {
                    match reader.read(&mut buf) {
                        Ok(0) => return,
                        Ok(n) => {
                            if tx.send(buf[..n].to_vec()).is_err() {
                                return;
                            }
                        }
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        Err(_) => return,
                    }
                }
            })?;
        Ok(std::thread::Builder::new()
            .name("tribo-virtual-rig".into())
            .spawn(move || {
                let _keep = (self._slave, self.master);
                let mut rig = rig;
                let mut cfg = cfg;
                let mut decoder = Decoder::<HostMsg>::new();
                let mut start = (Instant::now(), rig.now_us());
                let fast = !opts.speed.is_finite();
                let (mut armed_since, mut pressed_at): (Option<u64>, Option<u64>) = (None, None);
                loop {
                    let wait = if fast { Duration::ZERO } else { opts.max_wait };
                    let mut input = match rx.recv_timeout(wait) {
                        Ok(b) => b,
                        Err(mpsc::RecvTimeoutError::Timeout) => vec![],
                        Err(mpsc::RecvTimeoutError::Disconnected) => return Ok(()),
                    };
                    while let Ok(more) = rx.try_recv() {
                        input.extend(more);
                    }
                    if !input.is_empty() {
                        let mut load = None;
                        decoder.feed(&input, |f| {
                            if let Ok(Frame {
                                msg: HostMsg::Configure(c),
                                ..
                            }) = f
                            {
                                load = Some(c.rig.load_n as f64);
                            }
                        });
                        let idle = !matches!(rig.app().state(), RigState::Running);
                        if let Some(l) =
                            load.filter(|l| follow_load && idle && (*l - cfg.load_n).abs() > 1e-9)
                        {
                            let temp = rig.hardware().plate_temp_c();
                            let mut c = cfg.clone();
                            c.load_n = l;
                            if let Ok(mut r) = VirtualRig::new(c.clone()) {
                                r.hardware().set_plate_temp_c(temp);
                                r.set_host_lease_ms(tribo_rig::lease_for_speed(opts.speed));
                                rig = r;
                                cfg = c;
                                start = (Instant::now(), rig.now_us());
                            }
                        }
                        rig.input(&input);
                    }
                    let target = if fast {
                        rig.now_us() + 10_000
                    } else {
                        start.1
                            + (start.0.elapsed().as_secs_f64() * opts.speed.max(0.0) * 1e6) as u64
                    };
                    rig.advance_to(target);
                    tribo_rig::print_events(&mut rig, &opts);
                    if let Some(after) = button_after_s {
                        // A finger on the button: pressed `after` s into the armed state, held 50 ms.
                        let now = rig.now_us();
                        if matches!(rig.app().state(), RigState::Armed) {
                            let since = *armed_since.get_or_insert(now);
                            if pressed_at.is_none()
                                && now.saturating_sub(since) as f64 >= after * 1e6
                            {
                                rig.set_button(true);
                                pressed_at = Some(now);
                            }
                        } else {
                            armed_since = None;
                        }
                        if pressed_at.is_some_and(|t| now.saturating_sub(t) >= 50_000) {
                            rig.set_button(false);
                            pressed_at = None;
                        }
                    }
                    let out = rig.take_output();
                    if !out.is_empty() {
                        writer
                            .write_all(&out)
                            .context("virtual rig: writing to the pseudo-terminal")?;
                    }
                }
            })?)
    }

    /// Serves `rig` on this port on a new thread, until the process ends.
    pub fn spawn(self, mut rig: VirtualRig, opts: ServeOptions) -> JoinHandle<anyhow::Result<()>> {
        std::thread::Builder::new()
            .name("tribo-virtual-rig".into())
            .spawn(move || {
                let _keep = self._slave;
                loop {
                    let reader = File::from(self.master.try_clone()?);
                    let writer = File::from(self.master.try_clone()?);
                    serve(&mut rig, reader, writer, &opts)
                        .context("virtual rig: writing to the pseudo-terminal")?;
                }
            })
            .expect("spawning a thread")
    }
}

/// Points `link` at `target` (a symlink), replacing an older symlink but never a real file.
pub fn make_link(link: &Path, target: &Path) -> anyhow::Result<()> {
    if let Ok(m) = std::fs::symlink_metadata(link) {
        if m.file_type().is_symlink() {
            std::fs::remove_file(link)
                .with_context(|| format!("cannot replace {}", link.display()))?;
        } else {
            anyhow::bail!(
                "{} exists and is not a symlink: choose another path with --link",
                link.display()
            );
        }
    }
    std::os::unix::fs::symlink(target, link)
        .with_context(|| format!("cannot create the symlink {}", link.display()))
}
