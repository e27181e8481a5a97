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
    /// The velocity reversals of the simulated motion (τ of the simulator's clock, which runs
    /// [`Prepared::release_shift`] ahead of the record's).
    pub reversals: Vec<f64>,
}

/// Length of the τ segments over which a drifting Coulomb level is held constant (and the
/// temperature averaged).
pub const THERMAL_SEGMENT: f64 = 0.5;

/// The Coulomb level's drift of a model in time (thermal drift, running-in), held constant over
/// segments of [`THERMAL_SEGMENT`] of τ on the simulator's clock: what [`simulate_spec`] adds to
/// μ0, and what the force channel's trend of μ0 leaves out of the level it tests for a drift
/// (`crate::mu0_trend_of`, the trend that remains beside the model's).
#[derive(Debug, Clone, Copy)]
pub struct Mu0Drift<'a> {
    /// dμ0/dT and the smoothed temperature of each segment ([`Prepared::temp_smooth`]).
    thermal: Option<(f64, &'a [f64])>,
    /// Running-in's Δ and shape `c` ([`running_in_shape`]).
    running: Option<(f64, f64)>,
    /// The end of the motion (τ) running-in's shape is scaled to.
    span_end: f64,
    /// Where the release falls before the first compared sample (τ; [`simulate_spec`]).
    shift: f64,
}

impl<'a> Mu0Drift<'a> {
    /// The drift of `spec`/`p` on `data`; `None` if the model has none.
    pub fn of(data: &'a Prepared, spec: &Spec, p: &[f64]) -> Option<Mu0Drift<'a>> {
        let thermal = match (
            spec.effect_params(Effect::ThermalDrift, p),
            data.temp_smooth.as_deref(),
        ) {
            (Some(g), Some(tseg)) if !tseg.is_empty() => Some((g[0], tseg)),
            _ => None,
        };
        let running = spec
            .effect_params(Effect::RunningIn, p)
            .map(|d| (d[0], d[1]));
        let span = data.tau.last().copied().unwrap_or(0.0);
        (thermal.is_some() || running.is_some()).then_some(Mu0Drift {
            thermal,
            running,
            span_end: span.max(THERMAL_SEGMENT),
            shift: data.release_shift_of(spec, p),
        })
    }

    /// The change of μ0 from the release over segment `k` (τ in `(k, k + 1] × THERMAL_SEGMENT`).
    pub fn at_segment(&self, k: usize) -> f64 {
        let th = self.thermal.map_or(0.0, |(gamma, tseg)| {
            gamma * (tseg[k.min(tseg.len() - 1)] - tseg[0])
        });
        let run = self.running.map_or(0.0, |(d, c)| {
            let x = ((k as f64 + 0.5) * THERMAL_SEGMENT).min(self.span_end) / self.span_end;
            d * running_in_shape(c, x)
        });
        th + run
    }

    /// The change of μ0 from the release at every sample of `data` (sample `i` is at
    /// `τ_i + release_shift` on the simulator's clock, in the segment [`simulate_spec`] holds it).
    pub fn at_samples(&self, data: &Prepared) -> Vec<f64> {
        data.tau
            .iter()
            .map(|&t| {
                let t = (t + self.shift).max(0.0) / THERMAL_SEGMENT;
                self.at_segment((t.ceil() as usize).saturating_sub(1))
            })
            .collect()
    }
}

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
    if !spec.in_range(p, data.a0) {
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
    let shift = data.release_shift_of(spec, p);
    let (y0, v0) = data.initial_state();
    let (y0, v0) = (
        y0 * (1.0 + spec.start_scale(p)),
        v0 * (1.0 + spec.start_scale(p)),
    );
    // A Coulomb level that moves during the motion (thermal drift, running-in) is held constant
    // over segments of THERMAL_SEGMENT of τ.
    let drift = Mu0Drift::of(data, spec, p);
    let mut reversals: Vec<f64> = Vec::new();
    let (y, ydot, f) = match drift {
        None => {
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
                let s = sim.step_to((t + shift).max(0.0))?;
                steps_used_check(&sim, sim.steps(), budget)?;
                y.push(s.y);
                yd.push(s.ydot);
                f.push(s.f);
            }
            reversals.extend(sim.reversals().iter().map(|r| r.0));
            (y, yd, f)
        }
        Some(drift) => {
            let dmu = |k: usize| drift.at_segment(k);
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
                let t = (t + shift).max(0.0);
                while t > seg_end {
                    let s = sim.step_to(seg_end)?;
                    prior += sim.steps();
                    // (Its internal step may have run past the segment's end: the next
                    // simulator finds those reversals again.)
                    reversals.extend(
                        sim.reversals()
                            .iter()
                            .map(|r| r.0)
                            .filter(|&r| r <= seg_end),
                    );
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
            reversals.extend(sim.reversals().iter().map(|r| r.0));
            (y, yd, f)
        }
    };
    let mut fm = match (spec.lowpass_tau(p), data.force_cutoff_hz) {
        (Some(tau_f), _) => spec.filter_force(&f, tau_f, data.dtau),
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
        reversals,
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

/// The noise model of the one likelihood explain's search works with: each channel's residual
/// variance `s_c²` and its effective count of independent residuals `n_eff_c`, measured from a
/// reference model's residuals and then **held** while models are compared against it.
///
/// # Derivation
///
/// Model the residuals `r_c` of channel `c` (envelope, force; `n_c` compared points) as Gaussian
/// noise of variance `s_c²` whose correlation makes `n_c` points carry the information of `n_eff_c`
/// independent ones. The log-likelihood of a parameter vector θ and the variances, up to
/// constants, is then
///
/// `−2 ln L(θ, s) = Σ_c n_eff_c · (RSS_c(θ) / (n_c s_c²) + ln s_c²)`
///
/// (each channel's χ² `RSS_c / s_c²` deflated by `n_c / n_eff_c`, the variance inflation of a mean
/// of correlated residuals). The variances are nuisances, fitted, never guessed, but never below
/// the channel's measured noise floor: `s_c² = max(RSS_c / n_c, floor_c²)`. Profiled over them,
/// with `r_c = RSS_c / (n_c floor_c²)`, the deviance is
///
/// `D(θ) = Σ_c n_eff_c · g(r_c(θ))`,  `g(r) = r` for `r ≤ 1`, `1 + ln r` above
///
/// (up to constants; `g` is continuous with its slope at the floor). Its gradient is
/// `Σ_c w_c ∇RSS_c` with `w_c = n_eff_c / (n_c s_c²)`: minimising `D` is least squares with these
/// weights, re-measured at the solution (iteratively reweighted least squares). The search holds
/// `w_c` (from the current model's residuals: its `s_c²` and `n_eff_c`) through a round, and the
/// same noise model gives
///
/// - **the fit**: Levenberg–Marquardt minimises `Σ_c w_c RSS_c` ([`weighted`] returns
///   `√w_c · r_c`; the current model is refitted under the round's weights first, one
///   reweighting step), so a fit cannot trade misfit of a channel the likelihood weighs heavily
///   for misfit of one it weighs lightly (grid #213: the running-in fit lowered the envelope's
///   RSS and raised the force channel's, which the old evidence then rated a loss);
/// - **the evidence** of a model `a` (the reference `b` plus an effect of `k` constants):
///   `D(b) − D(a)` with `n_eff_c` held, twice the log-likelihood ratio, χ²_k when the effect is
///   absent; near the floor it is `Σ_c w_c (RSS_c(b) − RSS_c(a))`, and far above it the
///   logarithm keeps a strong effect's evidence from being capped at `n_eff_c` (an envelope
///   4500 × its floor with `n_eff` 9: a quadratic term that removes it all);
/// - **the excess misfit** of `b`: `Σ_c n_eff_c max(g(r_c(b)) − g(1 + 2 u_c), 0)` — its deviance
///   above what noise at the floor leaves, counted beyond 2 of `u_c = √(2 / n_eff_c + ε_c²)`, how
///   well a right model's mean square residual (`√(2 / n_eff_c)`) and the floor² read from the
///   record (`ε_c`, [`Prepared::floor_rel_se`]) are known: over every force sample, 0.5 % of the
///   floor² is hundreds of units, and within the floor's own ± — so the share an effect removes is
///   its evidence over that excess, in the same units.
///
/// `None` in [`Prepared::noise`] (before any model is fitted) is noise at the floor with
/// independent residuals, `w_c = 1 / floor_c²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Residual variance of the envelope channel (`a0` units²).
    pub env_var: f64,
    /// Effective count of independent envelope residuals.
    pub env_n_eff: f64,
    /// Residual variance of the force channel (`F/N / a0` units²; 0 without a force channel).
    pub force_var: f64,
    /// Effective count of independent force residuals.
    pub force_n_eff: f64,
}

impl NoiseModel {
    /// The noise model of a model's residuals: each channel's mean square residual (never below
    /// its noise floor²) and their effective count (between 1 and the number of points).
    pub fn of(data: &Prepared, env: &[f64], force: &[f64]) -> NoiseModel {
        let part = |r: &[f64], floor: f64| -> (f64, f64) {
            if r.is_empty() {
                return (floor * floor, 1.0);
            }
            let n = r.len() as f64;
            let var = (r.iter().map(|x| x * x).sum::<f64>() / n).max(floor * floor);
            let n_eff = tribo_physics::uncertainty::effective_count(r);
            let n_eff = if n_eff.is_finite() {
                n_eff.clamp(1.0, n)
            } else {
                n
            };
            (var, n_eff)
        };
        let (env_var, env_n_eff) = part(env, data.env_floor());
        let (force_var, force_n_eff) = part(force, data.force_floor());
        NoiseModel {
            env_var,
            env_n_eff,
            force_var,
            force_n_eff,
        }
    }
}

impl Prepared {
    /// The likelihood's weight of one squared residual of each channel, `(w_env, w_force)` with
    /// `w_c = n_eff_c / (n_c s_c²)` ([`NoiseModel`]), for `n_env` and `n_force` compared points.
    pub fn channel_weights(&self, n_env: usize, n_force: usize) -> (f64, f64) {
        let w = |var: f64, n_eff: f64, n: usize| {
            if n == 0 || var.is_nan() || var <= 0.0 {
                0.0
            } else {
                n_eff.min(n as f64) / (n as f64 * var)
            }
        };
        match &self.noise {
            Some(m) => (
                w(m.env_var, m.env_n_eff, n_env),
                w(m.force_var, m.force_n_eff, n_force),
            ),
            None => {
                let (fe, ff) = (self.env_floor(), self.force_floor());
                (
                    w(fe * fe, n_env as f64, n_env),
                    w(ff * ff, n_force as f64, n_force),
                )
            }
        }
    }

    /// `−2 ln L` of residuals under [`Prepared::noise`]: `Σ_c w_c RSS_c`.
    pub fn chi2(&self, env: &[f64], force: &[f64]) -> f64 {
        let (we, wf) = self.channel_weights(env.len(), force.len());
        let ss = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>();
        we * ss(env) + wf * ss(force)
    }
}

/// The residual vector the fits minimise for the model `spec`/`p`: [`weighted`], then the release
/// instant's prior ([`Prepared::release_prior`]) when the instant is a parameter, so that `Σ` of
/// the squares is `−2 ln L` with the prior.
pub fn objective(data: &Prepared, spec: &Spec, p: &[f64], env: &[f64], force: &[f64]) -> Vec<f64> {
    let mut r = weighted(data, env, force);
    r.extend(data.release_prior(spec, p));
    r
}

/// The blocks of an [`objective`] residual vector `r` with `n_env` envelope and `n_force` force
/// residuals for the HAC sandwich (envelope, force, the release instant's prior), and the residuals
/// its meat is built from: the prior is one residual whose variance is 1 by construction, so its
/// part of the meat is its expected square, 1, not its realised one.
pub fn sandwich_blocks(
    r: &[f64],
    n_env: usize,
    n_force: usize,
) -> ([std::ops::Range<usize>; 3], Vec<f64>) {
    let nc = n_env + n_force;
    let mut meat = r.to_vec();
    meat[nc..].iter_mut().for_each(|v| *v = 1.0);
    ([0..n_env, n_env..nc, nc..r.len()], meat)
}

/// Weighted residual vector minimised by the fits: each channel's residuals times `√w_c`, the
/// square root of its weight in the likelihood ([`NoiseModel`]: its noise variance and the
/// correlation of its residuals), so that `Σ` of the squares is the `−2 ln L` the evidence and the
/// excess rule use ([`Prepared::chi2`]).
pub fn weighted(data: &Prepared, env: &[f64], force: &[f64]) -> Vec<f64> {
    let (we, wf) = data.channel_weights(env.len(), force.len());
    let (we, wf) = (we.sqrt(), wf.sqrt());
    env.iter()
        .map(|r| r * we)
        .chain(force.iter().map(|r| r * wf))
        .collect()
}
