//! What the rig's codes mean, in words a technician can act on: error codes, heater and fail-safe
//! faults, reset causes, commands and versions.

use tribo_wire::limits;
use tribo_wire::{
    DeviceInfo, ErrorCode, FaultReason, FaultReport, Field, HeaterFault, HostMsg, Interlock,
    ResetCause, PROTOCOL_VERSION,
};

/// The configuration field a refusal names, with the range the rig accepts ([`limits`]): the one
/// wording of a range for the rig's own refusals and the host's checks before sending.
pub fn field_name(f: Field) -> String {
    let r = |r: &core::ops::RangeInclusive<f32>| format!("{}–{}", r.start(), r.end());
    match f {
        Field::Mass => format!("the mass ({} kg)", r(&limits::MASS_KG)),
        Field::Stiffness => format!("the stiffness ({} N/m)", r(&limits::STIFFNESS_N_PER_M)),
        Field::Load => format!("the load ({} N)", r(&limits::LOAD_N)),
        Field::SampleRate => format!(
            "the sample rate ({}–{} kHz)",
            limits::SAMPLE_RATE_HZ.start() / 1000,
            limits::SAMPLE_RATE_HZ.end() / 1000
        ),
        Field::Channels => "the channel set (displacement and velocity are required)".into(),
        Field::InitialAmplitude => format!(
            "the initial amplitude ({} µm – {} mm)",
            limits::INITIAL_AMPLITUDE_M.start() * 1e6,
            limits::INITIAL_AMPLITUDE_M.end() * 1e3
        ),
        Field::MaxDuration => format!("the maximum duration ({} s)", r(&limits::MAX_DURATION_S)),
        Field::Calibration => "a channel calibration".into(),
        Field::HeaterSetpoint => {
            format!("the heater setpoint ({} °C)", r(&limits::HEATER_SETPOINT_C))
        }
        Field::HeaterRamp => format!(
            "the heater ramp ({} °C/min)",
            r(&limits::HEATER_RAMP_C_PER_MIN)
        ),
        Field::RunId => "the run id".into(),
    }
}

/// A sentence for a rig's error code, ending with what to do.
pub fn explain(code: ErrorCode) -> String {
    match code {
        ErrorCode::Malformed => "the rig could not read a command (garbled on the line): check the cable and retry".into(),
        ErrorCode::ProtocolMismatch { device } => {
            tribo_wire::ProtocolMismatch { ours: PROTOCOL_VERSION, theirs: device }.to_string()
        }
        ErrorCode::OutOfRange(f) => format!("the rig refused {}: out of range; fix the value and retry", field_name(f)),
        ErrorCode::NotConfigured => "the rig has no configuration for this run: run `tribo run` again".into(),
        ErrorCode::Busy => "the rig is busy with a run: wait for it to end (or abort it from the program that \
                            started it), then fetch it with `tribo pull`"
            .into(),
        ErrorCode::Interlock(i) => match i {
            Interlock::NotArmed => "release refused: the pin is not held; arm again (rerun the command)".into(),
            Interlock::NotSampling => "release refused: the acquisition is not running yet; retry in a moment".into(),
            Interlock::HeaterUnhealthy => "release refused: the heater is faulted; check the thermocouple and the \
                                           plate, then run again"
                .into(),
            Interlock::MagnetOff => "release refused: the electromagnet is off; check its supply and arm again".into(),
            Interlock::HeaterOn => "refused while the heater heats: a deliberate reset is only tried with every \
                                    output off; turn the heater off (a plan without temperatures), then run the \
                                    self-test again"
                .into(),
        },
        ErrorCode::Heater(f) => format!("heater fault: {}", heater_fault_text(f)),
        ErrorCode::NoRun => "the rig holds no such run (it was power-cycled, or a newer run replaced it)".into(),
        ErrorCode::Overrun { lost_samples } => format!(
            "the rig lost {lost_samples} samples (acquisition overrun): the run cannot be trusted; repeat it at a \
             lower sample rate"
        ),
        ErrorCode::HoldTimeExceeded => "the electromagnet held the pin too long and was switched off to protect it: \
                                        release sooner after arming (or check the release wiring)"
            .into(),
        ErrorCode::MagnetCooling { wait_ms } => format!(
            "the electromagnet is cooling down after holding too long (at most {} s at a stretch, {:.0} % of \
             the time): arm again in {:.0} s",
            tribo_wire::limits::MAGNET_MAX_HOLD_MS / 1000,
            tribo_wire::limits::MAGNET_MAX_DUTY * 100.0,
            (wait_ms as f64 / 1000.0).ceil()
        ),
    }
}

/// What a heater fault means and what to do about it.
pub fn heater_fault_text(f: HeaterFault) -> String {
    use tribo_wire::limits as l;
    match f {
        HeaterFault::OverTemperature => format!(
            "the plate went over {} °C and the heater was cut off; let it cool, then check the heater's switch \
             and the setpoint",
            l::HEATER_CUTOFF_C
        ),
        HeaterFault::OpenThermocouple => {
            "the thermocouple is open (a wire or the connector is broken): check its wiring".into()
        }
        HeaterFault::ShortedThermocouple => {
            "the thermocouple touches a supply or ground (converter over/under voltage): check its wiring".into()
        }
        HeaterFault::NoReading => format!(
            "no thermocouple reading for {} reads in a row (the converter stopped answering): check the converter \
             board and its cable",
            l::TC_BAD_READS
        ),
        HeaterFault::BadConverterData => "the thermocouple converter answers garbage (all zeros or all ones, or it \
                                          lost its configuration): check its cable and supply, then power-cycle the \
                                          rig"
            .into(),
        HeaterFault::ThermocoupleRange => "the thermocouple reads out of range (reversed polarity, wrong type, or \
                                           damaged): check it"
            .into(),
        HeaterFault::ColdJunction => format!(
            "the converter's own (cold-junction) temperature is outside {}–{} °C: the converter board is damaged or \
             overheating",
            l::COLD_JUNCTION_C.start(),
            l::COLD_JUNCTION_C.end()
        ),
        HeaterFault::HeatingFailed => format!(
            "the plate did not warm as the heater drove it (less than {} °C in {} s): the heater does not heat, or \
             the thermocouple is off the plate; check both, then set the temperature again",
            l::HEATER_WATCH_GAIN_C,
            l::HEATER_WATCH_PERIOD_S
        ),
        HeaterFault::Runaway => format!(
            "the plate warmed by more than {} °C while no heat was asked for: the heater's switch may be stuck on; \
             switch the heater's supply off",
            l::HEATER_RUNAWAY_RISE_C
        ),
    }
}

/// A sentence for a fault the rig handled by itself (its outputs are already safe).
pub fn explain_fault(r: &FaultReport) -> String {
    let what = match r.reason {
        FaultReason::Heater(f) => format!("heater fault: {}", heater_fault_text(f)),
        FaultReason::LeaseExpired => format!(
            "no word from the host for {:.0} s while heating or holding the magnet: the rig switched both off \
             (the host program stopped, hung or lost its cable); set the temperature again to go on",
            tribo_wire::limits::HOST_LEASE_MS as f64 / 1000.0
        ),
        FaultReason::MagnetHoldTime => "the electromagnet held too long and was switched off to protect the \
                                        coil: release sooner after arming"
            .into(),
        FaultReason::StandAloneExpired => format!(
            "stand-alone mode ended ({} min without a button press): heater and magnet off",
            tribo_wire::limits::STANDALONE_HEAT_MS / 60_000
        ),
    };
    let temp = if r.temp_c.is_finite() {
        format!(", plate at {:.1} °C", r.temp_c)
    } else {
        String::new()
    };
    format!("{what} (at {} of rig uptime{temp})", uptime(r.uptime_ms))
}

/// A duration of rig uptime, as `1 h 02 min 03.4 s`.
pub fn uptime(ms: u64) -> String {
    let s = ms as f64 / 1000.0;
    let h = (s / 3600.0).floor();
    let m = ((s - h * 3600.0) / 60.0).floor();
    let sec = s - h * 3600.0 - m * 60.0;
    if h > 0.0 {
        format!("{h:.0} h {m:02.0} min {sec:04.1} s")
    } else if m > 0.0 {
        format!("{m:.0} min {sec:04.1} s")
    } else {
        format!("{sec:.1} s")
    }
}

/// What a reset cause means.
pub fn reset_cause_text(c: ResetCause) -> &'static str {
    match c {
        ResetCause::PowerOn => "power-on",
        ResetCause::Pin => "reset button or debugger",
        ResetCause::Software => "software reset",
        ResetCause::Watchdog => "watchdog: a task of the firmware stopped (outputs were made safe)",
        ResetCause::Panic => "firmware panic (outputs were made safe)",
        ResetCause::CpuFault => "CPU fault (outputs were made safe)",
        ResetCause::Brownout => "brown-out: the supply dipped",
        ResetCause::Unknown => "unknown",
    }
}

pub(super) fn command_name(m: &HostMsg) -> &'static str {
    match m {
        HostMsg::Hello { .. } => "hello",
        HostMsg::Configure(_) => "configure",
        HostMsg::SetHeater(_) => "set-heater",
        HostMsg::HeaterOff => "heater-off",
        HostMsg::Arm => "arm",
        HostMsg::Disarm => "disarm",
        HostMsg::Release => "release",
        HostMsg::Abort => "abort",
        HostMsg::Status => "status",
        HostMsg::Pull { .. } => "pull",
        HostMsg::Heartbeat => "heartbeat",
        HostMsg::Safe => "safe",
        HostMsg::PullBlocks { .. } => "pull-blocks",
        HostMsg::SelfTest(_) => "self-test",
        HostMsg::RunFloor { .. } => "run-floor",
    }
}

/// `major.minor.patch`.
pub fn firmware_version(info: &DeviceInfo) -> String {
    format!(
        "{}.{}.{}",
        info.firmware[0], info.firmware[1], info.firmware[2]
    )
}

/// The rig's state as a lab technician reads it.
pub fn state_name(s: tribo_wire::RigState) -> &'static str {
    match s {
        tribo_wire::RigState::Idle => "idle (not configured)",
        tribo_wire::RigState::Configured => "configured",
        tribo_wire::RigState::Armed => "armed (the magnet holds the pin)",
        tribo_wire::RigState::Running => "running a run",
        tribo_wire::RigState::Finished => "run finished",
        tribo_wire::RigState::Fault => "FAULT (heater cut off)",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The ranges a refusal quotes are the rig's own limits, written the way a person reads them.
    #[test]
    fn refusals_quote_the_rigs_limits() {
        assert_eq!(field_name(Field::Load), "the load (0–0.7 N)");
        assert_eq!(field_name(Field::SampleRate), "the sample rate (1–20 kHz)");
        assert_eq!(
            field_name(Field::HeaterSetpoint),
            "the heater setpoint (15–100 °C)"
        );
        assert_eq!(
            field_name(Field::MaxDuration),
            "the maximum duration (0.1–60 s)"
        );
        assert_eq!(
            field_name(Field::InitialAmplitude),
            "the initial amplitude (1 µm – 1 mm)"
        );
        assert_eq!(
            field_name(Field::HeaterRamp),
            "the heater ramp (0.1–30 °C/min)"
        );
    }
}
