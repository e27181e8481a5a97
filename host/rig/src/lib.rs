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
#![warn(missing_docs)]

pub mod config;
mod error;
pub mod serve;
pub mod sim;

pub use config::{AcquisitionFaults, EcrModel, Noise, ThermalModel, VirtualRigConfig};
pub use error::RigError;
pub use serve::{in_process, serve, HostEvent, ServeOptions, TcpRig, HANDOVER};
pub use sim::{ChannelFault, ConverterFault, HeaterStage, OutputFault, SimHardware};

use std::io::{self, Write};
use tribo_firmware::app::{App, AppConfig};
use tribo_firmware::reset::{self, Record, ResetFlags};
use tribo_firmware::runstore::{RunStore, BOARD_RING_BYTES, MAX_RUN_BLOCKS};
use tribo_firmware::selftest::Deliberate;
use tribo_firmware::watchdog::{self, Liveness, BOARD_TASKS, FEED_PERIOD_MS};
use tribo_wire::{limits, BootReport, Decoder, Frame, HostMsg, ResetCause};

/// A task of the board's firmware, as the virtual rig emulates them (fault injection).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Task {
    /// The application: stalled, it hogs the core (a busy loop), so no other task runs either and
    /// only the hardware watchdog gets the rig out.
    App,
    /// The thermocouple converter task: stalled, it waits forever (an SPI transfer that never
    /// completes).
    Thermocouple,
}

impl Task {
    fn index(self) -> usize {
        match self {
            Task::App => watchdog::task::APP,
            Task::Thermocouple => watchdog::task::THERMOCOUPLE,
        }
    }
}

/// Something the rig did that its technician would want to see on its console (`tribo rig
/// --virtual` prints these).
#[derive(Debug, Clone, PartialEq)]
pub struct RigEvent {
    /// Device time, µs.
    pub t_us: u64,
    /// What happened, in words.
    pub what: String,
}

impl std::fmt::Display for RigEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "[{:>10.3} s] {}", self.t_us as f64 * 1e-6, self.what)
    }
}

/// A virtual rig: simulated hardware and the firmware application, with the board's watchdog,
/// panic and fault handling emulated around it.
pub struct VirtualRig {
    app: App<'static>,
    hw: SimHardware,
    /// What the rig was built from (to rebuild it at another load).
    cfg: VirtualRigConfig,
    serial: u64,
    now_us: u64,
    tick_us: u64,
    // The board around the application: watchdog, reset record, resets.
    tasks: Liveness<{ BOARD_TASKS.len() }>,
    stalled: [bool; BOARD_TASKS.len()],
    next_feed_us: u64,
    last_pet_us: u64,
    /// The watchdog task saw a silent task and stopped feeding.
    starving: bool,
    noinit: Record,
    resets: u32,
    /// The converter task's reads already counted as check-ins.
    tc_reads_seen: u64,
    // The console.
    events: Vec<RigEvent>,
    decoder: Decoder<HostMsg>,
    last_host_us: Option<u64>,
    faults_seen: u32,
    host_lease_ms: u32,
}

/// A run store with the board's RAM (ring buffers and block index), so that what a host can pull
/// from the virtual rig is what it could pull from the real one. Leaked: it lives as long as the
/// program (761 KiB per rig, and per reset or power cycle).
fn board_store() -> RunStore<'static> {
    let ring = BOARD_RING_BYTES
        .map(|n| -> &'static mut [u8] { Box::leak(vec![0u8; n].into_boxed_slice()) });
    let index: &'static mut [u32] = Box::leak(vec![0u32; MAX_RUN_BLOCKS].into_boxed_slice());
    RunStore::new(ring, index)
}

fn new_app(serial: u64) -> App<'static> {
    App::new(AppConfig::new(serial), board_store())
}

impl VirtualRig {
    /// A rig at time 0, just powered on: pin held nowhere (magnet off), heater off. Refuses an
    /// invalid configuration.
    pub fn new(cfg: VirtualRigConfig) -> Result<VirtualRig, RigError> {
        let hw = SimHardware::new(&cfg)?;
        Ok(VirtualRig::with_hardware(cfg, hw))
    }

    /// A rig at time 0 on hardware built from `cfg`.
    fn with_hardware(cfg: VirtualRigConfig, hw: SimHardware) -> VirtualRig {
        let app_cfg = AppConfig::new(cfg.serial);
        let mut app = App::new(app_cfg, board_store());
        app.set_boot_report(BootReport {
            cause: ResetCause::PowerOn,
            message: Default::default(),
        });
        let mut rig = VirtualRig {
            app,
            hw,
            serial: cfg.serial,
            cfg,
            now_us: 0,
            // polled as the board polls it
            tick_us: app_cfg.poll_period_us as u64,
            tasks: Liveness::new(BOARD_TASKS, 0),
            stalled: [false; BOARD_TASKS.len()],
            next_feed_us: FEED_PERIOD_MS as u64 * 1000,
            last_pet_us: 0,
            starving: false,
            noinit: reset::EMPTY,
            resets: 0,
            tc_reads_seen: 0,
            events: Vec::new(),
            decoder: Decoder::new(),
            last_host_us: None,
            faults_seen: 0,
            host_lease_ms: limits::HOST_LEASE_MS,
        };
        rig.app.poll(&mut rig.hw, 0);
        rig
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

    /// The configuration the rig was built from.
    pub fn config(&self) -> &VirtualRigConfig {
        &self.cfg
    }

    /// The load knob turned to `load_n` while the rig stays powered (a load is a weight on the
    /// arm): the firmware, its run numbers, its stored run and its clock go on. Refuses a load the
    /// rig cannot take.
    pub fn turn_load_knob(&mut self, load_n: f64) -> Result<(), RigError> {
        self.hw.set_load(load_n)?;
        self.cfg.load_n = load_n;
        self.event(format!("load knob turned to {load_n:.4} N"));
        Ok(())
    }

    /// Cuts the power and turns it on again: the firmware restarts with empty RAM (an operation the
    /// flash was doing is torn, the reset record is gone), the flash keeps what it holds, the
    /// physical rig stays where it is (the magnet lets go, the heater stops). The application
    /// recovers the last run from flash on its first poll, as the board does, and reports a
    /// power-on reset.
    pub fn power_cycle(&mut self) {
        self.noinit = reset::EMPTY;
        self.reset(ResetFlags {
            power_on: true,
            brownout: true,
            pin: true,
            ..Default::default()
        });
    }

    /// Sets the firmware's host lease, ms of device time (kept across resets). A rig served faster
    /// than real time stretches it by its speed ([`lease_for_speed`]), so that a host talking in real
    /// time keeps the lease it would keep with the real rig.
    pub fn set_host_lease_ms(&mut self, ms: u32) {
        self.host_lease_ms = ms;
        self.app.set_host_lease_ms(ms);
    }

    /// Resets of the MCU since power-on (watchdog, panic, CPU fault).
    pub fn resets(&self) -> u32 {
        self.resets
    }

    /// Bytes from the host.
    pub fn input(&mut self, bytes: &[u8]) {
        if self.stalled[Task::App.index()] {
            // The core is busy elsewhere: nobody reads the link (the bytes are lost, as a USB
            // FIFO would drop them).
            return;
        }
        self.journal_commands(bytes);
        let now = self.now_us;
        self.guarded(|app, hw| app.on_bytes(hw, bytes, now));
        self.deliberate();
    }

    /// What the board's application task does when the self-test asks for a deliberate panic or
    /// stall (after the command's `Ack`): the panic comes from the next hardware call, the stall
    /// is the thermocouple task's, which the watchdog must catch.
    fn deliberate(&mut self) {
        match self.app.take_deliberate() {
            Some(Deliberate::Panic) => self.inject_panic(tribo_wire::DELIBERATE_PANIC),
            Some(Deliberate::Stall) => self.stall_task(Task::Thermocouple),
            None => {}
        }
    }

    /// Makes an analog channel of the converter misbehave (or heals it with `None`); the fault
    /// is in the front end, so it outlasts the MCU's resets.
    pub fn set_channel_fault(&mut self, channel: usize, fault: Option<ChannelFault>) {
        self.hw.set_channel_fault(channel, fault);
    }

    /// Bytes for the host produced so far.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.hw.out)
    }

    /// What the rig did since the last call (host commands that change its state, faults,
    /// resets), for its console.
    pub fn take_events(&mut self) -> Vec<RigEvent> {
        std::mem::take(&mut self.events)
    }

    fn event(&mut self, what: String) {
        self.events.push(RigEvent {
            t_us: self.now_us,
            what,
        });
    }

    /// Runs the simulation and the application up to `t_us`, polling the application every
    /// millisecond of device time (as the board's application task does), with the board's
    /// watchdog task every 50 ms.
    pub fn advance_to(&mut self, t_us: u64) {
        while self.now_us < t_us {
            let next = (self.now_us + self.tick_us).min(t_us);
            self.hw.advance(next);
            self.now_us = next;
            self.board_tick();
        }
    }

    /// One tick of the board's tasks: check-ins, the application, the watchdog task, the IWDG.
    fn board_tick(&mut self) {
        let now = self.now_us;
        let ms = (now / 1000) as u32;
        let hog = self.stalled[Task::App.index()];
        if !hog {
            // The executor runs: the converter task checks in as it runs.
            let reads = self.hw.tc_reads();
            if reads != self.tc_reads_seen {
                self.tc_reads_seen = reads;
                self.tasks.check_in(watchdog::task::THERMOCOUPLE, ms);
            }
            self.tasks.check_in(watchdog::task::APP, ms);
            self.guarded(|app, hw| app.poll(hw, now));
            self.note_faults();
            if now >= self.next_feed_us {
                self.next_feed_us = now + FEED_PERIOD_MS as u64 * 1000;
                self.watchdog_task(ms);
            }
        }
        if now.saturating_sub(self.last_pet_us) > limits::WATCHDOG_TIMEOUT_MS as u64 * 1000 {
            self.reset(ResetFlags {
                independent_watchdog: true,
                pin: true,
                ..Default::default()
            });
        }
    }

    /// The board's watchdog task: feed while every task checks in; else safe state, the note, and
    /// no more feeding.
    fn watchdog_task(&mut self, ms: u32) {
        if self.starving {
            return;
        }
        match self.tasks.verdict(ms) {
            Ok(()) => self.last_pet_us = self.now_us,
            Err(stuck) => {
                self.hw.drive_safe();
                self.noinit = reset::encode(ResetCause::Watchdog, stuck.message().as_bytes());
                self.starving = true;
                self.event(format!(
                    "{}: safe state applied, watchdog no longer fed",
                    stuck.message()
                ));
            }
        }
    }

    /// Runs application code as the board does: a panic in it goes to the panic handler, which
    /// applies the safe state, keeps the message and resets.
    fn guarded(&mut self, f: impl FnOnce(&mut App<'static>, &mut SimHardware)) {
        let (app, hw) = (&mut self.app, &mut self.hw);
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(app, hw)));
        if let Err(payload) = r {
            let msg = payload
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| payload.downcast_ref::<&str>().copied())
                .unwrap_or("(no message)");
            let text = format!("panicked: {msg}");
            self.hw.drive_safe();
            self.noinit = reset::encode(ResetCause::Panic, text.as_bytes());
            self.event(format!("{text}: safe state applied, resetting"));
            self.reset(ResetFlags {
                software: true,
                pin: true,
                ..Default::default()
            });
        }
    }

    /// A reset of the MCU: a new application, outputs at their reset state, the boot report from
    /// the reset flags and the record kept in "no-init RAM".
    fn reset(&mut self, flags: ResetFlags) {
        // A reset aborts a flash operation in progress just as a power cut does.
        self.hw.flash.power_cut();
        self.hw.reset_mcu();
        let noinit = self.noinit;
        let report = reset::boot_report(flags, || noinit);
        self.noinit = reset::EMPTY;
        self.event(format!(
            "reset ({:?}{}{})",
            report.cause,
            if report.message.is_empty() { "" } else { ": " },
            report.message
        ));
        self.app = new_app(self.serial);
        self.app.set_host_lease_ms(self.host_lease_ms);
        self.app.set_boot_report(report);
        self.stalled = [false; BOARD_TASKS.len()];
        self.starving = false;
        let ms = (self.now_us / 1000) as u32;
        self.tasks = Liveness::new(BOARD_TASKS, ms);
        self.last_pet_us = self.now_us;
        self.next_feed_us = self.now_us + FEED_PERIOD_MS as u64 * 1000;
        self.faults_seen = 0;
        self.decoder.reset();
        self.resets += 1;
        let now = self.now_us;
        self.app.poll(&mut self.hw, now);
    }

    /// Logs host commands that change the rig's state.
    fn journal_commands(&mut self, bytes: &[u8]) {
        let mut seen = Vec::new();
        self.decoder.feed(bytes, |f| {
            if let Ok(Frame { msg, .. }) = f {
                seen.push(msg);
            }
        });
        for msg in seen {
            if tribo_firmware::lease::renews(&msg) {
                self.last_host_us = Some(self.now_us);
            }
            let what = match msg {
                HostMsg::Hello { .. } => "host: hello".to_string(),
                HostMsg::Configure(c) => format!("host: configure (load {} N)", c.rig.load_n),
                HostMsg::SetHeater(sp) => format!(
                    "host: heater to {:.1} °C at {} °C/min",
                    sp.setpoint_c, sp.ramp_c_per_min
                ),
                HostMsg::HeaterOff => "host: heater off".into(),
                HostMsg::Arm => "host: arm".into(),
                HostMsg::Disarm => "host: disarm".into(),
                HostMsg::Release => "host: release".into(),
                HostMsg::Abort => "host: abort".into(),
                HostMsg::Safe => "host: safe (heater and magnet off)".into(),
                HostMsg::SelfTest(check) => format!("host: self-test {check:?}"),
                HostMsg::RunFloor { run_id } => format!("host: holds runs up to {run_id}"),
                HostMsg::Status
                | HostMsg::Heartbeat
                | HostMsg::Pull { .. }
                | HostMsg::PullBlocks { .. } => continue,
            };
            self.event(what);
        }
    }

    /// Logs the faults the application handled since the last look.
    fn note_faults(&mut self) {
        if self.app.faults() == self.faults_seen {
            return;
        }
        self.faults_seen = self.app.faults();
        if let Some(f) = self.app.last_fault() {
            let silence = self
                .last_host_us
                .map(|t| {
                    format!(
                        " (last host command {} ms before)",
                        (self.now_us - t) / 1000
                    )
                })
                .unwrap_or_default();
            self.event(format!(
                "FAULT {:?} at {:.1} °C: outputs safe{silence}",
                f.reason, f.temp_c
            ));
        }
    }

    /// Holds the user button down (true) or lets it go.
    pub fn set_button(&mut self, pressed: bool) {
        self.hw.button = pressed;
    }

    /// Makes the thermocouple or its converter misbehave (or heals it with `None`).
    pub fn set_thermocouple_fault(&mut self, fault: Option<ConverterFault>) {
        self.hw.tc_fault = fault;
    }

    /// Makes an output read back wrong (or heals it with `None`).
    pub fn set_output_fault(&mut self, fault: Option<OutputFault>) {
        self.hw.output_fault = fault;
    }

    /// Makes the HSE run `ppm` off its nominal (0: as built): the clock check's timer ticks that
    /// much fast (positive) or slow.
    pub fn set_hse_error_ppm(&mut self, ppm: f64) {
        self.hw.hse_error_ppm = if ppm.is_finite() { ppm } else { 0.0 };
    }

    /// Wires two converter inputs to each other's signal (or back as built with `None`).
    pub fn swap_channels(&mut self, pair: Option<(usize, usize)>) {
        self.hw.swap_channels(pair);
    }

    /// Makes the heater's power stage misbehave.
    pub fn set_heater_stage(&mut self, stage: HeaterStage) {
        self.hw.heater_stage = stage;
    }

    /// Stalls a task of the board's firmware (see [`Task`]) until the next reset.
    pub fn stall_task(&mut self, task: Task) {
        self.stalled[task.index()] = true;
        if task == Task::Thermocouple {
            self.hw.tc_task_stalled = true;
        }
    }

    /// The next step of the application panics inside a hardware call, with this message.
    pub fn inject_panic(&mut self, msg: &str) {
        self.hw.panic_next = Some(msg.to_string());
    }

    /// A CPU fault (HardFault) now: the board's handler applies the safe state, keeps the fault
    /// registers and resets.
    pub fn inject_cpu_fault(&mut self) {
        self.hw.drive_safe();
        // What a bus fault on a read of unmapped memory would leave: precise data bus error,
        // escalated to HardFault.
        let m = reset::cpu_fault_message(
            0x0800_4a1c,
            0x0800_3f7b,
            0x0000_8200,
            0x4000_0000,
            0xa000_0000,
        );
        self.noinit = reset::encode(ResetCause::CpuFault, m.as_bytes());
        self.event("HardFault: safe state applied, resetting".into());
        self.reset(ResetFlags {
            software: true,
            pin: true,
            ..Default::default()
        });
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

/// The host lease, ms of device time, of a rig served at `speed` × real time: the firmware's lease
/// in wall-clock time (device time runs `speed` times faster; never shorter than the firmware's).
pub fn lease_for_speed(speed: f64) -> u32 {
    let ms = limits::HOST_LEASE_MS as f64 * speed.max(1.0);
    if ms.is_finite() && ms < u32::MAX as f64 {
        ms as u32
    } else {
        u32::MAX
    }
}

/// Prints the rig's events on standard output if `opts` asks for it (else drops them).
pub fn print_events(rig: &mut VirtualRig, opts: &ServeOptions) {
    let events = rig.take_events();
    if opts.log_events && !events.is_empty() {
        let mut out = io::stdout().lock();
        for e in events {
            // The console is best effort: a closed stdout does not stop the rig.
            let _ = writeln!(out, "{e}");
        }
        let _ = out.flush();
    }
}

// The rig can be moved to a serving thread.
const _: fn() = || {
    fn send<T: Send>() {}
    send::<VirtualRig>();
};
