//! Limits every configuration must respect (the rig's physical ranges), the fail-safe limits the rig
//! enforces, and the host's settling defaults: each fact once, read by firmware and host alike.

use core::ops::RangeInclusive;
pub const MASS_KG: RangeInclusive<f32> = 1e-3..=10.0;
pub const STIFFNESS_N_PER_M: RangeInclusive<f32> = 1.0..=1e5;
/// Micrometric knob range.
pub const LOAD_N: RangeInclusive<f32> = 0.0..=0.7;
pub const SAMPLE_RATE_HZ: RangeInclusive<u32> = 1_000..=20_000;
/// The electromagnet holds the head up to 1 mm out of equilibrium.
pub const INITIAL_AMPLITUDE_M: RangeInclusive<f32> = 1e-6..=1e-3;
pub const MAX_DURATION_S: RangeInclusive<f32> = 0.1..=60.0;
/// Heater setpoint: ambient to 100 °C.
pub const HEATER_SETPOINT_C: RangeInclusive<f32> = 15.0..=100.0;
pub const HEATER_RAMP_C_PER_MIN: RangeInclusive<f32> = 0.1..=30.0;
/// Hard heater cut-off, whatever the setpoint.
pub const HEATER_CUTOFF_C: f32 = 110.0;
/// Longest time without a command or [`super::HostMsg::Heartbeat`] from the host while heating or
/// holding the magnet; then the outputs go safe ([`super::FaultReason::LeaseExpired`]).
pub const HOST_LEASE_MS: u32 = 3_000;

// ---- Fail-safe limits: every interlock's number, in one place (README "Safety") ----

/// The host sends a [`super::HostMsg::Heartbeat`] this often while it holds the rig (three per
/// lease: one lost frame never expires it).
pub const HEARTBEAT_MS: u32 = HOST_LEASE_MS / 3;
/// Consecutive bad or missing thermocouple reads (one every 100 ms) that make a heater fault. The
/// heater is off from the first bad read on; the fault latches at this count.
pub const TC_BAD_READS: u8 = 3;
/// A converter reading older than this is missing (the converter stopped answering).
pub const TC_MAX_AGE_MS: u32 = 250;
/// Bad reads in the first second after boot do not make a fault yet (the converter's first
/// conversion takes ~150 ms after it is configured); the heater is off for them all the same.
pub const TC_STARTUP_GRACE_MS: u32 = 1_000;
/// Plausible cold-junction (board) temperature of the MAX31856; outside, its readings are bad.
pub const COLD_JUNCTION_C: RangeInclusive<f32> = 5.0..=50.0;
/// Lowest plausible plate temperature; below, the reading is bad (reversed or damaged
/// thermocouple).
pub const PLATE_MIN_C: f32 = -20.0;
/// Heating watch: while the plate is more than [`HEATER_BAND_C`] below the (ramped) setpoint it
/// must gain at least this much…
pub const HEATER_WATCH_GAIN_C: f32 = 2.0;
/// …in this time, or the heater is cut off (`HeatingFailed`: the heater does not heat, or the
/// thermocouple is not on the plate). Also the window of the runaway rise below.
pub const HEATER_WATCH_PERIOD_S: f32 = 60.0;
/// The band around the (ramped) setpoint in which the plate is "at setpoint".
pub const HEATER_BAND_C: f32 = 5.0;
/// Runaway: while no heat is wanted (heater off, faulted, or the plate above the band) the plate
/// may not rise this much above its lowest reading of the last [`HEATER_WATCH_PERIOD_S`]
/// (`Runaway`: the heater's switch is stuck on).
pub const HEATER_RUNAWAY_RISE_C: f32 = 5.0;
/// The electromagnet holds at most this long at a stretch…
pub const MAGNET_MAX_HOLD_MS: u32 = 120_000;
/// …and at most this fraction of the time on average: a budget of [`MAGNET_MAX_HOLD_MS`] that
/// holding spends and rest refills at `duty / (1 − duty)` per second. An empty budget switches
/// the coil off (`MagnetHoldTime`); it may hold again once half the budget is back (the
/// cool-down, 60 s at 50 %).
pub const MAGNET_MAX_DUTY: f32 = 0.5;
/// Stand-alone mode (button only, no host): a press this long on an idle, configured rig arms it…
pub const STANDALONE_PRESS_MS: u32 = 2_000;
/// …the magnet then holds at most this long without a release…
pub const STANDALONE_HOLD_MS: u32 = 30_000;
/// …and the heater (at the host's last setpoint) runs at most this long after the last press.
pub const STANDALONE_HEAT_MS: u32 = 1_800_000;
/// Hardware watchdog timeout of the board (IWDG), fed only while every task checks in.
pub const WATCHDOG_TIMEOUT_MS: u32 = 250;
/// Host default: the plate is settled when within this of the setpoint…
pub const SETTLE_TOL_C: f32 = 0.5;
/// …for this long (`tribo run --settle-secs`, campaign `settle_s`).
pub const SETTLE_S: f64 = 30.0;
/// Host default: give up heating after this long.
pub const SETTLE_TIMEOUT_S: f64 = 1_800.0;

// The settle tolerance is inside the runaway band: a settled plate cannot trip a fault.
const _: () = assert!(SETTLE_TOL_C < HEATER_BAND_C);
// One lost heartbeat does not expire the lease.
const _: () = assert!(2 * HEARTBEAT_MS < HOST_LEASE_MS);
