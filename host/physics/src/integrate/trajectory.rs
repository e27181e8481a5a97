//! Whole records: a model simulated from one initial state and sampled on a grid of times.

use super::{Method, SimError, Simulator};
use crate::model::Model;

/// A sampled dimensionless trajectory.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trajectory {
    /// τ.
    pub tau: Vec<f64>,
    /// y.
    pub y: Vec<f64>,
    /// y'.
    pub ydot: Vec<f64>,
    /// Internal state z.
    pub z: Vec<f64>,
    /// Contact friction force f.
    pub f: Vec<f64>,
    /// τ at which the pin stuck for good, if it did within the record.
    pub stop_tau: Option<f64>,
    /// Velocity reversals `(τ, y)` within the record (discontinuous laws).
    pub reversals: Vec<(f64, f64)>,
}

/// Simulates `model` from `(y0, ydot0)` and samples it at the increasing times `taus`.
pub fn simulate(
    model: &Model,
    y0: f64,
    ydot0: f64,
    taus: &[f64],
    method: Method,
) -> Result<Trajectory, SimError> {
    model.validate()?;
    if !(y0.is_finite() && ydot0.is_finite()) {
        return Err(SimError::Run("initial state must be finite".into()));
    }
    let mut sim = Simulator::new(model.clone(), y0, ydot0, method);
    let mut tr = Trajectory {
        tau: Vec::with_capacity(taus.len()),
        y: Vec::with_capacity(taus.len()),
        ydot: Vec::with_capacity(taus.len()),
        z: Vec::with_capacity(taus.len()),
        f: Vec::with_capacity(taus.len()),
        ..Default::default()
    };
    for &t in taus {
        let s = sim.step_to(t)?;
        tr.tau.push(t);
        tr.y.push(s.y);
        tr.ydot.push(s.ydot);
        tr.z.push(s.z);
        tr.f.push(s.f);
        if s.stuck && tr.stop_tau.is_none() {
            tr.stop_tau = Some(sim.tau());
        }
    }
    let end = taus.last().copied().unwrap_or(0.0);
    tr.reversals = sim
        .reversals()
        .iter()
        .copied()
        .filter(|r| r.0 <= end)
        .collect();
    Ok(tr)
}

/// Uniform grid `0, dtau, 2 dtau, …` with `n` points.
pub fn grid(n: usize, dtau: f64) -> Vec<f64> {
    (0..n).map(|i| i as f64 * dtau).collect()
}
