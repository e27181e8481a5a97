//! `tribo`: command-line front end of the oscillating tribometer.
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// Oscillating (relaxation) tribometer: run the rig, store runs, fit friction laws, explain
/// disagreements between model and measurement.
///
/// Every command works without hardware against the simulated rig; start with `tribo demo`.
///
/// Exit status: 0 done; 1 error (the message says what to do next); 2 usage (a wrong command
/// line); 3 finished but incomplete (a record that cannot be analysed, a fit that did not converge,
/// a run with missing data): everything usable was printed or kept; 130 interrupted by Ctrl-C, 143
/// by SIGTERM, 129 by SIGHUP (128 + the signal's number): stopped cleanly, the rig made safe.
#[derive(Parser)]
#[command(name = "tribo", version, about, long_about)]
struct Cli {
    #[command(flatten)]
    global: tribo::cmd::Global,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the firmware's on-board analysis (μ0, μ1, envelope shape) over a record, as if live.
    Onboard(tribo::cmd::onboard::Args),
    /// List attached rigs: port, USB id, serial number, firmware version.
    Devices(tribo::cmd::devices::Args),
    /// Take a run: configure, settle the heater, arm, release, stream, save, print μ0/μ1.
    #[command(after_help = tribo::ui::safety_help())]
    Run(tribo::cmd::run::Args),
    /// The rig's state, temperature, last fault and last reset cause.
    Status(tribo::cmd::status::Args),
    /// Bring-up self-test: the rig measures its converter, flash, link, reset record and watchdog.
    Selftest(tribo::cmd::selftest::Args),
    /// Fetch the rig's last run (or complete a stored one), resuming after the last good block.
    Pull(tribo::cmd::pull::Args),
    /// A series of runs over loads × temperatures × repetitions from PLAN.toml, resumable.
    #[command(after_help = tribo::ui::safety_help())]
    Campaign(tribo::cmd::campaign::Args),
    /// Start the virtual rig (firmware logic + physics simulator) on a local TCP address.
    Rig(tribo::cmd::rig::Args),
    /// Feed a recorded run back through the firmware pipeline and the simulator; report differences.
    Replay(tribo::cmd::replay::Args),
    /// A complete run on a virtual rig in this process, through the link, saved, printed and drawn.
    Demo(tribo::cmd::demo::Args),
    /// List and filter the stored runs.
    Runs(tribo::cmd::runs::Args),
    /// Campaign tables (rows × columns of mean ± sd over repetitions), as the thesis's Tables 5–7.
    Table(tribo::cmd::table::Args),
    /// Simulate the rig's free response from a friction law and write a record (CSV).
    Sim(tribo::cmd::sim::Args),
    /// Fit a friction law (coulomb, viscous, coulomb-viscous, quadratic, poly:N, lugre) to a record.
    #[command(long_about = tribo::cmd::fit::LONG_ABOUT)]
    Fit(tribo::cmd::fit::Args),
    /// Find what a friction law misses in a record, add it, and show the gap shrink.
    #[command(long_about = tribo::cmd::explain::LONG_ABOUT)]
    Explain(tribo::cmd::explain::Args),
    /// Figures (SVG/PNG) and a self-contained HTML page of a run, a record or a campaign.
    Report(tribo::cmd::report::Args),
    /// The rig's front panel in a web browser: live state, plate, trace, result and controls.
    Panel(tribo::cmd::panel::Args),
    /// Write a run or record as CSV, JSON or Parquet, or the catalog of runs as one table.
    #[command(long_about = tribo::cmd::export::LONG_ABOUT)]
    Export(tribo::cmd::export::Args),
    /// Push this PC's runs to the lab catalog (PostgreSQL): idempotent, resumable, from many PCs at once.
    #[command(long_about = tribo::cmd::sync::LONG_ABOUT)]
    Sync(tribo::cmd::sync::Args),
}

/// Errors are printed as the chain of their causes, one per line, without a backtrace (which
/// `anyhow` would add whenever `RUST_BACKTRACE` is set): a lab user needs what went wrong and what to
/// do next, not the program's stack.
///
/// A closed standard output (`tribo runs | head -1`) ends the program quietly with status 0.
fn main() -> std::process::ExitCode {
    tribo::out::install_pipe_hook();
    // Parsed in two steps to know the subcommand's name (for `--json`'s check) without a list
    // of the variants' names beside clap's own.
    let matches = Cli::command().get_matches();
    let name = matches.subcommand_name().unwrap_or_default().to_owned();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    match run(cli, &name) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) if tribo::out::is_broken_pipe(&e) => std::process::ExitCode::SUCCESS,
        Err(e) => std::process::ExitCode::from(tribo::cmd::exit::report(&e).code()),
    }
}

fn run(cli: Cli, name: &str) -> anyhow::Result<()> {
    cli.global.check_for(name)?;
    let tribo::cmd::Global { quiet, json } = cli.global;
    match cli.command {
        Command::Onboard(a) => tribo::cmd::onboard::run(tribo::cmd::onboard::Args { json, ..a }),
        Command::Devices(a) => tribo::cmd::devices::run(a),
        Command::Run(a) => tribo::cmd::run::run(tribo::cmd::run::Args { quiet, ..a }),
        Command::Status(a) => tribo::cmd::status::run(tribo::cmd::status::Args { json, ..a }),
        Command::Selftest(a) => tribo::cmd::selftest::run(tribo::cmd::selftest::Args { json, ..a }),
        Command::Pull(a) => tribo::cmd::pull::run(tribo::cmd::pull::Args { quiet, ..a }),
        Command::Campaign(a) => {
            tribo::cmd::campaign::run(tribo::cmd::campaign::Args { quiet, ..a })
        }
        Command::Rig(a) => tribo::cmd::rig::run(a),
        Command::Replay(a) => tribo::cmd::replay::run(a),
        Command::Demo(a) => tribo::cmd::demo::run(tribo::cmd::demo::Args { quiet, ..a }),
        Command::Runs(a) => tribo::cmd::runs::run(tribo::cmd::runs::Args { quiet, json, ..a }),
        Command::Table(a) => tribo::cmd::table::run(tribo::cmd::table::Args { json, ..a }),
        Command::Sim(a) => tribo::cmd::sim::run(tribo::cmd::sim::Args { quiet, ..a }),
        Command::Fit(a) => tribo::cmd::fit::run(tribo::cmd::fit::Args { json, ..a }),
        Command::Explain(a) => {
            tribo::cmd::explain::run(tribo::cmd::explain::Args { quiet, json, ..a })
        }
        Command::Report(a) => tribo::cmd::report::run(a),
        Command::Panel(a) => tribo::cmd::panel::run(tribo::cmd::panel::Args { quiet, ..a }),
        Command::Export(a) => tribo::cmd::export::run(tribo::cmd::export::Args { quiet, ..a }),
        Command::Sync(a) => tribo::cmd::sync::run(tribo::cmd::sync::Args { quiet, json, ..a }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every name in `JSON_COMMANDS` is a subcommand, so the refusal's list names real commands
    /// and `--json` is never refused to one that prints JSON under another name.
    #[test]
    fn the_json_commands_are_subcommands() {
        let cli = Cli::command();
        let names: Vec<&str> = cli.get_subcommands().map(|c| c.get_name()).collect();
        for c in tribo::cmd::JSON_COMMANDS {
            assert!(
                names.contains(&c),
                "{c} is not a subcommand of tribo: {names:?}"
            );
        }
    }

    #[test]
    fn cli_is_well_formed() {
        Cli::command().debug_assert();
    }
}
