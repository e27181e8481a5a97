//! One module per `tribo` subcommand: its clap arguments and the function that runs it.

/// The flags every command takes, before or after its name (`tribo -q run …`, `tribo runs --json`).
#[derive(clap::Args, Debug, Clone, Copy, Default)]
pub struct Global {
    /// No progress bars or progress messages (results, warnings and errors are still printed).
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// Print one JSON object instead of text, for scripts: fit, explain, onboard, runs, selftest,
    /// status, sync and table (`tribo help COMMAND` gives its fields); any other command refuses it.
    #[arg(long, global = true)]
    pub json: bool,
}

/// The commands that print one JSON object with `--json` (every other command refuses the flag).
pub const JSON_COMMANDS: [&str; 8] = [
    "fit", "explain", "onboard", "runs", "selftest", "status", "sync", "table",
];

impl Global {
    /// Refuses `--json` for `command` when it has no JSON output (a usage error, exit status 2),
    /// naming the commands that have one, so that a script never gets text where it asked for JSON.
    pub fn check_for(&self, command: &str) -> Result<(), crate::exit::Usage> {
        if self.json && !JSON_COMMANDS.contains(&command) {
            return Err(crate::exit::Usage(format!(
                "--json: `tribo {command}` has no JSON output; the commands that print one are {}",
                JSON_COMMANDS.join(", ")
            )));
        }
        Ok(())
    }
}

pub mod campaign;
pub mod common;
pub mod demo;
pub mod devices;
pub mod exit;
pub mod explain;
pub mod export;
pub mod fit;
pub mod onboard;
pub mod panel;
pub mod pull;
pub mod replay;
pub mod report;
pub mod rig;
pub mod run;
pub mod runs;
pub mod selftest;
pub mod sim;
pub mod status;
pub mod sync;
pub mod table;
