//! What the host asks of a run before it starts: the rig's configuration, heating, the button.

use tribo_wire::Configure;

/// Heat the plate to a setpoint and wait until it holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeaterPlan {
    /// Plate temperature to reach (°C).
    pub setpoint_c: f32,
    /// Heating ramp (°C/min).
    pub ramp_c_per_min: f32,
    /// Settled when within this of the setpoint…
    pub tolerance_c: f32,
    /// …for this long.
    pub settle_s: f64,
    /// Give up after this long.
    pub timeout_s: f64,
}

impl HeaterPlan {
    /// Heat to `setpoint_c` at `ramp_c_per_min`, settled by the defaults of
    /// [`tribo_wire::limits`] (within [`tribo_wire::limits::SETTLE_TOL_C`] for
    /// [`tribo_wire::limits::SETTLE_S`], giving up after [`tribo_wire::limits::SETTLE_TIMEOUT_S`]).
    pub fn new(setpoint_c: f32, ramp_c_per_min: f32) -> HeaterPlan {
        HeaterPlan {
            setpoint_c,
            ramp_c_per_min,
            tolerance_c: tribo_wire::limits::SETTLE_TOL_C,
            settle_s: tribo_wire::limits::SETTLE_S,
            timeout_s: tribo_wire::limits::SETTLE_TIMEOUT_S,
        }
    }
}

/// Everything `tribo run` needs to take one run.
#[derive(Debug, Clone)]
pub struct RunPlan {
    /// The rig's configuration for the run (rate, duration, rig constants, load, x0).
    pub config: Configure,
    /// `None`: heater off.
    pub heater: Option<HeaterPlan>,
    /// Wait for the rig's button instead of releasing from here.
    pub button: bool,
    /// Leave the heater on after the run (campaigns).
    pub keep_heater: bool,
    /// Label stored with the run.
    pub label: Option<String>,
    /// The sample (pin and plate materials) stored with the run.
    pub sample: Option<String>,
    /// The lubricant stored with the run.
    pub lubricant: Option<String>,
    /// The campaign the run belongs to.
    pub campaign: Option<String>,
    /// Which repetition of its campaign point (from 1).
    pub repeat: Option<u32>,
    /// Rig constants a default stood in for (recorded in the run's metadata).
    pub defaults: Vec<String>,
}

impl RunPlan {
    /// A plan for `config`: heater off, released from here, nothing labelled.
    pub fn new(config: Configure) -> RunPlan {
        RunPlan {
            config,
            heater: None,
            button: false,
            keep_heater: false,
            label: None,
            sample: None,
            lubricant: None,
            campaign: None,
            repeat: None,
            defaults: Vec::new(),
        }
    }
}

/// The heater's settling rule (`tribo run --settle-tol/--settle-secs/--settle-timeout`, a
/// campaign's `settle_tol_c`, `settle_s`, `settle_timeout_s`) as a plate can meet it: a tolerance
/// above 0 (a reading never equals its setpoint: 0 waits the whole timeout) and inside the
/// heater's band (±[`limits::HEATER_BAND_C`], where the plate counts as at its setpoint), a time
/// of 0 s or more, and a timeout longer than that time.
///
/// [`limits::HEATER_BAND_C`]: tribo_wire::limits::HEATER_BAND_C
pub fn check_settle(tol_c: f32, settle_s: f64, timeout_s: f64) -> Result<(), String> {
    let band = tribo_wire::limits::HEATER_BAND_C;
    if !(tol_c.is_finite() && tol_c > 0.0 && tol_c < band) {
        return Err(format!(
            "the settle tolerance must be above 0 and below {band} °C (the heater's band; default {} °C)",
            tribo_wire::limits::SETTLE_TOL_C
        ));
    }
    if !(settle_s.is_finite() && settle_s >= 0.0) {
        return Err(format!(
            "the settle time must be 0 s or more (default {} s)",
            tribo_wire::limits::SETTLE_S
        ));
    }
    if !(timeout_s.is_finite() && timeout_s > settle_s) {
        return Err(format!(
            "the settle timeout must be longer than the settle time (default {} s)",
            tribo_wire::limits::SETTLE_TIMEOUT_S
        ));
    }
    Ok(())
}
