//! `tribo status`: what the rig is doing, its last fault and why it last reset.

use crate::link::args::LinkArgs;
use crate::link::{
    explain_fault, firmware_version, heater_fault_text, reset_cause_text, state_name, uptime,
};
use crate::out::text as out;
use tribo_wire::{Control, Status};

/// Arguments of `tribo status`.
#[derive(clap::Args, Debug)]
#[command(
    after_long_help = "--json prints one JSON object: {\"port\", \"firmware\", \"serial\", \"status\": {…the rig's Status…}, \"boot_message\"}."
)]
pub struct Args {
    /// The rig to ask.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Print one JSON object (set by the global `--json`; its shape is in `after_long_help`).
    #[arg(skip)]
    pub json: bool,
}

/// The status as text, one `name  value` line each.
pub fn render(s: &Status, boot_message: Option<&str>) -> String {
    let mut t = String::new();
    let mut line = |k: &str, v: String| t.push_str(&format!("{k:<13}{v}\n"));
    line("state", state_name(s.state).to_string());
    let active = s.heater_setpoint_c.is_some() || s.magnet_on;
    line(
        "held by",
        match (active, s.control) {
            (_, Control::StandAlone) => "the technician at the rig (stand-alone mode)".into(),
            (false, _) => "nobody needs to: nothing heats or holds".into(),
            (true, Control::Host) => "a host (it renews its lease)".into(),
            (true, Control::None) => "nobody: heater and magnet are going off".into(),
        },
    );
    let plate = if s.temp_c.is_finite() {
        format!("{:.1} °C", s.temp_c)
    } else {
        "unknown".into()
    };
    line(
        "plate",
        match s.heater_setpoint_c {
            Some(sp) => format!(
                "{plate}, heating to {sp:.1} °C (duty {:.0} %)",
                s.heater_duty * 100.0
            ),
            None => format!("{plate}, heater off"),
        },
    );
    if let Some(f) = s.heater_fault {
        line("heater fault", heater_fault_text(f));
    }
    line("magnet", if s.magnet_on { "on" } else { "off" }.to_string());
    line(
        "last run",
        if s.run_id == 0 {
            "none since power-on".into()
        } else {
            format!("{}", s.run_id)
        },
    );
    line(
        "last fault",
        match &s.last_fault {
            Some(f) => format!("{} ({} since boot)", explain_fault(f), s.faults),
            None => "none since boot".into(),
        },
    );
    line(
        "last reset",
        match boot_message {
            Some(m) if !m.is_empty() => format!("{}: {m}", reset_cause_text(s.reset_cause)),
            _ => reset_cause_text(s.reset_cause).to_string(),
        },
    );
    line("uptime", uptime(s.uptime_ms));
    t
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (mut link, info) = args.link.connect()?;
    let s = link.status()?;
    let boot = link.boot_report().map(|b| b.message.as_str().to_owned());
    if args.json {
        crate::out::print_json(serde_json::json!({
            "port": link.name(),
            "firmware": firmware_version(&info),
            "serial": format!("{:016x}", info.serial),
            "status": s,
            "boot_message": boot,
        }))?;
        return Ok(());
    }
    let mut text = format!(
        "rig on {}: firmware {}, serial {:016x}\n",
        link.name(),
        firmware_version(&info),
        info.serial
    );
    text.push_str(&render(&s, boot.as_deref()));
    if boot.is_none() && s.reset_cause != tribo_wire::ResetCause::PowerOn {
        text.push_str(
            "             (the reset's message, if any, went to the first program that connected after it)\n",
        );
    }
    out(&text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_wire::{FaultReason, FaultReport, HeaterFault, ResetCause, RigState};

    fn status() -> Status {
        Status {
            state: RigState::Configured,
            run_id: 4,
            temp_c: 41.25,
            heater_setpoint_c: None,
            heater_duty: 0.0,
            heater_fault: None,
            magnet_on: false,
            log10_ecr_ohm: 7.0,
            ecr_range: 2,
            samples: 0,
            overruns: 0,
            uptime_ms: 3_723_400,
            last_fault: Some(FaultReport {
                reason: FaultReason::LeaseExpired,
                uptime_ms: 62_500,
                temp_c: 40.0,
            }),
            faults: 1,
            reset_cause: ResetCause::Watchdog,
            control: Control::None,
        }
    }

    #[test]
    fn the_status_says_what_is_on_the_last_fault_and_the_last_reset() {
        let t = render(
            &status(),
            Some("watchdog: task thermocouple silent for 312 ms"),
        );
        assert!(t.contains("plate        41.2 °C, heater off"), "{t}");
        assert!(t.contains("nothing heats or holds"), "{t}");
        assert!(
            t.contains("no word from the host")
                && t.contains("1 min 02.5 s")
                && t.contains("(1 since boot)"),
            "{t}"
        );
        assert!(
            t.contains("last reset   watchdog: a task of the firmware stopped (outputs were made safe): watchdog: task thermocouple silent for 312 ms"),
            "{t}"
        );
        assert!(t.contains("uptime       1 h 02 min 03.4 s"), "{t}");
        let mut s = status();
        s.heater_setpoint_c = Some(60.0);
        s.heater_duty = 0.5;
        s.heater_fault = Some(HeaterFault::Runaway);
        s.control = Control::Host;
        s.last_fault = None;
        let t = render(&s, None);
        assert!(t.contains("heating to 60.0 °C (duty 50 %)"), "{t}");
        assert!(t.contains("a host (it renews its lease)"), "{t}");
        assert!(t.contains("switch may be stuck on"), "{t}");
        assert!(t.contains("none since boot"), "{t}");
    }
}
