//! The virtual rig: the firmware's application (`tribo_firmware::app::App`, the very code that runs
//! on the board) driven against the physics simulator instead of embassy-stm32 peripherals.
//!
//! * [`VirtualRigConfig`]: the simulated rig (constants, friction law, noise, heater, ECR), readable
//!   from TOML.
//! * [`VirtualRig`]: the simulator-backed hardware ([`sim::SimHardware`]) plus the application, stepped
//!   with [`VirtualRig::advance_to`] and fed with [`VirtualRig::input`]; frames come out of
//!   [`VirtualRig::take_output`].
//! * [`serve`]: runs the rig in real time (or faster) over any byte stream, e.g. the master side of a
//!   pseudo-terminal. It returns when the reader reaches end of file, like a pulled cable; the rig keeps
//!   its stored run, so a later `serve` on the same rig answers a `Pull` of it.

pub mod config;
pub mod sim;

pub use config::{AcquisitionFaults, EcrModel, LawConfig, Noise, ThermalModel, VirtualRigConfig};
pub use sim::SimHardware;

use std::io::{self, Read, Write};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use tribo_firmware::app::{App, AppConfig};
use tribo_firmware::hal::{HeaterOutput, Magnet, MagnetDrive, SampleSource, ThermocoupleFault};
use tribo_firmware::runstore::{RunStore, BOARD_RING_BYTES, MAX_RUN_BLOCKS};

/// A virtual rig: simulated hardware and the firmware application.
pub struct VirtualRig {
    app: App<'static>,
    hw: SimHardware,
    now_us: u64,
    tick_us: u64,
    serial: u64,
}

/// A run store with the board's RAM (ring buffers and block index), so that what a host can pull
/// from the virtual rig is what it could pull from the real one. Leaked: it lives as long as the
/// program (761 KiB per rig, and per power cycle).
fn board_store() -> RunStore<'static> {
    let ring = BOARD_RING_BYTES
        .map(|n| -> &'static mut [u8] { Box::leak(vec![0u8; n].into_boxed_slice()) });
    let index: &'static mut [u32] = Box::leak(vec![0u32; MAX_RUN_BLOCKS].into_boxed_slice());
    RunStore::new(ring, index)
}

impl VirtualRig {
    /// A rig at time 0, pin held nowhere (magnet off), heater off. Refuses an invalid configuration.
    pub fn new(cfg: VirtualRigConfig) -> Result<VirtualRig, String> {
        let hw = SimHardware::new(&cfg)?;
        let mut rig = VirtualRig {
            app: App::new(AppConfig::new(cfg.serial), board_store()),
            hw,
            now_us: 0,
            // polled as the board polls it
            tick_us: AppConfig::new(cfg.serial).poll_period_us as u64,
            serial: cfg.serial,
        };
        rig.app.poll(&mut rig.hw, 0);
        Ok(rig)
    }

    /// Cuts the power and turns it on again: the firmware restarts with empty RAM (an operation the
    /// flash was doing is torn), the flash keeps what it holds, the physical rig stays where it is
    /// (the magnet lets go, the heater stops). The application recovers the last run from flash on
    /// its first poll, as the board does.
    pub fn power_cycle(&mut self) {
        self.hw.flash.power_cut();
        self.hw.adc_stop();
        self.hw.magnet_drive(MagnetDrive::Off);
        self.hw.set_heater_duty(0.0);
        self.app = App::new(AppConfig::new(self.serial), board_store());
        self.app.poll(&mut self.hw, self.now_us);
    }

    /// Device time, µs.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// The application (state, status, stored run).
    pub fn app(&self) -> &App<'static> {
        &self.app
    }

    /// The simulated hardware (for inspection and fault injection).
    pub fn hardware(&mut self) -> &mut SimHardware {
        &mut self.hw
    }

    /// Bytes from the host.
    pub fn input(&mut self, bytes: &[u8]) {
        self.app.on_bytes(&mut self.hw, bytes, self.now_us);
    }

    /// Bytes for the host produced so far.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.hw.out)
    }

    /// Runs the simulation and the application up to `t_us`, polling the application every
    /// millisecond of device time (as the board's application task does).
    pub fn advance_to(&mut self, t_us: u64) {
        while self.now_us < t_us {
            let next = (self.now_us + self.tick_us).min(t_us);
            self.hw.advance(next);
            self.now_us = next;
            self.app.poll(&mut self.hw, next);
        }
    }

    /// Holds the user button down (true) or lets it go.
    pub fn set_button(&mut self, pressed: bool) {
        self.hw.button = pressed;
    }

    /// Makes the thermocouple converter report a fault (or heals it with `None`).
    pub fn set_thermocouple_fault(&mut self, fault: Option<ThermocoupleFault>) {
        self.hw.tc_fault = fault;
    }

    /// Whether the link takes frames (false: the cable is out; frames wait in the firmware).
    pub fn set_connected(&mut self, connected: bool) {
        self.hw.connected = connected;
        if connected {
            self.app.link_reset();
        }
    }

    /// The dimensionless (μ0, μ1) a Coulomb–viscous fit of this rig should find: the contact law's
    /// constants plus the apparatus damping in μ1 (`None` for a law without both).
    pub fn truth(&self) -> Option<(f64, f64)> {
        self.hw.truth()
    }
}

/// How [`serve`] runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServeOptions {
    /// Device seconds per wall-clock second (1 = real time; `f64::INFINITY` = as fast as possible).
    pub speed: f64,
    /// Longest wait for host bytes before the simulation moves on, wall-clock.
    pub max_wait: Duration,
}

impl Default for ServeOptions {
    fn default() -> Self {
        ServeOptions {
            speed: 1.0,
            max_wait: Duration::from_millis(2),
        }
    }
}

/// Serves the rig over a byte stream: host frames are read from `reader` (on a thread of its own),
/// device frames written to `writer`, and the simulation advances with the wall clock times
/// `opts.speed`. Returns `Ok(())` when `reader` reaches end of file or fails (the cable is pulled),
/// and an error when `writer` fails. The rig keeps its state, stored run included: call `serve`
/// again on the same rig to reconnect.
///
/// For a stream that is both (a pseudo-terminal master, a socket), pass `f.try_clone()?` and `f`.
/// The reader thread ends at the stream's end of file (it may outlive this call until then).
///
/// With a pseudo-terminal, reading the master fails (EIO) once no process holds the slave open, so
/// `serve` returns when the client closes the port: loop on `serve` to accept the next client (the
/// stored run survives), and keep a slave descriptor open in the serving process if the client
/// should be able to close and reopen the port without the rig noticing.
pub fn serve<R, W>(
    rig: &mut VirtualRig,
    mut reader: R,
    mut writer: W,
    opts: &ServeOptions,
) -> io::Result<()>
where
    R: Read + Send + 'static,
    W: Write,
{
    if opts.speed.is_nan() || opts.speed <= 0.0 {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("speed must be > 0, got {}", opts.speed),
        ));
    }
    rig.app.link_reset();
    let (tx, rx) = mpsc::channel::<Vec<u8>>();
    std::thread::spawn(move || {
        let mut buf = [0u8; 4096];
        loop {
            match reader.read(&mut buf) {
                Ok(0) => return,
                Ok(n) => {
                    if tx.send(buf[..n].to_vec()).is_err() {
                        return;
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(_) => return,
            }
        }
    });
    let start_wall = Instant::now();
    let start_dev = rig.now_us;
    let fast = !opts.speed.is_finite();
    loop {
        let wait = if fast { Duration::ZERO } else { opts.max_wait };
        let mut closed = false;
        match rx.recv_timeout(wait) {
            Ok(bytes) => rig.input(&bytes),
            Err(mpsc::RecvTimeoutError::Timeout) => {}
            Err(mpsc::RecvTimeoutError::Disconnected) => closed = true,
        }
        while let Ok(bytes) = rx.try_recv() {
            rig.input(&bytes);
        }
        let target = if fast {
            rig.now_us + 10_000
        } else {
            start_dev + (start_wall.elapsed().as_secs_f64() * opts.speed.max(0.0) * 1e6) as u64
        };
        rig.advance_to(target);
        let out = rig.take_output();
        if !out.is_empty() {
            writer.write_all(&out)?;
            writer.flush()?;
        }
        if closed {
            return Ok(());
        }
    }
}

// The rig can be moved to a serving thread.
const _: fn() = || {
    fn send<T: Send>() {}
    send::<VirtualRig>();
};
