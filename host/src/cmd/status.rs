//! `tribo status`: what the rig is doing, its last fault and why it last reset.

use super::run::{out, LinkArgs};
use crate::link::{explain_fault, firmware_version, heater_fault_text, reset_cause_text, uptime};
use tribo_wire::{Control, RigState, Status};

/// Arguments of `tribo status`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub link: LinkArgs,
}

/// The rig's state as a lab technician reads it.
pub fn state_name(s: RigState) -> &'static str {
    match s {
        RigState::Idle => "idle (not configured)",
        RigState::Configured => "configured",
        RigState::Armed => "armed (the magnet holds the pin)",
        RigState::Running => "running a run",
        RigState::Finished => "run finished",
        RigState::Fault => "FAULT (heater cut off)",
    }
}

/// The status as text, one `name  value` line each.
pub fn render(s: &Status, boot_message: Option<&str>) -> String {
    let mut t = String::new();
    let mut line = |k: &str, v: String| t.push_str(&format!("{k:<13}{v}\n"));
    line("state", state_name(s.state).to_string());
    line(
        "held by",
        match s.control {
            Control::Host => "a host (its lease is renewed)".into(),
            Control::StandAlone => "the technician at the rig (stand-alone mode)".into(),
            Control::None => "nobody: nothing heats or holds".into(),
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
