//! Rig logic of the oscillating tribometer.
//!
//! `no_std`, no heap, `f32` maths through `micromath`. Nothing in here names a pin, a DMA channel or
//! an interrupt: hardware sits behind the small traits of [`hal`], bound to embassy-stm32 by the board
//! binary (`firmware/board`) and to the physics simulator by the host's virtual rig.
#![cfg_attr(not(test), no_std)]

pub use tribo_wire as wire;

// On-board analysis: counts → SI → peaks and envelope → two friction fits → result.
pub mod analysis;
pub mod calib;
pub mod envelope;
pub mod fit;
pub mod peaks;

// The application: hardware traits, the rig's concerns, the state machine.
pub mod acquisition;
pub mod app;
pub mod ecr;
pub mod hal;
pub mod heater;
pub mod release;
pub mod runstore;

// The fail-safe rig: thermocouple trust, host lease, the safe state as data, the
// watchdog's liveness bookkeeping, the reset record.
pub mod lease;
pub mod link_tx;
pub mod reset;
pub mod safety;
pub mod selftest;
pub mod stack;
pub mod thermocouple;
pub mod watchdog;
