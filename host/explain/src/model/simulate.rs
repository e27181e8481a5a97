//! Simulating a model over the record's time axis, and the gap between the two.

use super::*;

/// Simulated channels of a model on the record's grid.
#[derive(Debug, Clone)]
pub struct Simulated {
    /// y at every sample.
    pub y: Vec<f64>,
    /// y' at every sample.
    pub ydot: Vec<f64>,
    /// Force `F/N` as the force channel would read it (low-pass, delay), every sample.
    pub f_meas: Vec<f64>,
    /// The contact's force `F/N` before the channel (no low-pass, no delay), every sample.
    pub f_true: Vec<f64>,
    /// Direction asymmetry `δ` of the model (0 without it): the simulation is the symmetric
    /// motion about the shifted centre; the force channel reads `δ` more ([`super::chain`]).
    pub asym: f64,
    /// Whether the force channel's gain is a fitted nuisance (a law with a Coulomb level, which
    /// the envelope measures: without one the gain cannot be told from the viscous split).
    pub gain_free: bool,
}

/// Length of the τ segments over which a drifting Coulomb level is held constant (and the
/// temperature averaged).
pub const THERMAL_SEGMENT: f64 = 0.5;

/// Integration steps allowed per radian of τ at amplitudes up to 2.5 (proportionally more above;
/// a well-behaved law needs about ten at rtol 1e-8);
/// beyond, the candidate is rejected as too stiff.
pub(super) const STEPS_PER_RAD: f64 = 60.0;

pub(super) fn steps_used_check(
    _sim: &Simulator,
    used: usize,
    budget: usize,
) -> Result<(), ExplainError> {
    if used > budget {
        Err(ExplainError::Candidate(format!(
            "simulation needs more than {budget} steps (stiff parameters)"
        )))
    } else {
        Ok(())
    }
}

/// Simulates the model `spec`/`p` on the prepared record's grid.
pub fn simulate_spec(data: &Prepared, spec: &Spec, p: &[f64]) -> Result<Simulated, ExplainError> {
    if !spec.in_range(p) {
        return Err(ExplainError::Candidate("parameters out of range".into()));
    }
    let span = data.tau.last().copied().unwrap_or(0.0);
    // Stiffness of memory laws grows with the velocity scale, i.e. with the amplitude.
    let budget = (STEPS_PER_RAD * (data.a0 / 2.5).max(1.0) * span) as usize + 2000;
    let kappa = spec
        .effect_params(Effect::CubicStiffness, p)
        .map_or(0.0, |k| k[0]);
    let mu_a = spec.apparatus_mu1(p);
    let model_at = |dmu0: f64| {
        Model::new(spec.law(p, dmu0))
            .with_cubic(kappa)
            .with_apparatus_damping(mu_a)
    };
    let (y0, v0) = data.initial_state();
    let (y0, v0) = (
        y0 * (1.0 + spec.start_scale(p)),
        v0 * (1.0 + spec.start_scale(p)),
    );
    // A Coulomb level that moves during the motion (thermal drift, running-in) is held constant
    // over segments of THERMAL_SEGMENT of τ.
    let thermal = match (
        spec.effect_params(Effect::ThermalDrift, p),
        data.temp_seg.as_deref(),
    ) {
        (Some(g), Some(tseg)) if !tseg.is_empty() => Some((g[0], tseg)),
        _ => None,
    };
    let running = spec.effect_params(Effect::RunningIn, p).map(|d| d[0]);
    let span_end = span.max(THERMAL_SEGMENT);
    let (y, ydot, f) = match (thermal, running) {
        (None, None) => {
            let model = model_at(0.0);
            model.validate()?;
            let mut sim = Simulator::new(model, y0, v0, data.method);
            let n = data.tau.len();
            let (mut y, mut yd, mut f) = (
                Vec::with_capacity(n),
                Vec::with_capacity(n),
                Vec::with_capacity(n),
            );
            for &t in &data.tau {
                let s = sim.step_to((t + data.release_shift).max(0.0))?;
                steps_used_check(&sim, sim.steps(), budget)?;
                y.push(s.y);
                yd.push(s.ydot);
                f.push(s.f);
            }
            (y, yd, f)
        }
        (thermal, running) => {
            let dmu = |k: usize| {
                let th = thermal.map_or(0.0, |(gamma, tseg)| {
                    gamma * (tseg[k.min(tseg.len() - 1)] - tseg[0])
                });
                let run = running.map_or(0.0, |d| {
                    d * ((k as f64 + 0.5) * THERMAL_SEGMENT).min(span_end) / span_end
                });
                th + run
            };
            let model = model_at(dmu(0));
            model.validate()?;
            let mut sim = Simulator::new(model, y0, v0, data.method);
            let mut seg = 0usize;
            let mut seg_end = THERMAL_SEGMENT;
            let mut prior = 0usize;
            let n = data.tau.len();
            let (mut y, mut yd, mut f) = (
                Vec::with_capacity(n),
                Vec::with_capacity(n),
                Vec::with_capacity(n),
            );
            for &t in &data.tau {
                let t = (t + data.release_shift).max(0.0);
                while t > seg_end {
                    let s = sim.step_to(seg_end)?;
                    prior += sim.steps();
                    seg += 1;
                    let m = model_at(dmu(seg));
                    m.validate()?;
                    sim = Simulator::with_state(m, seg_end, [s.y, s.ydot, s.z], data.method);
                    seg_end += THERMAL_SEGMENT;
                }
                let s = sim.step_to(t)?;
                steps_used_check(&sim, prior + sim.steps(), budget)?;
                y.push(s.y);
                yd.push(s.ydot);
                f.push(s.f);
            }
            (y, yd, f)
        }
    };
    let mut fm = match (spec.lowpass_tau(p), data.force_cutoff_hz) {
        (Some(tau_f), _) => lowpass_of_order(&f, tau_f, data.dtau, spec.lowpass_poles),
        (None, Some(fc)) => butterworth2(&f, fc, data.rate_hz),
        (None, None) => f.clone(),
    };
    if let Some(d) = spec.effect_params(Effect::SensorLag, p) {
        fm = delay(&fm, d[0] / data.dtau);
    }
    Ok(Simulated {
        y,
        ydot,
        f_meas: fm,
        f_true: f,
        asym: spec
            .effect_params(Effect::DirectionAsymmetry, p)
            .map_or(0.0, |d| d[0]),
        gain_free: spec.powers.contains(&0),
    })
}

/// Residuals of a simulation against the record: `(envelope, force)`, both divided by the
/// initial amplitude (forces in units of N, i.e. relative to the initial spring force `k x0`),
/// with the measurement chain's nuisances (displacement centre, force gain and zero) fitted to
/// them ([`super::chain`]).
pub fn residuals(data: &Prepared, sim: &Simulated) -> (Vec<f64>, Vec<f64>) {
    let c = super::chain::fit(data, sim, data.force_zero);
    (c.env, c.force)
}

/// Root mean square (0 for an empty slice).
pub fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        0.0
    } else {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }
}

/// The gap: `√(gap_env² + gap_force²)`, each the RMS of its block of [`residuals`].
pub fn gap_of(env: &[f64], force: &[f64]) -> f64 {
    rms(env).hypot(rms(force))
}

/// Weighted residual vector minimised by the fits: each channel divided by its own noise floor
/// (the likelihood of Gaussian noise: a channel counts by how far its misfit stands above its
/// noise, so a noisy vibrometer does not drown the force channel where lag and drift show), and by
/// `√n`, so that every channel weighs by its misfit-to-noise ratio whatever the number of points
/// compared.
pub fn weighted(data: &Prepared, env: &[f64], force: &[f64]) -> Vec<f64> {
    let we = 1.0 / ((env.len().max(1) as f64).sqrt() * data.env_floor());
    let wf = 1.0 / ((force.len().max(1) as f64).sqrt() * data.force_floor().max(1e-300));
    env.iter()
        .map(|r| r * we)
        .chain(force.iter().map(|r| r * wf))
        .collect()
}
