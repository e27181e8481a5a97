//! The release instant of a record held by the magnet before it, measured from the motion.
//!
//! While the magnet holds, the head sits at `y_h` and its velocity is zero; from the release on it
//! moves freely, from rest. Over its first radian or so the free motion of any law of the
//! vocabulary is, to well within the noise, `y = y_h − A (1 − cos ω(τ − τ_r))` and
//! `y' = v_h + B sin ω(τ − τ_r)`: a spring released from rest against a friction level that has
//! not yet had time to change. [`release_from_motion`] fits that to the displacement and velocity
//! channels around the first moving sample, with `τ_r` (the instant), `ω` (the frequency the motion
//! has at its release amplitude: a cubic stiffness or a stiffness error of the rig moves it), the
//! held level `y_h`, the velocity channel's zero `v_h`, and the two amplitudes (the velocity's free
//! of the displacement's: a gain of the velocity channel is not assumed) all free.
//!
//! Why from the motion and not from the model's misfit: the search compares the envelope (an
//! amplitude, nearly blind to phase) and the force channel. Fitted there, the instant is the same
//! thing as a delay of the force channel (a sensor lag) and moves with any effect that changes the
//! motion's phase (a missing cubic stiffness pulls it by samples). The motion channels near the
//! release carry the instant itself; the model then holds it, like the filter's order, and prints
//! it with this ±.

use tribo_physics::identify::solve;
use tribo_physics::uncertainty::{invert, noise_sigma};

/// Phase of the motion (rad from the release) up to which the free motion is fitted: short enough
/// that a friction law's change with speed and a cubic stiffness's distortion stay in the noise,
/// long enough that the velocity's rise pins the instant.
pub const RELEASE_WINDOW_RAD: f64 = 1.0;

/// Fewest moving samples the instant is fitted from (a coarse sampling widens the window).
const MIN_MOVING_SAMPLES: usize = 12;

/// Held samples before the first moving one that enter the fit (they fix the held level and the
/// velocity's zero, and where the motion has not yet started).
const HELD_SAMPLES: usize = 16;

/// The release instant measured from the motion channels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReleaseFit {
    /// The release instant on the record's τ axis.
    pub tau: f64,
    /// Its standard error (τ units): from the fit's curvature, widened by √(χ²/dof) when the
    /// window's misfit exceeds the channels' noise.
    pub se: f64,
    /// χ² per degree of freedom of the fit in units of each channel's noise.
    pub chi2_dof: f64,
    /// The motion's frequency at its release (units of the rig's ω).
    pub omega: f64,
    /// Samples the fit used (held and moving, each with its two channels).
    pub samples: usize,
}

/// Nonlinear constants of the window's model: the instant `τ_r`, the frequency `ω` and the decay
/// rate `ζ` (a friction force that grows with the speed, viscous or quadratic, damps the rise).
const NONLINEAR: usize = 3;

/// The two shape columns of the window's model at each sample for the nonlinear constants `q`
/// (displacement `e^{−ζr}(cos ωr + (ζ/ω) sin ωr) − 1`, velocity `e^{−ζr} sin ωr`, `r = τ − τ_r`;
/// both 0 before the release).
fn shapes(tau: &[f64], q: &[f64; NONLINEAR]) -> (Vec<f64>, Vec<f64>) {
    let [tr, w, z] = *q;
    tau.iter()
        .map(|&t| {
            let r = t - tr;
            if r <= 0.0 {
                (0.0, 0.0)
            } else {
                let (s, c) = (w * r).sin_cos();
                let e = (-z * r).exp();
                (e * (c + z / w * s) - 1.0, e * s)
            }
        })
        .unzip()
}

/// Least squares of `z ≈ c + a g` (closed form): `(c, a)`, `None` if `g` is constant.
fn line(g: &[f64], z: &[f64]) -> Option<(f64, f64)> {
    let n = g.len() as f64;
    let (mg, mz) = (g.iter().sum::<f64>() / n, z.iter().sum::<f64>() / n);
    let sgg: f64 = g.iter().map(|v| (v - mg) * (v - mg)).sum();
    let sgz: f64 = g.iter().zip(z).map(|(a, b)| (a - mg) * (b - mz)).sum();
    (sgg > 0.0).then(|| {
        let a = sgz / sgg;
        (mz - a * mg, a)
    })
}

/// All the window model's constants: the nonlinear ones, then the held level, the displacement's
/// amplitude, the velocity's zero and its amplitude.
type Constants = [f64; NONLINEAR + 4];

/// The linear constants at their least-squares values for `q`, given `q`'s shape columns.
fn with_linear(w: &Window, q: &[f64; NONLINEAR], gy: &[f64], gv: &[f64]) -> Option<Constants> {
    let (yh, a) = line(gy, &w.y)?;
    let (vh, b) = line(gv, &w.v)?;
    Some([q[0], q[1], q[2], yh, a, vh, b])
}

/// The window's residuals in units of each channel's noise.
fn residuals(w: &Window, p: &Constants) -> Vec<f64> {
    let (gy, gv) = shapes(&w.tau, &[p[0], p[1], p[2]]);
    residuals_with(w, p, &gy, &gv)
}

/// [`residuals`] with the shape columns of `p`'s nonlinear constants given.
fn residuals_with(w: &Window, p: &Constants, gy: &[f64], gv: &[f64]) -> Vec<f64> {
    let ry =
        w.y.iter()
            .zip(gy)
            .map(|(y, g)| (y - p[3] - p[4] * g) / w.sy);
    let rv =
        w.v.iter()
            .zip(gv)
            .map(|(v, g)| (v - p[5] - p[6] * g) / w.sv);
    ry.chain(rv).collect()
}

/// The residuals with the linear constants projected out.
fn projected(w: &Window, q: &[f64; NONLINEAR]) -> Option<Vec<f64>> {
    let (gy, gv) = shapes(&w.tau, q);
    Some(residuals_with(w, &with_linear(w, q, &gy, &gv)?, &gy, &gv))
}

fn chi2(w: &Window, q: &[f64; NONLINEAR]) -> f64 {
    projected(w, q).map_or(f64::INFINITY, |r| r.iter().map(|x| x * x).sum())
}

struct Window {
    tau: Vec<f64>,
    y: Vec<f64>,
    v: Vec<f64>,
    sy: f64,
    sv: f64,
}

/// Central-difference Jacobian of `f` at `p` (steps `1e-3 × scale`), as columns.
fn jacobian<const N: usize>(
    f: impl Fn(&[f64; N]) -> Option<Vec<f64>>,
    p: &[f64; N],
    scale: &[f64; N],
) -> Option<Vec<Vec<f64>>> {
    (0..N)
        .map(|j| {
            let h = 1e-3 * scale[j];
            let (mut pp, mut pm) = (*p, *p);
            pp[j] += h;
            pm[j] -= h;
            let (rp, rm) = (f(&pp)?, f(&pm)?);
            Some(
                rp.iter()
                    .zip(&rm)
                    .map(|(a, b)| (a - b) / (2.0 * h))
                    .collect(),
            )
        })
        .collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The release instant of a held record (`tau`, `y`, `ydot`: the whole record, dimensionless;
/// `start`: the first sample of the motion as [`tribo_physics::identify::motion_span`] finds it,
/// within a sample or two of the release). `None` when the record does not hold before `start`,
/// has too few samples after it, or the fit does not determine the instant.
pub fn release_from_motion(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    start: usize,
) -> Option<ReleaseFit> {
    release_from_motion_over(tau, y, ydot, start, RELEASE_WINDOW_RAD)
}

/// [`release_from_motion`] over the first `window_rad` of phase after the release.
pub fn release_from_motion_over(
    tau: &[f64],
    y: &[f64],
    ydot: &[f64],
    start: usize,
    window_rad: f64,
) -> Option<ReleaseFit> {
    let n = tau.len().min(y.len()).min(ydot.len());
    if start == 0 || start >= n || n < 8 {
        return None;
    }
    let dtau = (tau[n - 1] - tau[0]) / (n - 1) as f64;
    if !(dtau.is_finite() && dtau > 0.0) {
        return None;
    }
    let moving = ((window_rad / dtau).ceil() as usize).max(MIN_MOVING_SAMPLES);
    // A window past the first reversal (half a period) is not a release from rest any more.
    if moving as f64 * dtau > 2.5 {
        return None;
    }
    let lo = start.saturating_sub(HELD_SAMPLES);
    let hi = (start + moving).min(n);
    if hi - start < MIN_MOVING_SAMPLES.min(moving) {
        return None;
    }
    let (sy, sv) = (noise_sigma(&y[..n])?, noise_sigma(&ydot[..n])?);
    let amp = y[start..hi]
        .iter()
        .chain(&ydot[start..hi])
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let tiny = 1e-9 * amp.max(f64::MIN_POSITIVE);
    let w = Window {
        tau: tau[lo..hi].to_vec(),
        y: y[lo..hi].to_vec(),
        v: ydot[lo..hi].to_vec(),
        sy: sy.max(tiny),
        sv: sv.max(tiny),
    };
    if !w.y.iter().chain(&w.v).all(|v| v.is_finite()) {
        return None;
    }
    // Start: the best of half-sample steps about `start` at the rig's frequency, undamped.
    let t0 = tau[start];
    let mut q = (-8..=4)
        .map(|k| [t0 + 0.5 * k as f64 * dtau, 1.0, 0.0])
        .min_by(|a, b| chi2(&w, a).total_cmp(&chi2(&w, b)))?;
    let mut f = chi2(&w, &q);
    // Levenberg–Marquardt on the nonlinear constants, the linear ones projected out.
    let scale = [dtau, 1e-3, 1e-3];
    let mut lambda = 1e-3;
    for _ in 0..80 {
        let r0 = projected(&w, &q)?;
        let jac = jacobian(|q| projected(&w, q), &q, &scale)?;
        let a: Vec<Vec<f64>> = jac
            .iter()
            .map(|ji| jac.iter().map(|jj| dot(ji, jj)).collect())
            .collect();
        let g: Vec<f64> = jac.iter().map(|j| -dot(j, &r0)).collect();
        let mut improved = false;
        for _ in 0..12 {
            let mut m = a.clone();
            for (i, row) in m.iter_mut().enumerate() {
                row[i] *= 1.0 + lambda;
            }
            let Some(d) = solve(m, g.clone()) else {
                lambda *= 10.0;
                continue;
            };
            let trial = [q[0] + d[0], q[1] + d[1], q[2] + d[2]];
            let ft = chi2(&w, &trial);
            if ft < f {
                let small = d.iter().zip(&scale).all(|(d, s)| d.abs() < 1e-6 * s);
                q = trial;
                f = ft;
                lambda = (lambda * 0.3).max(1e-9);
                improved = !small;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    if !(q[1] > 0.5 && q[1] < 2.0 && q[2].abs() < 1.0) {
        return None;
    }
    // The ± from the full Jacobian (the nonlinear and the linear constants).
    let (gy, gv) = shapes(&w.tau, &q);
    let p = with_linear(&w, &q, &gy, &gv)?;
    let ps = [
        dtau,
        1e-3,
        1e-3,
        w.sy,
        w.sy.max(1e-3 * p[4].abs()),
        w.sv,
        w.sv.max(1e-3 * p[6].abs()),
    ];
    let cols = jacobian(|p| Some(residuals(&w, p)), &p, &ps)?;
    let jtj: Vec<Vec<f64>> = cols
        .iter()
        .map(|ci| cols.iter().map(|cj| dot(ci, cj)).collect())
        .collect();
    let var = invert(&jtj)?[0][0];
    let dof = (2 * w.tau.len()).saturating_sub(p.len()).max(1) as f64;
    let chi2_dof = f / dof;
    let se = (var * chi2_dof.max(1.0)).sqrt();
    (se.is_finite() && se > 0.0).then_some(ReleaseFit {
        tau: q[0],
        se,
        chi2_dof,
        omega: q[1],
        samples: w.tau.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_physics::stats::Rng;

    /// A held record made analytically: at rest at `y_h` until `τ_r`, then a spring released from
    /// rest against a constant Coulomb level `c` with a viscous damping `ζ`, at a frequency `ω`
    /// (a rig's stiffness error), white noise on both channels; the motion runs past the window.
    fn record(
        frac: f64,
        omega: f64,
        zeta: f64,
        noise: f64,
        seed: u64,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>, f64) {
        let dtau = 2.0 * std::f64::consts::PI * 25.0 / 8000.0;
        let tr = (300.0 + frac) * dtau;
        let (yh, c) = (2.0, 0.02);
        let wd = (omega * omega - zeta * zeta).sqrt();
        let mut rng = Rng::new(seed);
        let (mut tau, mut y, mut v) = (vec![], vec![], vec![]);
        for i in 0..700 {
            let t = i as f64 * dtau;
            let r = (t - tr).max(0.0);
            let e = (-zeta * r).exp();
            let (s, co) = (wd * r).sin_cos();
            tau.push(t);
            y.push(c + (yh - c) * e * (co + zeta / wd * s) + noise * rng.normal());
            v.push(-(yh - c) * omega * omega / wd * e * s + noise * rng.normal());
        }
        (tau, y, v, tr)
    }

    #[test]
    fn the_release_is_found_between_two_samples_with_a_true_plus_minus() {
        let mut worst: f64 = 0.0;
        for (k, frac) in [0.03, 0.37, 0.5, 0.81, 0.97].iter().enumerate() {
            for (omega, zeta) in [(1.0, 0.0), (1.04, 0.03), (0.97, -0.01)] {
                let (tau, y, v, tr) = record(*frac, omega, zeta, 2e-3, 7 + k as u64);
                let dtau = tau[1] - tau[0];
                let start = tribo_physics::identify::motion_span(&tau, &y, &v).start;
                let f = release_from_motion(&tau, &y, &v, start).expect("a fit");
                let z = (f.tau - tr) / f.se;
                assert!(
                    z.abs() < 3.5 && f.se < 0.1 * dtau,
                    "release at +{frac} sample, ω {omega}, ζ {zeta}: fitted {:+.4} samples off, \
                     ± {:.4} (start {start})",
                    (f.tau - tr) / dtau,
                    f.se / dtau
                );
                assert!((f.omega - omega).abs() < 0.06, "ω {} for {omega}", f.omega);
                worst = worst.max(z.abs());
            }
        }
        println!("largest |z| {worst:.2}");
    }

    #[test]
    fn a_record_that_does_not_hold_or_stops_at_once_has_no_fit() {
        let (tau, y, v, _) = record(0.5, 1.0, 0.0, 2e-3, 1);
        assert!(release_from_motion(&tau, &y, &v, 0).is_none());
        assert!(release_from_motion(&tau[..305], &y[..305], &v[..305], 301).is_none());
        let mut bad = y.clone();
        bad[302] = f64::NAN;
        assert!(release_from_motion(&tau, &bad, &v, 301).is_none());
    }
}
