//! One module per `tribo` subcommand: its clap arguments and the function that runs it.
pub mod onboard;
pub mod campaign;
pub mod demo;
pub mod devices;
pub mod pull;
pub mod replay;
pub mod rig;
pub mod run;
pub mod runs;
pub mod table;
pub mod fit;
pub mod explain;
pub mod sim;
pub mod report;
