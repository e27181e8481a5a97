//! The virtual rig: the firmware's application (`tribo_firmware::app::App`, the very code that runs
//! on the board) driven against the physics simulator instead of embassy-stm32 peripherals.
//!
//! * [`VirtualRigConfig`]: the simulated rig (constants, friction law, noise, heater, ECR), readable
//!   from TOML.
//! * [`VirtualRig`]: the simulator-backed hardware ([`sim::SimHardware`]) plus the application, stepped
//!   with [`VirtualRig::advance_to`] and fed with [`VirtualRig::input`]; frames come out of
//!   [`VirtualRig::take_output`].
//! * [`serve`](mod@serve): the rig in real time (or faster) for a host: over any byte stream
//!   ([`serve()`]), to successive TCP connections ([`TcpRig`]), or in-process ([`in_process`]).

pub mod config;
pub mod serve;
pub mod sim;

pub use config::{AcquisitionFaults, EcrModel, LawConfig, Noise, ThermalModel, VirtualRigConfig};
pub use serve::{in_process, serve, HostEvent, ServeOptions, TcpRig};
pub use sim::SimHardware;

use tribo_firmware::app::{App, AppConfig};
use tribo_firmware::hal::{HeaterOutput, Magnet, MagnetDrive, SampleSource, ThermocoupleFault};
use tribo_firmware::runstore::{RunStore, BOARD_RING_BYTES, MAX_RUN_BLOCKS};

/// A virtual rig: simulated hardware and the firmware application.
pub struct VirtualRig {
    app: App<'static>,
    hw: SimHardware,
    /// What the rig was built from (to rebuild it at another load).
    cfg: VirtualRigConfig,
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
        let app_cfg = AppConfig::new(cfg.serial);
        let mut rig = VirtualRig {
            app: App::new(app_cfg, board_store()),
            hw,
            serial: cfg.serial,
            cfg,
            now_us: 0,
            // polled as the board polls it
            tick_us: app_cfg.poll_period_us as u64,
        };
        rig.app.poll(&mut rig.hw, 0);
        Ok(rig)
    }

    /// The configuration the rig was built from.
    pub fn config(&self) -> &VirtualRigConfig {
        &self.cfg
    }

    /// This rig power-cycled with its load knob turned to `load_n` (the plate keeps its
    /// temperature; the stored run and the clock start afresh). Refuses a load the rig cannot take.
    pub fn with_load(&self, load_n: f64) -> Result<VirtualRig, String> {
        let mut cfg = self.cfg.clone();
        cfg.load_n = load_n;
        let mut rig = VirtualRig::new(cfg)?;
        rig.hw.set_plate_temp_c(self.hw.plate_temp_c());
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

// The rig can be moved to a serving thread.
const _: fn() = || {
    fn send<T: Send>() {}
    send::<VirtualRig>();
};
