//! The force channel's low-pass as a fitted nuisance: a 2nd-order Butterworth filter of the
//! continuous-time charge amplifier, `y'' + √2 ω_c y' + ω_c² y = ω_c² u`, discretised exactly for an
//! input that is linear between samples (first-order hold). Its one constant is the time constant
//! `τ_f = 1/ω_c` (in τ units, radians of the rig's oscillation); the output is a smooth function
//! of it down to `τ_f = 0`, where the filter is the identity, so that the fit can tell "no filter"
//! from "a filter" without a guess. (The bilinear filter the rig's records are made with,
//! [`tribo_physics::sensor::butterworth2`], is not: it is clamped below the Nyquist rate.)
//!
//! A bench's force channel may instead have a 1-pole filter (`shared/docs/real-bench.md`:
//! none, 1-pole or 2-pole at 100–1000 Hz): [`lowpass_1pole`], `y' = ω_c (u − y)`, discretised the
//! same way, also the identity at `τ_f = 0`. The order is part of the fitted nuisance
//! ([`lowpass_of_order`], `Spec::lowpass_poles`).

/// `exp(M)` of a 4×4 matrix (scaling and squaring of a Taylor series).
fn expm4(m: [[f64; 4]; 4]) -> [[f64; 4]; 4] {
    let norm = m
        .iter()
        .map(|r| r.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let mut s = 0u32;
    while norm / f64::from(1u32 << s.min(31)) > 0.25 && s < 60 {
        s += 1;
    }
    let scale = 0.5f64.powi(s as i32);
    let a: [[f64; 4]; 4] = m.map(|r| r.map(|v| v * scale));
    let mul = |x: &[[f64; 4]; 4], y: &[[f64; 4]; 4]| {
        let mut z = [[0.0; 4]; 4];
        for i in 0..4 {
            for j in 0..4 {
                z[i][j] = (0..4).map(|k| x[i][k] * y[k][j]).sum();
            }
        }
        z
    };
    let mut e = [[0.0; 4]; 4];
    let mut term = [[0.0; 4]; 4];
    for i in 0..4 {
        e[i][i] = 1.0;
        term[i][i] = 1.0;
    }
    for n in 1..=16 {
        term = mul(&term, &a).map(|r| r.map(|v| v / n as f64));
        for i in 0..4 {
            for j in 0..4 {
                e[i][j] += term[i][j];
            }
        }
    }
    for _ in 0..s {
        e = mul(&e, &e);
    }
    e
}

/// Low-pass of a uniformly sampled signal `u` (sample interval `h` in τ) by the Butterworth filter
/// of time constant `tau_f` (τ units; its magnitude is used, 0 = no filter), settled at the first
/// value.
pub fn lowpass(u: &[f64], tau_f: f64, h: f64) -> Vec<f64> {
    let tau_f = tau_f.abs();
    if u.is_empty() || tau_f == 0.0 || h.is_nan() || h <= 0.0 || !tau_f.is_finite() {
        return u.to_vec();
    }
    let w = 1.0 / tau_f;
    let r2 = std::f64::consts::SQRT_2;
    // State (y, y'/ω_c), input u, its slope s over the sample interval.
    let m = [
        [0.0, w * h, 0.0, 0.0],
        [-w * h, -r2 * w * h, w * h, 0.0],
        [0.0, 0.0, 0.0, h],
        [0.0, 0.0, 0.0, 0.0],
    ];
    let e = expm4(m);
    let mut x = [u[0], 0.0];
    let mut out = Vec::with_capacity(u.len());
    out.push(u[0]);
    for k in 1..u.len() {
        let (u0, s) = (u[k - 1], (u[k] - u[k - 1]) / h);
        x = [
            e[0][0] * x[0] + e[0][1] * x[1] + e[0][2] * u0 + e[0][3] * s,
            e[1][0] * x[0] + e[1][1] * x[1] + e[1][2] * u0 + e[1][3] * s,
        ];
        out.push(x[0]);
    }
    out
}

/// Low-pass of a uniformly sampled signal `u` (sample interval `h` in τ) by the 1-pole filter
/// `y' = (u − y)/τ_f` (τ units; its magnitude is used, 0 = no filter), exact for an input linear
/// between samples, settled at the first value.
pub fn lowpass_1pole(u: &[f64], tau_f: f64, h: f64) -> Vec<f64> {
    let tau_f = tau_f.abs();
    if u.is_empty() || tau_f == 0.0 || h.is_nan() || h <= 0.0 || !tau_f.is_finite() {
        return u.to_vec();
    }
    // y(h) = a y0 + (1 − a) u0 + s (h − τ_f (1 − a)), a = e^{−h/τ_f}, s the input's slope.
    let a = (-h / tau_f).exp();
    let c = h - tau_f * (1.0 - a);
    let mut y = u[0];
    let mut out = Vec::with_capacity(u.len());
    out.push(y);
    for k in 1..u.len() {
        let (u0, s) = (u[k - 1], (u[k] - u[k - 1]) / h);
        y = a * y + (1.0 - a) * u0 + s * c;
        out.push(y);
    }
    out
}

/// The low-pass of `poles` (1: [`lowpass_1pole`]; anything else: the 2-pole [`lowpass`]).
pub fn lowpass_of_order(u: &[f64], tau_f: f64, h: f64, poles: u8) -> Vec<f64> {
    if poles == 1 {
        lowpass_1pole(u, tau_f, h)
    } else {
        lowpass(u, tau_f, h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_physics::sensor::butterworth2;

    #[test]
    fn it_is_the_charge_amplifier_and_none_at_zero() {
        // A square wave at 27 Hz sampled at 10 kS/s, filtered at 300 Hz: the exact filter and the
        // rig's bilinear one agree to a small fraction of the step.
        let rate = 10_000.0;
        let f0 = 27.0;
        let omega = 2.0 * std::f64::consts::PI * f0;
        let u: Vec<f64> = (0..4000)
            .map(|i| {
                let t = i as f64 / rate;
                if (omega * t).sin() >= 0.0 {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect();
        let h = omega / rate;
        let tau_f = omega / (2.0 * std::f64::consts::PI * 300.0);
        let a = lowpass(&u, tau_f, h);
        let b = butterworth2(&u, 300.0, rate);
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.15, "exact vs bilinear: {worst}");
        let rms =
            (a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
        assert!(rms < 0.02, "rms {rms}");
        // Zero is no filter, and a tiny time constant is next to it (continuity at 0).
        assert_eq!(lowpass(&u, 0.0, h), u);
        let c = lowpass(&u, 1e-6 * h, h);
        let worst = c
            .iter()
            .zip(&u)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-4, "tiny time constant: {worst}");
        // A constant passes unchanged (settled at the first value).
        let k = lowpass(&[0.3; 50], tau_f, h);
        assert!(k.iter().all(|v| (v - 0.3).abs() < 1e-12));
    }

    #[test]
    fn the_1pole_filter_is_exact_and_none_at_zero() {
        // A ramp from rest: y(t) = s (t − τ (1 − e^{−t/τ})) exactly, at any sample interval.
        let (h, tau_f, s) = (0.07, 0.3, 2.0);
        let u: Vec<f64> = (0..200).map(|i| s * i as f64 * h).collect();
        let y = lowpass_1pole(&u, tau_f, h);
        let worst = y
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let t = i as f64 * h;
                (v - s * (t - tau_f * (1.0 - (-t / tau_f).exp()))).abs()
            })
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "ramp response off by {worst}");
        // A step settles with e^{−t/τ}.
        let mut step = vec![0.0; 100];
        step.iter_mut().skip(1).for_each(|v| *v = 1.0);
        let y = lowpass_1pole(&step, tau_f, h);
        // The step is linear over the first interval, then constant: after it, the remainder
        // decays as e^{−t/τ}.
        let r = (1.0 - y[50]) / (1.0 - y[20]);
        assert!((r - (-30.0 * h / tau_f).exp()).abs() < 1e-12, "decay {r}");
        assert_eq!(lowpass_1pole(&u, 0.0, h), u);
        let c = lowpass_1pole(&u, 1e-6 * h, h);
        let worst = c
            .iter()
            .zip(&u)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-4, "tiny time constant: {worst}");
        assert_eq!(
            lowpass_of_order(&u, tau_f, h, 1),
            lowpass_1pole(&u, tau_f, h)
        );
        assert_eq!(lowpass_of_order(&u, tau_f, h, 2), lowpass(&u, tau_f, h));
    }
}
