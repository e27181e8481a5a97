//! `tribo`: command-line front end of the oscillating tribometer.
use clap::{Parser, Subcommand};

/// Oscillating (relaxation) tribometer: run the rig, store runs, fit friction laws, explain
/// disagreements between model and measurement.
///
/// Every command works without hardware against the simulated rig; start with `tribo demo`.
#[derive(Parser)]
#[command(name = "tribo", version, about, long_about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {}
}
