//! `tribo`: the host side of the oscillating tribometer.
//!
//! The CLI (`src/main.rs`) is thin: each subcommand parses its arguments and calls one function of
//! this library, found in the module of the same name under [`cmd`].

pub mod archive;
pub mod cmd;
pub mod exit;
pub mod link;
pub mod load;
pub mod out;
pub mod signals;

pub use load::{load_for_fit, load_record, Holes, LONGEST_CLEAN_STRETCH_FLAG};

pub use tribo_firmware as firmware;
pub use tribo_physics as physics;
pub use tribo_report::crosscheck;
pub use tribo_wire as wire;
