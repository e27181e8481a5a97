//! An independent generator of rig records for the explain tests: its own SI equations and its own
//! integrator (fixed-step RK4 with located velocity reversals), sharing no code with the models
//! `tribo explain` fits — only the acquisition chain (noise, 16-bit quantisation, the charge
//! amplifier's 300 Hz low-pass) comes from `tribo-physics`' sensor model, as it does on the rig.
//!
//! The contact: `m x'' + c x' + k x + k3 x³ = −F`, where the friction force `F` follows
//! `F_ss(v, t) = sgn(v) N [μ0(t) + μ2 (v/V)² + (μs − μ0) e^{−(v/vs)²}] + N μ1 v / V` (V = NΩ/k, the
//! velocity unit of the dimensionless law) either at once or with a memory time T
//! (`T dF/dt = F_ss − F`); μ0 may depend on the plane temperature `T(t) = T0 + ΔT (1 − e^{−t/τ_h})`
//! and may differ between the two sliding directions, and may drift in time (running-in,
//! `μ0 + r t`, or settling first order towards a new level).
#![allow(dead_code)]

pub mod bench;
pub mod lhs;

use tribo_physics::record::{Record, Units};
use tribo_physics::sensor::SensorModel;
use tribo_physics::Rig;

/// What the contact does.
#[derive(Debug, Clone, PartialEq)]
pub struct Contact {
    pub mu0: f64,
    pub mu1: f64,
    /// Quadratic term μ2 (dimensionless law).
    pub mu2: f64,
    /// Static level μs and Stribeck velocity vs (dimensionless); `None` = no Stribeck rise.
    pub stribeck: Option<(f64, f64)>,
    /// Memory time of the friction force (s); 0 = none.
    pub memory_s: f64,
    /// Cubic spring k3 (N/m³).
    pub k3: f64,
    /// dμ0/dT (per °C) and the temperature rise ΔT (°C) with its time constant τ_h (s).
    pub thermal: Option<(f64, f64, f64)>,
    /// Coulomb level when sliding towards negative x, if it differs from μ0 (direction-dependent
    /// friction, outside the explain vocabulary).
    pub mu0_backward: Option<f64>,
    /// Running-in: dμ0/dt (per second) at constant temperature, μ0(t) = μ0 + rate · t.
    pub running_in_per_s: f64,
}

impl Contact {
    pub fn coulomb_viscous(mu0: f64, mu1: f64) -> Contact {
        Contact {
            mu0,
            mu1,
            mu2: 0.0,
            stribeck: None,
            memory_s: 0.0,
            k3: 0.0,
            thermal: None,
            mu0_backward: None,
            running_in_per_s: 0.0,
        }
    }
}

/// The record: the real rig (m = 0.04 kg, k = 1150 N/m), load `load_n`, released at rest from
/// 667 µm, `duration_s` at 10 kHz; `chain` = the acquisition chain (`None`: ideal channels, the
/// true force, no temperature noise).
pub fn record(c: &Contact, load_n: f64, duration_s: f64, chain: Option<&SensorModel>) -> Record {
    let (m, k, n) = (0.04f64, 1150.0f64, load_n);
    let rig = Rig::new(m, k, n).unwrap();
    let omega = (k / m).sqrt();
    let vunit = n * omega / k; // m/s per unit of y'
    let rate = 10_000.0;
    let samples = (duration_s * rate).round() as usize + 1;
    let sub = 40usize; // RK4 steps per sample
    let h = 1.0 / rate / sub as f64;
    let temp_at = |t: f64| match c.thermal {
        Some((_, dt, tau_h)) => 40.0 + dt * (1.0 - (-t / tau_h).exp()),
        None => 40.0,
    };
    let mu0_at = |t: f64, dir: f64| {
        let base = match (dir < 0.0, c.mu0_backward) {
            (true, Some(b)) => b,
            _ => c.mu0,
        };
        let base = base + c.running_in_per_s * t;
        match c.thermal {
            Some((g, _, _)) => base + g * (temp_at(t) - 40.0),
            None => base,
        }
    };
    // Steady friction force (N) on the branch `dir`.
    let f_ss = |v: f64, t: f64, dir: f64| {
        let u = v / vunit;
        let mut level = mu0_at(t, dir) + c.mu2 * u * u;
        if let Some((mus, vs)) = c.stribeck {
            level += (mus - c.mu0) * (-(u / vs).powi(2)).exp();
        }
        n * (dir * level + c.mu1 * u)
    };
    let lag = c.memory_s > 0.0;
    // State [x, v, F]; F is only a state with memory.
    let rhs = |s: [f64; 3], t: f64, dir: f64| -> [f64; 3] {
        let f = if lag { s[2] } else { f_ss(s[1], t, dir) };
        let a = -(k * s[0] + c.k3 * s[0].powi(3) + f) / m;
        let df = if lag {
            (f_ss(s[1], t, dir) - s[2]) / c.memory_s
        } else {
            0.0
        };
        [s[1], a, df]
    };
    let rk4 = |s: [f64; 3], t: f64, h: f64, dir: f64| -> [f64; 3] {
        let add =
            |a: [f64; 3], b: [f64; 3], w: f64| [a[0] + w * b[0], a[1] + w * b[1], a[2] + w * b[2]];
        let k1 = rhs(s, t, dir);
        let k2 = rhs(add(s, k1, h / 2.0), t + h / 2.0, dir);
        let k3 = rhs(add(s, k2, h / 2.0), t + h / 2.0, dir);
        let k4 = rhs(add(s, k3, h), t + h, dir);
        [
            s[0] + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            s[1] + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
            s[2] + h / 6.0 * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
        ]
    };
    let x0 = 667e-6;
    let mut s = [x0, 0.0, 0.0];
    let mut dir = -1.0; // released towards the equilibrium
    let mut stuck = false;
    let mut t = 0.0;
    let (mut ts, mut xs, mut vs, mut fs, mut st) = (vec![], vec![], vec![], vec![], vec![]);
    let force_now = |s: [f64; 3], t: f64, dir: f64, stuck: bool| {
        if stuck {
            -(k * s[0] + c.k3 * s[0].powi(3))
        } else if lag {
            s[2]
        } else {
            f_ss(s[1], t, dir)
        }
    };
    for i in 0..samples {
        let ti = i as f64 / rate;
        while t < ti - 1e-12 && !stuck {
            let step = h.min(ti - t);
            let next = rk4(s, t, step, dir);
            if dir * next[1] < 0.0 {
                // Locate the reversal by bisection on the step length.
                let (mut lo, mut hi) = (0.0, step);
                for _ in 0..50 {
                    let mid = 0.5 * (lo + hi);
                    if dir * rk4(s, t, mid, dir)[1] < 0.0 {
                        hi = mid;
                    } else {
                        lo = mid;
                    }
                }
                s = rk4(s, t, hi, dir);
                s[1] = 0.0;
                t += hi;
                let spring = k * s[0] + c.k3 * s[0].powi(3);
                // The pin stays when the spring cannot overcome the static friction, the steady
                // law's level at rest (with memory too: at rest the contact holds like a Coulomb
                // one).
                let dir_new = -spring.signum();
                let static_level =
                    mu0_at(t, dir_new) + c.stribeck.map_or(0.0, |(mus, _)| mus - c.mu0);
                let hold = spring.abs() <= n * static_level;
                if hold {
                    stuck = true;
                } else {
                    dir = if lag {
                        -(spring + s[2]).signum()
                    } else {
                        -spring.signum()
                    };
                }
            } else {
                s = next;
                t += step;
            }
        }
        ts.push(ti);
        xs.push(s[0]);
        vs.push(if stuck { 0.0 } else { s[1] });
        fs.push(force_now(s, ti, dir, stuck));
        st.push(stuck);
    }
    let mut rec = Record::new(ts, xs, vs, Some(rig), Units::Si);
    match chain {
        Some(ch) => ch.apply(&mut rec, &fs, &st),
        None => rec.ft = Some(fs),
    }
    if c.thermal.is_some() {
        let noise = chain.map_or(0.0, |_| 0.05);
        let mut rng = tribo_physics::sensor::Rng::new(chain.map_or(0, |c| c.seed) ^ 0x7e);
        rec.temp = Some(
            rec.t
                .iter()
                .map(|&t| temp_at(t) + noise * rng.normal())
                .collect(),
        );
    }
    rec
}

/// The real acquisition chain with noise seed `seed`.
pub fn chain(seed: u64) -> SensorModel {
    SensorModel {
        seed,
        ..SensorModel::default()
    }
}
