//! The tests, and [`TESTS`], the one list the runner goes through (in this order).

pub mod app;
pub mod failsafe;
pub mod parts;
pub mod pipeline;
pub mod store;
pub mod wire;

use crate::{test, Test};

/// Every on-target test. Add yours here: `test!(module::function)`.
pub const TESTS: &[Test] = &[
    test!(wire::crc_known_vectors),
    test!(wire::cobs_round_trip),
    test!(wire::frames_match_the_host),
    test!(wire::decoder_resynchronises),
    test!(wire::framing_costs),
    test!(store::wraps_and_reads_back_and_recovers),
    test!(parts::block_path),
    test!(parts::analysis_setup),
    test!(parts::peak_fit),
    test!(pipeline::unloaded),
    test!(pipeline::coulomb_viscous),
    test!(pipeline::noisy),
    test!(pipeline::held_20k),
    test!(pipeline::short),
    test!(pipeline::cubic),
    test!(app::coulomb_viscous_run),
    test!(app::unloaded_run),
    test!(app::short_run),
    test!(app::selftest_checks),
    test!(failsafe::thermocouple_words),
    test!(failsafe::bad_reads_in_a_row_fault_the_heater),
    test!(failsafe::runaway_and_watch),
    test!(failsafe::magnet_hold_limit),
    test!(failsafe::reset_record),
    test!(failsafe::safe_state_table),
    test!(failsafe::watchdog_liveness),
    test!(failsafe::app_goes_safe),
];
