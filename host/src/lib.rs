//! `tribo`: the host side of the oscillating tribometer.
//!
//! The CLI (`src/main.rs`) is thin: each subcommand's arguments and printing are in the module of
//! the same name under `cmd`, which calls this library's modules; no module outside `cmd`
//! imports it, and no command imports another (what several share of their command lines is in
//! `cmd::common`).

#![warn(missing_docs)]

pub mod analysis;
pub mod archive;
pub mod exit;
pub mod export;
pub mod lab;
pub mod load;
pub mod onboard;
pub mod out;
pub mod replay;
pub mod simulate;

// The command line and the rig: the `cli` feature (default; the Python package goes without).
#[cfg(feature = "cli")]
pub mod campaign;
#[cfg(feature = "cli")]
pub mod cmd;
#[cfg(feature = "cli")]
pub mod link;
#[cfg(feature = "cli")]
pub mod panel;
#[cfg(feature = "cli")]
pub mod signals;
#[cfg(feature = "cli")]
pub mod ui;
#[cfg(feature = "cli")]
pub mod virtual_rig;

pub use load::{load_for_fit, load_record, Holes, LONGEST_CLEAN_STRETCH_FLAG};

pub use tribo_firmware as firmware;
pub use tribo_physics as physics;
pub use tribo_report::crosscheck;
pub use tribo_wire as wire;
