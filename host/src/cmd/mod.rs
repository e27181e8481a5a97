//! One module per `tribo` subcommand: its clap arguments and the function that runs it.

/// The flags every command takes, before or after its name (`tribo -q run …`).
#[derive(clap::Args, Debug, Clone, Copy, Default)]
pub struct Global {
    /// No progress bars or progress messages (results, warnings and errors are still printed).
    #[arg(short, long, global = true)]
    pub quiet: bool,
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
