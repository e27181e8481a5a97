//! The fail-safe rig's reports (protocol v2): faults it handled by itself, and why it last reset.

use super::*;

wire_type! {
    /// Why the rig drove outputs to their safe state by itself.
    #[derive(Copy, Eq)]
    pub enum FaultReason {
        /// The heater was cut off (thermocouple, temperature or runaway fault).
        Heater(HeaterFault),
        /// No command or heartbeat from the host for longer than [`limits::HOST_LEASE_MS`] while
        /// heating or holding the magnet.
        LeaseExpired,
        /// The electromagnet held longer than its limit and was switched off.
        MagnetHoldTime,
        /// Stand-alone mode ran out of its time limit (no button press for
        /// [`limits::STANDALONE_HEAT_MS`]).
        StandAloneExpired,
    }
}

wire_type! {
    /// A fault the rig handled by itself: the outputs concerned are already safe when this is sent.
    #[derive(Copy)]
    pub struct FaultReport {
        pub reason: FaultReason,
        /// Device uptime when the fault was detected.
        pub uptime_ms: u64,
        /// Temperature at the time (NaN when unknown).
        pub temp_c: f32,
    }
}

wire_type! {
    /// Why the MCU last reset.
    #[derive(Copy, Eq)]
    pub enum ResetCause {
        PowerOn,
        /// The reset pin (NRST button, debugger).
        Pin,
        /// A software reset requested by the firmware.
        Software,
        /// The independent watchdog was not fed in time: a task was stuck.
        Watchdog,
        /// A panic (message in [`BootReport::message`]).
        Panic,
        /// A HardFault or other CPU fault (registers in [`BootReport::message`]).
        CpuFault,
        Brownout,
        Unknown,
    }
}

impl ResetCause {
    /// Every cause, in the order of their codes in the reset record.
    pub const ALL: [ResetCause; 8] = [
        ResetCause::PowerOn,
        ResetCause::Pin,
        ResetCause::Software,
        ResetCause::Watchdog,
        ResetCause::Panic,
        ResetCause::CpuFault,
        ResetCause::Brownout,
        ResetCause::Unknown,
    ];
}

/// Longest message a [`BootReport`] carries.
pub const BOOT_MESSAGE_LEN: usize = 120;

wire_type! {
    /// The reset cause and, after a panic or fault, what was kept of its message.
    pub struct BootReport {
        pub cause: ResetCause,
        pub message: heapless::String<BOOT_MESSAGE_LEN>,
    }
}
