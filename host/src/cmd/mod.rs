//! One module per `tribo` subcommand: its clap arguments and the function that runs it.
pub mod campaign;
pub mod demo;
pub mod devices;
pub mod explain;
pub mod fit;
pub mod onboard;
pub mod pull;
pub mod replay;
pub mod report;
pub mod rig;
pub mod run;
pub mod runs;
pub mod sim;
pub mod status;
pub mod sync;
pub mod table;
