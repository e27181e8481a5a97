//! The fault-injection table of the fail-safe rig: one row per fault, each row a test on
//! the simulated rig (the firmware's application with the board's watchdog, panic and HardFault
//! handling emulated around it, `tribo_rig::VirtualRig`).
//!
//! Every row starts from a rig a live host is using (heating, and for most rows the magnet holding
//! the pin), injects its fault at `t0`, and asserts:
//! * the outputs the fault concerns are safe (heater off, magnet off) within the row's stated time,
//!   in device time, and stay safe;
//! * the host gets a frame with the right reason: a `Fault` frame, or after a reset the `Boot`
//!   report answered to its next `Hello`.
//!
//! The host-process rows (a `tribo` killed with SIGKILL, `tribo run … | true`) are in
//! `host/tests/failsafe_process.rs`: they need the `tribo` binary and a rig process of their own.

use tribo_firmware::hal::MagnetDrive;
use tribo_firmware::watchdog::{BOARD_TASKS, FEED_PERIOD_MS};
use tribo_rig::{ConverterFault, HeaterStage, Task, VirtualRig, VirtualRigConfig};
use tribo_wire::frame::{decode_one, encode_vec};
use tribo_wire::*;

/// A host using the rig in-process, and everything the rig said.
struct Bench {
    rig: VirtualRig,
    seq: u32,
    msgs: Vec<(u64, DeviceMsg)>,
    /// Whether the host sends heartbeats while time passes.
    alive: bool,
    next_beat_us: u64,
}

impl Bench {
    fn new() -> Bench {
        let cfg = VirtualRigConfig {
            seed: 12,
            ..Default::default()
        };
        Bench {
            rig: VirtualRig::new(cfg).unwrap(),
            seq: 0,
            msgs: Vec::new(),
            alive: true,
            next_beat_us: 0,
        }
    }

    fn collect(&mut self) {
        let t = self.rig.now_us();
        for f in self.rig.take_output().split_inclusive(|&b| b == 0) {
            let f = decode_one::<DeviceMsg>(f).expect("the rig sends valid frames");
            self.msgs.push((t, f.msg));
        }
    }

    fn send(&mut self, msg: HostMsg) -> u32 {
        self.seq += 1;
        self.rig.input(&encode_vec(self.seq, &msg).unwrap());
        self.collect();
        self.seq
    }

    fn command(&mut self, msg: HostMsg) -> Result<(), ErrorCode> {
        let seq = self.send(msg);
        self.msgs
            .iter()
            .rev()
            .find_map(|(_, m)| match m {
                DeviceMsg::Ack { seq: s } if *s == seq => Some(Ok(())),
                DeviceMsg::Error(DeviceError {
                    code,
                    about_seq: Some(s),
                }) if *s == seq => Some(Err(*code)),
                _ => None,
            })
            .expect("answered")
    }

    /// One millisecond of device time (with a heartbeat each second if the host is alive).
    fn tick(&mut self) {
        let t = self.rig.now_us() + 1000;
        self.rig.advance_to(t);
        self.collect();
        if self.alive && t >= self.next_beat_us {
            self.next_beat_us = t + limits::HEARTBEAT_MS as u64 * 1000;
            self.send(HostMsg::Heartbeat);
        }
    }

    fn run_ms(&mut self, ms: u64) {
        for _ in 0..ms {
            self.tick();
        }
    }

    /// Heats towards `setpoint_c` for `secs` and, if `arm`, arms (the magnet holds the pin).
    fn heating(&mut self, setpoint_c: f32, secs: u64, arm: bool) {
        let mut c = Configure::real_rig(0.3);
        c.max_duration_s = 8.0;
        assert_eq!(self.command(HostMsg::Configure(c)), Ok(()));
        let sp = HeaterSetpoint {
            setpoint_c,
            ramp_c_per_min: 30.0,
        };
        assert_eq!(self.command(HostMsg::SetHeater(sp)), Ok(()));
        self.run_ms(secs * 1000);
        if arm {
            assert_eq!(self.command(HostMsg::Arm), Ok(()));
            self.run_ms(100);
            assert!(matches!(
                self.rig.hardware().magnet(),
                MagnetDrive::Hold { .. }
            ));
        }
        assert!(self.rig.hardware().heater_duty() > 0.0, "heating");
        assert!(self.faults().is_empty(), "{:?}", self.faults());
    }

    fn faults(&self) -> Vec<FaultReason> {
        self.msgs
            .iter()
            .filter_map(|(_, m)| match m {
                DeviceMsg::Fault(f) => Some(f.reason),
                _ => None,
            })
            .collect()
    }

    fn boot(&self) -> Option<BootReport> {
        self.msgs.iter().find_map(|(_, m)| match m {
            DeviceMsg::Boot(b) => Some(b.clone()),
            _ => None,
        })
    }
}

/// Which outputs a fault must make safe.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Outputs {
    /// The heater (the magnet, not at fault, may hold on).
    Heater,
    /// The magnet.
    Magnet,
    /// Heater and magnet (the application's safe state: the ECR source, harmless, stays).
    HeaterAndMagnet,
    /// The board's safe state: heater, magnet and ECR source off; after the reset that follows,
    /// heater and magnet stay off (the restarted application sets its 2 mV ECR source again).
    Board,
}

/// What the host must be told.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Told {
    Fault(FaultReason),
    /// After a reset, the boot report to the next hello: its cause, and text its message contains.
    Boot(ResetCause, &'static str),
}

/// One row of the table (its injection is given beside it in [`rows!`]).
struct Row {
    /// The state the fault strikes in.
    setup: fn(&mut Bench),
    /// The host stops talking at the injection (the host-silence row).
    host_silent: bool,
    outputs: Outputs,
    /// Longest time from the injection to safe outputs, ms (device time).
    safe_within_ms: u64,
    told: Told,
    /// Longest time from the injection to the frame (a `Fault`), or to the reset (a `Boot`), ms.
    told_within_ms: u64,
}

fn heating_armed(b: &mut Bench) {
    b.heating(50.0, 20, true);
}

fn heating_only(b: &mut Bench) {
    b.heating(50.0, 20, false);
}

fn heating_from_cold(b: &mut Bench) {
    let mut c = Configure::real_rig(0.3);
    c.max_duration_s = 8.0;
    assert_eq!(b.command(HostMsg::Configure(c)), Ok(()));
    let sp = HeaterSetpoint {
        setpoint_c: 60.0,
        ramp_c_per_min: 30.0,
    };
    assert_eq!(b.command(HostMsg::SetHeater(sp)), Ok(()));
    b.run_ms(300);
    assert!(b.rig.hardware().heater_duty() > 0.0);
}

fn at_setpoint(b: &mut Bench) {
    b.heating(40.0, 120, false);
    let t = b.rig.hardware().plate_temp_c();
    assert!((t - 40.0).abs() < 0.5, "at setpoint: {t}");
}

fn tc(f: ConverterFault) -> impl Fn(&mut Bench) {
    move |b: &mut Bench| b.rig.set_thermocouple_fault(Some(f))
}

/// The slowest reaction of the converter checks: one read at most 100 ms away, then the fault after
/// `TC_BAD_READS` reads.
const TC_SAFE_MS: u64 = 100;
const TC_FAULT_MS: u64 = 100 * limits::TC_BAD_READS as u64;

/// Runs a row: setup, inject at t0, then up to `told_within_ms` + 1 s more, checking the outputs
/// every millisecond. Returns (ms to safe, ms to told).
fn run_row(name: &str, row: &Row, inject: &dyn Fn(&mut Bench)) -> (u64, u64) {
    let mut b = Bench::new();
    (row.setup)(&mut b);
    let resets = b.rig.resets();
    let before = b.msgs.len();
    let t0 = b.rig.now_us();
    if row.host_silent {
        b.alive = false;
    }
    inject(&mut b);
    b.collect();
    let safe = |b: &mut Bench| {
        let reset = b.rig.resets() > resets;
        let hw = b.rig.hardware();
        let heater = hw.heater_duty() == 0.0;
        let magnet = hw.magnet() == MagnetDrive::Off;
        match row.outputs {
            Outputs::Heater => heater,
            Outputs::Magnet => magnet,
            Outputs::HeaterAndMagnet => heater && magnet,
            Outputs::Board => heater && magnet && (hw.ecr_source_v() == 0.0 || reset),
        }
    };
    let mut safe_at = None;
    let mut told_at = None;
    let horizon = t0 + (row.told_within_ms + 1000) * 1000;
    loop {
        let now = b.rig.now_us();
        let is_safe = safe(&mut b);
        match (safe_at, is_safe) {
            (None, true) => safe_at = Some(now),
            (Some(_), false) => panic!("{name}: outputs on again at {} ms", (now - t0) / 1000),
            _ => {}
        }
        if told_at.is_none() {
            told_at = match row.told {
                Told::Fault(r) => b.msgs[before..]
                    .iter()
                    .find(|(_, m)| matches!(m, DeviceMsg::Fault(f) if f.reason == r))
                    .map(|(t, _)| *t),
                Told::Boot(..) => (b.rig.resets() > resets).then_some(now),
            };
        }
        if now >= horizon {
            break;
        }
        b.tick();
    }
    let safe_ms = (safe_at.unwrap_or_else(|| panic!("{name}: never safe")) - t0) / 1000;
    let told_ms =
        (told_at.unwrap_or_else(|| panic!("{name}: the host was never told")) - t0) / 1000;
    assert!(
        safe_ms <= row.safe_within_ms,
        "{name}: safe after {safe_ms} ms, stated {} ms",
        row.safe_within_ms
    );
    assert!(
        told_ms <= row.told_within_ms,
        "{name}: told after {told_ms} ms, stated {} ms",
        row.told_within_ms
    );
    match row.told {
        Told::Fault(r) => {
            // Told once, and nothing else went wrong on the way.
            let faults = b.faults();
            assert_eq!(
                faults.iter().filter(|f| **f == r).count(),
                1,
                "{name}: {faults:?}"
            );
        }
        Told::Boot(cause, text) => {
            // The host says hello after the reset: the boot report answers it, once.
            b.alive = true;
            b.send(HostMsg::Hello {
                protocol: PROTOCOL_VERSION,
            });
            let boot = b.boot().unwrap_or_else(|| panic!("{name}: no boot report"));
            assert_eq!(boot.cause, cause, "{name}");
            assert!(
                boot.message.contains(text),
                "{name}: {:?} lacks {text:?}",
                boot.message
            );
            let n = b.msgs.len();
            b.send(HostMsg::Hello {
                protocol: PROTOCOL_VERSION,
            });
            assert!(!b.msgs[n..]
                .iter()
                .any(|(_, m)| matches!(m, DeviceMsg::Boot(_))));
            let status = b.rig.app().status();
            assert_eq!(status.reset_cause, cause);
            assert_eq!(
                status.heater_setpoint_c, None,
                "nothing heats after a reset"
            );
            assert!(!status.magnet_on);
        }
    }
    eprintln!("{name}: safe after {safe_ms} ms, told after {told_ms} ms");
    (safe_ms, told_ms)
}

macro_rules! rows {
    ($($name:ident: $row:expr, inject: $inject:expr;)*) => {
        $(
            #[test]
            fn $name() {
                let row: Row = $row;
                run_row(stringify!($name), &row, &$inject);
            }
        )*
    };
}

/// No setup, or no injection.
fn none(_: &mut Bench) {}

fn row(
    setup: fn(&mut Bench),
    outputs: Outputs,
    safe_within_ms: u64,
    told: Told,
    told_within_ms: u64,
) -> Row {
    Row {
        setup,
        host_silent: false,
        outputs,
        safe_within_ms,
        told,
        told_within_ms,
    }
}

const TC_TASK_SILENCE_MS: u64 =
    BOARD_TASKS[tribo_firmware::watchdog::task::THERMOCOUPLE].max_silence_ms as u64;

rows! {
    // ---- the firmware itself fails ----
    panic_inside_a_task:
        // The injected panic fires in the next heater step (at most 100 ms on): safe and reset there.
        row(heating_armed, Outputs::Board, 100, Told::Boot(ResetCause::Panic, "index out of bounds"), 100),
        inject: |b: &mut Bench| b.rig.inject_panic("index out of bounds: the len is 4 but the index is 9");
    hard_fault:
        row(heating_armed, Outputs::Board, 0, Told::Boot(ResetCause::CpuFault, "HardFault at pc=0x08004a1c"), 0),
        inject: |b: &mut Bench| b.rig.inject_cpu_fault();
    stuck_task_waiting_forever_is_caught_by_the_watchdog_task:
        // Safe when the watchdog task sees the silence; reset by the IWDG once it starves.
        row(heating_armed, Outputs::Board, TC_TASK_SILENCE_MS + FEED_PERIOD_MS as u64 + 100,
            Told::Boot(ResetCause::Watchdog, "task thermocouple silent"),
            TC_TASK_SILENCE_MS + 100 + FEED_PERIOD_MS as u64 + limits::WATCHDOG_TIMEOUT_MS as u64 + 1),
        inject: |b: &mut Bench| b.rig.stall_task(Task::Thermocouple);
    stuck_task_hogging_the_core_is_reset_by_the_hardware_watchdog:
        // Nothing runs: the outputs hold until the IWDG resets the chip into its safe reset state.
        row(heating_armed, Outputs::Board, FEED_PERIOD_MS as u64 + limits::WATCHDOG_TIMEOUT_MS as u64 + 1,
            Told::Boot(ResetCause::Watchdog, ""),
            FEED_PERIOD_MS as u64 + limits::WATCHDOG_TIMEOUT_MS as u64 + 1),
        inject: |b: &mut Bench| b.rig.stall_task(Task::App);
    // ---- the host goes away ----
    host_silent_while_heating_and_holding:
        Row { host_silent: true, ..row(heating_armed, Outputs::HeaterAndMagnet, limits::HOST_LEASE_MS as u64 + 1,
            Told::Fault(FaultReason::LeaseExpired), limits::HOST_LEASE_MS as u64 + 1) },
        inject: none;
    // ---- the thermocouple and its converter ----
    thermocouple_open:
        row(heating_armed, Outputs::Heater, TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::OpenThermocouple)), TC_FAULT_MS),
        inject: tc(ConverterFault::Open);
    thermocouple_shorted_to_a_supply:
        row(heating_armed, Outputs::Heater, TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::ShortedThermocouple)), TC_FAULT_MS),
        inject: tc(ConverterFault::Shorted);
    converter_reads_all_zero:
        row(heating_armed, Outputs::Heater, TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::BadConverterData)), TC_FAULT_MS),
        inject: tc(ConverterFault::AllZero);
    converter_reads_all_ones:
        row(heating_armed, Outputs::Heater, TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::BadConverterData)), TC_FAULT_MS),
        inject: tc(ConverterFault::AllOnes);
    converter_reset_loses_its_configuration:
        row(heating_armed, Outputs::Heater, TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::BadConverterData)), TC_FAULT_MS),
        inject: tc(ConverterFault::Reset);
    cold_junction_implausible:
        row(heating_armed, Outputs::Heater, TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::ColdJunction)), TC_FAULT_MS),
        inject: tc(ConverterFault::ColdJunction(71.0));
    converter_stale:
        // The last reading ages past its limit, then the bad reads count.
        row(heating_armed, Outputs::Heater, limits::TC_MAX_AGE_MS as u64 + TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::NoReading)),
            limits::TC_MAX_AGE_MS as u64 + TC_FAULT_MS),
        inject: tc(ConverterFault::Stale);
    // ---- the heater ----
    heater_that_does_not_heat:
        // The ramp (30 °C/min) leaves the plate behind by the band, then the watch period runs out.
        row(heating_from_cold, Outputs::Heater,
            (limits::HEATER_BAND_C / 0.5 * 1000.0 + limits::HEATER_WATCH_PERIOD_S * 1000.0) as u64,
            Told::Fault(FaultReason::Heater(HeaterFault::HeatingFailed)),
            (limits::HEATER_BAND_C / 0.5 * 1000.0 + limits::HEATER_WATCH_PERIOD_S * 1000.0) as u64),
        inject: |b: &mut Bench| b.rig.set_heater_stage(HeaterStage::Dead);
    heater_stuck_on_at_setpoint:
        // At 40 °C, the switch shorts: the plate runs away at ~1.3 °C/s; the regulator asks for no
        // heat once above the setpoint, the runaway watch faults past the band plus its rise.
        row(at_setpoint, Outputs::Heater, 12_000,
            Told::Fault(FaultReason::Heater(HeaterFault::Runaway)), 12_000),
        inject: |b: &mut Bench| b.rig.set_heater_stage(HeaterStage::StuckOn);
    heater_stuck_on_while_off:
        // The firmware commands the heater off (it was); the fault says the switch is stuck. A
        // shorted switch keeps heating whatever the firmware does: the thermal fuse of the README's
        // Safety section is what stops that.
        row(none, Outputs::Heater, 0,
            Told::Fault(FaultReason::Heater(HeaterFault::Runaway)), 5_000),
        inject: |b: &mut Bench| b.rig.set_heater_stage(HeaterStage::StuckOn);
    plate_over_the_cut_off:
        // Something else heats the plate past 110 °C (the runaway watch is not asked: the plate is
        // within its rise when it crosses): the cut-off.
        row(heating_armed, Outputs::Heater, TC_SAFE_MS,
            Told::Fault(FaultReason::Heater(HeaterFault::OverTemperature)), TC_SAFE_MS),
        inject: |b: &mut Bench| b.rig.hardware().set_plate_temp_c(limits::HEATER_CUTOFF_C as f64 + 0.5);
    // ---- the magnet ----
    magnet_held_too_long:
        row(heating_only, Outputs::Magnet, limits::MAGNET_MAX_HOLD_MS as u64 + 1,
            Told::Fault(FaultReason::MagnetHoldTime), limits::MAGNET_MAX_HOLD_MS as u64 + 1),
        inject: |b: &mut Bench| assert_eq!(b.command(HostMsg::Arm), Ok(()));
}
