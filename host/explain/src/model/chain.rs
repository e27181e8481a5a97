//! The measurement chain's nuisances a record may not state, fitted to every model: the
//! displacement centre, the force channel's gain and its zero.
//!
//! What the physics lets each channel tell:
//!
//! - **Displacement centre** `c` (y units): the motion's centre as the vibrometer reads it. A zero
//!   offset of the vibrometer (±50 µm on a bench) shifts the measured oscillation; so does a
//!   direction asymmetry `δ` of μ0 (the constant force `N δ` while sliding moves the equilibrium by
//!   `−δ`). The Mark & Crandall envelope of a shifted oscillation ripples at the oscillation
//!   frequency with amplitude `c`, so `c` is measured from the displacement alone — but only as
//!   the sum `zero − δ`. (The simulation starts from the first sample's state scaled by `1 + s`,
//!   which takes up the shifted start.)
//! - **Force gain** `g` (measured = g × true): the envelope measures the Coulomb level μ0, the
//!   force channel `g μ0`, so `g` is told apart when the law has a Coulomb level. Without one (a
//!   viscous law) the force sees `g μ1` and the envelope `μ1 + μ_a`: the gain cannot be told from
//!   the apparatus' share of the damping, and it is held at 1.
//! - **Force zero** `z` (`F/N`): a constant added to the force channel. A direction asymmetry adds
//!   `g δ` to it while sliding, and (with the centre moved by `−δ`) the same during sticking (the
//!   friction then balances the spring about the true equilibrium). So the two zero offsets
//!   together are *exactly* a direction asymmetry for every law of the vocabulary: `(c, z) =
//!   (zero_x − δ, zero_f + g δ)`. With the force zero stated by the record (the rig zeroes the
//!   channel unloaded) the asymmetry is measured; without it, a constant force offset is reported
//!   as "a force zero offset or a direction asymmetry", never named as either. The rest after the
//!   final stop adds no equation: there the force channel reads the spring, whose `F + y` is
//!   `zero_f + zero_x` = `c + z` again (`tests/asymmetry_zero.rs`: a grid record with an
//!   asymmetry and no hold is its symmetric twin with the two offsets, to one quantisation step).
//!
//! All three enter the residuals linearly or nearly so, and are fitted in closed form (the force)
//! and by three Gauss–Newton steps (the centre) for every evaluation of a model: no simulation is
//! added. Their ± come from the full Jacobian (the law's parameters and the nuisances together,
//! [`nuisance_standard_errors`]).

use super::*;

/// The chain's nuisances fitted to one simulation, with the residuals they leave.
#[derive(Debug, Clone)]
pub struct ChainFit {
    /// Displacement centre `c` (y units).
    pub center: f64,
    /// Force channel gain `g` (1 when held).
    pub gain: f64,
    /// Force channel zero `z` (`F/N`; the stated value when stated).
    pub zero: f64,
    /// Envelope residuals (model − measured) / a0.
    pub env: Vec<f64>,
    /// Force residuals (model − measured) / a0.
    pub force: Vec<f64>,
}

/// The measured envelope about the centre `c` at the compared points.
fn envelope_about(data: &Prepared, c: f64) -> Vec<f64> {
    data.env_idx
        .iter()
        .map(|&i| (data.y[i] - c).hypot(data.ydot[i]))
        .collect()
}

/// Residuals of a simulation with given nuisances.
pub fn apply(
    data: &Prepared,
    sim: &Simulated,
    center: f64,
    gain: f64,
    zero: f64,
) -> (Vec<f64>, Vec<f64>) {
    let env = data
        .env_idx
        .iter()
        .zip(envelope_about(data, center))
        .map(|(&i, m)| (sim.y[i].hypot(sim.ydot[i]) - m) / data.a0)
        .collect();
    let force = match &data.f_meas {
        Some(fm) => data
            .f_idx
            .iter()
            .map(|&i| (gain * (sim.f_meas[i] + sim.asym) + zero - fm[i]) / data.a0)
            .collect(),
        None => Vec::new(),
    };
    (env, force)
}

/// Fits the nuisances to `sim`: the centre always; the force gain when `sim.gain_free`; the force
/// zero held at `zero` when given, else fitted.
pub fn fit(data: &Prepared, sim: &Simulated, zero: Option<f64>) -> ChainFit {
    // The centre: Gauss–Newton on Σ (A_sim − |(y − c, y')|)², from 0.
    let a_sim: Vec<f64> = data
        .env_idx
        .iter()
        .map(|&i| sim.y[i].hypot(sim.ydot[i]))
        .collect();
    let mut c = 0.0;
    for _ in 0..3 {
        let (mut num, mut den) = (0.0, 0.0);
        for (k, &i) in data.env_idx.iter().enumerate() {
            let dy = data.y[i] - c;
            let am = dy.hypot(data.ydot[i]);
            if am <= 0.0 {
                continue;
            }
            let r = a_sim[k] - am;
            let j = dy / am;
            num += r * j;
            den += j * j;
        }
        if !(den > 0.0 && num.is_finite()) {
            break;
        }
        let step = num / den;
        c -= step;
        if step.abs() < 1e-12 * data.a0 {
            break;
        }
    }
    if !c.is_finite() {
        c = 0.0;
    }
    // The force: least squares of the measured force on the simulated one (plus the asymmetry).
    let (mut gain, mut z) = (1.0, zero.unwrap_or(0.0));
    if let Some(fm) = &data.f_meas {
        let n = data.f_idx.len() as f64;
        if n > 0.0 {
            let (mut su, mut sf, mut suu, mut suf) = (0.0, 0.0, 0.0, 0.0);
            for &i in &data.f_idx {
                let u = sim.f_meas[i] + sim.asym;
                su += u;
                sf += fm[i];
                suu += u * u;
                suf += u * fm[i];
            }
            match (zero, sim.gain_free) {
                (Some(z0), true) => {
                    if suu > 0.0 {
                        gain = (suf - z0 * su) / suu;
                    }
                }
                (Some(_), false) => {}
                (None, true) => {
                    let det = n * suu - su * su;
                    if det > 1e-12 * n * suu {
                        gain = (n * suf - su * sf) / det;
                        z = (sf - gain * su) / n;
                    } else {
                        z = (sf - su) / n;
                    }
                }
                (None, false) => z = (sf - su) / n,
            }
            if !(gain.is_finite() && gain > 0.0) {
                gain = 1.0;
                z = zero.unwrap_or((sf - su) / n);
            }
        }
    }
    let (env, force) = apply(data, sim, c, gain, z);
    ChainFit {
        center: c,
        gain,
        zero: z,
        env,
        force,
    }
}

/// Standard errors of the nuisances of a fitted model: `(centre, gain, zero)`, `NaN` for one held
/// (the gain without a Coulomb level, the zero when stated). From the Jacobian of the weighted
/// residuals in the model's free parameters and the nuisances together, with the HAC sandwich
/// per channel (as [`crate::standard_errors_of`]).
pub fn nuisance_standard_errors(
    data: &Prepared,
    spec: &Spec,
    p: &[f64],
    held: Option<usize>,
) -> [f64; 3] {
    let Ok(sim0) = simulate_spec(data, spec, p) else {
        return [f64::NAN; 3];
    };
    let cf = fit(data, &sim0, data.force_zero);
    let free: Vec<usize> = (0..p.len()).filter(|&i| Some(i) != held).collect();
    let gain_free = sim0.gain_free && data.has_force();
    let zero_free = data.force_zero.is_none() && data.has_force();
    let mut q0: Vec<f64> = free.iter().map(|&i| p[i]).collect();
    let mut scales: Vec<f64> = {
        let s = spec.se_scales(data.dtau);
        free.iter().map(|&i| s[i]).collect()
    };
    let np = q0.len();
    q0.push(cf.center);
    scales.push(1e-3);
    if gain_free {
        q0.push(cf.gain);
        scales.push(1e-2);
    }
    if zero_free {
        q0.push(cf.zero);
        scales.push(1e-4);
    }
    let residual = |q: &[f64]| -> Option<Vec<f64>> {
        let mut pp = p.to_vec();
        for (&i, &v) in free.iter().zip(&q[..np]) {
            pp[i] = v;
        }
        let same = pp.iter().zip(p).all(|(a, b)| a == b);
        let owned;
        let sim = if same {
            &sim0
        } else {
            owned = simulate_spec(data, spec, &pp).ok()?;
            &owned
        };
        let mut k = np + 1;
        let gain = if gain_free {
            k += 1;
            q[k - 1]
        } else {
            cf.gain
        };
        let zero = if zero_free { q[k] } else { cf.zero };
        let (e, f) = apply(data, sim, q[np], gain, zero);
        Some(objective(data, spec, &pp, &e, &f))
    };
    let Some(r0) = residual(&q0) else {
        return [f64::NAN; 3];
    };
    let (blocks, r_meat) = sandwich_blocks(&r0, cf.env.len(), cf.force.len());
    let se = jacobian(residual, &q0, &r0, 1e-3, &scales)
        .and_then(|j| hac_covariance_blocks(&j, &r_meat, &blocks))
        .map(|c| standard_errors(&c))
        .unwrap_or_else(|| vec![f64::NAN; q0.len()]);
    let mut k = np + 1;
    let gain_se = if gain_free {
        k += 1;
        se[k - 1]
    } else {
        f64::NAN
    };
    let zero_se = if zero_free { se[k] } else { f64::NAN };
    [se[np], gain_se, zero_se]
}

use tribo_physics::uncertainty::{hac_covariance_blocks, jacobian, standard_errors};
