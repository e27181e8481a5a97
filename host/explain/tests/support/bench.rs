//! The independent generator for any rig of the README's range (`shared/docs/real-bench.md`): its
//! own SI equations and its own integrator (fixed-step RK4 with velocity reversals located by
//! bisection), sharing no code with the models `tribo explain` fits. Only the acquisition chain's
//! noise, 16-bit quantisation and fractional delay come from `tribo-physics`' sensor model, as on
//! the rig; the force channel's filter (none, 1-pole, or the charge amplifier's 2-pole
//! Butterworth) is applied here.
//!
//! The contact, from the release (time `t` from the release, `x` from the spring's rest):
//!
//! `m x'' + k x + k3 x³ = −F`, with the steady friction force
//! `F_ss = N(x) [ d (μ0(t, x, d) + μ2 (v/V)² + (μs − μ0) e^{−(|v|/vs)^δ}) + μ1 v/V ]`,
//! `d` the sliding direction, `V = N Ω / k` the velocity unit of the dimensionless law,
//! reached either at once or through a memory time `T` (`T dF/dt = F_ss − F`). The Coulomb level
//! `μ0(t, x, d) = μ0 ± a/2 (forward/backward) + drift(t) + γ (T_plate(t) − T_plate(0))`
//! `+ μ0 s e^{−((x − x_s)/w)²}` (a worn stripe), and the load `N(x) = N (1 + g x / x0)` (a load
//! that varies along the track). The pin sticks at a reversal when the spring cannot overcome the
//! static level (`μ0 + (μs − μ0)` at rest) times the load.
#![allow(dead_code)]

use tribo_physics::record::{Record, Units};
use tribo_physics::sensor::SensorModel;
use tribo_physics::Rig;

/// Running-in (μ0 drifting in time at constant temperature).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RunningIn {
    /// `μ0 + r t` (r per second).
    Linear { per_s: f64 },
    /// `μ0 + Δ (1 − e^{−t/τ})`.
    FirstOrder { delta: f64, tau_s: f64 },
}

/// What the contact does (SI unless said).
#[derive(Debug, Clone, PartialEq)]
pub struct Friction {
    pub mu0: f64,
    /// Viscous term of the dimensionless law (either sign).
    pub mu1: f64,
    /// Quadratic term of the dimensionless law.
    pub mu2: f64,
    /// Stribeck: static level μs (absolute), speed vs (m/s), exponent δ.
    pub stribeck: Option<(f64, f64, f64)>,
    /// Memory time of the friction force (s); 0 = none.
    pub memory_s: f64,
    /// Cubic spring k3 (N/m³), either sign.
    pub k3: f64,
    /// Thermal: dμ0/dT (per K), the plate's change ΔT (K) and its time constant (s).
    pub thermal: Option<(f64, f64, f64)>,
    pub running_in: Option<RunningIn>,
    /// Forward (v > 0) minus backward Coulomb level.
    pub asymmetry: f64,
    /// A worn stripe: centre (m), half-width (m), relative change of μ0 on it.
    pub stripe: Option<(f64, f64, f64)>,
    /// Relative change of the load per release amplitude of displacement (`N(x) = N(1 + g x/x0)`).
    pub load_tilt: f64,
}

impl Friction {
    pub fn coulomb_viscous(mu0: f64, mu1: f64) -> Friction {
        Friction {
            mu0,
            mu1,
            mu2: 0.0,
            stribeck: None,
            memory_s: 0.0,
            k3: 0.0,
            thermal: None,
            running_in: None,
            asymmetry: 0.0,
            stripe: None,
            load_tilt: 0.0,
        }
    }
}

/// The force channel's analog filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Filter {
    None,
    OnePole(f64),
    TwoPole(f64),
}

/// The rig, the run and the acquisition chain.
#[derive(Debug, Clone, PartialEq)]
pub struct Bench {
    pub mass_kg: f64,
    pub stiffness_n_per_m: f64,
    pub load_n: f64,
    /// Release amplitude (m).
    pub x0_m: f64,
    pub rate_hz: f64,
    /// Held by the magnet before the release (s).
    pub hold_s: f64,
    /// At rest after the stop (s) — the record ends earlier if it reaches `max_s`.
    pub rest_s: f64,
    /// Longest record (s).
    pub max_s: f64,
    pub filter: Filter,
    /// Whether the header states the filter's cut-off (a 2-pole filter only: the header says a
    /// cut-off, read as the charge amplifier's 2-pole filter).
    pub filter_stated: bool,
    pub disp_noise_m: f64,
    pub vel_noise_m_s: f64,
    pub force_noise_n: f64,
    /// Pure delay of the force channel (s).
    pub sensor_delay_s: f64,
    /// Temperature channel noise (°C).
    pub temp_noise_c: f64,
    pub seed: u64,
}

impl Bench {
    /// The real rig at 10 kS/s, 667 µm, no hold, 2-pole 300 Hz stated.
    pub fn rig() -> Bench {
        Bench {
            mass_kg: 0.04,
            stiffness_n_per_m: 1150.0,
            load_n: 0.3,
            x0_m: 667e-6,
            rate_hz: 10_000.0,
            hold_s: 0.0,
            rest_s: 0.5,
            max_s: 25.0,
            filter: Filter::TwoPole(300.0),
            filter_stated: true,
            disp_noise_m: 2e-8,
            vel_noise_m_s: 2e-5,
            force_noise_n: 2e-4,
            sensor_delay_s: 0.0,
            temp_noise_c: 0.05,
            seed: 1,
        }
    }

    pub fn omega(&self) -> f64 {
        (self.stiffness_n_per_m / self.mass_kg).sqrt()
    }

    /// Velocity unit of the dimensionless law (m/s).
    pub fn v_unit(&self) -> f64 {
        self.load_n * self.omega() / self.stiffness_n_per_m
    }

    /// Rough duration of the motion (s): Coulomb decay of the release amplitude by 4 μ0 N / k a
    /// cycle (for sizing strengths "over a run").
    pub fn motion_estimate_s(&self, mu0: f64) -> f64 {
        let per_cycle = 4.0 * mu0 * self.load_n / self.stiffness_n_per_m;
        let cycles = self.x0_m / per_cycle;
        let f = self.omega() / (2.0 * std::f64::consts::PI);
        (cycles / f).min(self.max_s - self.hold_s - self.rest_s)
    }
}

/// Truth the generator records beside the record.
#[derive(Debug, Clone, PartialEq)]
pub struct Truth {
    /// Time the motion stopped, from the record's start (s; `None` = still moving at the end).
    pub stop_s: Option<f64>,
    /// Duration of the motion (s).
    pub motion_s: f64,
}

/// One record and its truth.
pub fn generate(c: &Friction, b: &Bench) -> (Record, Truth) {
    let (m, k, n) = (b.mass_kg, b.stiffness_n_per_m, b.load_n);
    let rig = Rig::new(m, k, n).unwrap();
    let vunit = b.v_unit();
    let rate = b.rate_hz;
    let t0c = 25.0;
    let temp_at = |t: f64| match c.thermal {
        Some((_, dt, tau_h)) => t0c + dt * (1.0 - (-t.max(0.0) / tau_h).exp()),
        None => t0c,
    };
    let mu0_at = |t: f64, x: f64, dir: f64| {
        let mut mu = c.mu0 + 0.5 * dir * c.asymmetry;
        match c.running_in {
            Some(RunningIn::Linear { per_s }) => mu += per_s * t,
            Some(RunningIn::FirstOrder { delta, tau_s }) => {
                mu += delta * (1.0 - (-t / tau_s).exp())
            }
            None => {}
        }
        if let Some((g, _, _)) = c.thermal {
            mu += g * (temp_at(t) - t0c);
        }
        if let Some((xc, w, s)) = c.stripe {
            mu += c.mu0 * s * (-((x - xc) / w).powi(2)).exp();
        }
        mu
    };
    let load_at = |x: f64| n * (1.0 + c.load_tilt * x / b.x0_m);
    let f_ss = |x: f64, v: f64, t: f64, dir: f64| {
        let u = v / vunit;
        let mut level = mu0_at(t, x, dir) + c.mu2 * u * u;
        if let Some((mus, vs, delta)) = c.stribeck {
            level += (mus - c.mu0) * (-(v.abs() / vs).powf(delta)).exp();
        }
        load_at(x) * (dir * level + c.mu1 * u)
    };
    let lag = c.memory_s > 0.0;
    let spring = |x: f64| k * x + c.k3 * x.powi(3);
    let rhs = |s: [f64; 3], t: f64, dir: f64| -> [f64; 3] {
        let f = if lag { s[2] } else { f_ss(s[0], s[1], t, dir) };
        let a = -(spring(s[0]) + f) / m;
        let df = if lag {
            (f_ss(s[0], s[1], t, dir) - s[2]) / c.memory_s
        } else {
            0.0
        };
        [s[1], a, df]
    };
    let rk4 = |s: [f64; 3], t: f64, h: f64, dir: f64| -> [f64; 3] {
        let add =
            |a: [f64; 3], d: [f64; 3], w: f64| [a[0] + w * d[0], a[1] + w * d[1], a[2] + w * d[2]];
        let k1 = rhs(s, t, dir);
        let k2 = rhs(add(s, k1, h / 2.0), t + h / 2.0, dir);
        let k3 = rhs(add(s, k2, h / 2.0), t + h / 2.0, dir);
        let k4 = rhs(add(s, k3, h), t + h, dir);
        let mut o = [0.0; 3];
        for i in 0..3 {
            o[i] = s[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        o
    };
    // Step: ≤ 10 µs (ω h ≤ 3e-3 on a 45 Hz rig) and ≤ a tenth of the memory time.
    let mut h_max = 1e-5f64;
    if lag {
        h_max = h_max.min(c.memory_s / 10.0);
    }
    let sub = (1.0 / (rate * h_max)).ceil().max(1.0);
    let h = 1.0 / rate / sub;
    let max_samples = (b.max_s * rate).round() as usize + 1;
    let mut s = [b.x0_m, 0.0, 0.0];
    let mut dir = -spring(b.x0_m).signum();
    let mut stuck = false;
    let mut stop_s: Option<f64> = None;
    let mut end_sample = max_samples;
    let mut t = 0.0; // from the release
    let (mut ts, mut xs, mut vs, mut fs, mut st) = (vec![], vec![], vec![], vec![], vec![]);
    let force_now = |s: [f64; 3], t: f64, dir: f64, stuck: bool| {
        if stuck {
            -spring(s[0])
        } else if lag {
            s[2]
        } else {
            f_ss(s[0], s[1], t, dir)
        }
    };
    let mut i = 0usize;
    while i < end_sample {
        let tr = i as f64 / rate; // record time
        let ti = tr - b.hold_s; // from the release
        if ti < 0.0 {
            // Held by the magnet: the magnet carries the spring; no friction force.
            ts.push(tr);
            xs.push(b.x0_m);
            vs.push(0.0);
            fs.push(0.0);
            st.push(true);
            i += 1;
            continue;
        }
        while t < ti - 1e-12 && !stuck {
            let step = h.min(ti - t);
            let next = rk4(s, t, step, dir);
            if dir * next[1] < 0.0 {
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
                let sp = spring(s[0]);
                let dir_new = -sp.signum();
                let static_level =
                    mu0_at(t, s[0], dir_new) + c.stribeck.map_or(0.0, |(mus, _, _)| mus - c.mu0);
                if sp.abs() <= load_at(s[0]) * static_level {
                    stuck = true;
                    stop_s = Some(t + b.hold_s);
                    let rest_end = ((t + b.hold_s + b.rest_s) * rate).ceil() as usize + 1;
                    end_sample = end_sample.min(rest_end.max(i + 1));
                } else {
                    dir = if lag { -(sp + s[2]).signum() } else { dir_new };
                }
            } else {
                s = next;
                t += step;
            }
        }
        ts.push(tr);
        xs.push(s[0]);
        vs.push(if stuck { 0.0 } else { s[1] });
        fs.push(force_now(s, ti, dir, stuck));
        st.push(stuck);
        i += 1;
    }
    let motion_s = stop_s.map_or(t, |e| e - b.hold_s);
    let mut rec = Record::new(ts, xs, vs, Some(rig), Units::Si);
    let dt = 1.0 / rate;
    let filtered = match b.filter {
        Filter::None => fs.clone(),
        Filter::TwoPole(fc) => tribo_physics::sensor::butterworth2(&fs, fc, rate),
        Filter::OnePole(fc) => one_pole(&fs, fc, dt),
    };
    let chain = SensorModel {
        disp_noise_m: b.disp_noise_m,
        vel_noise_m_s: b.vel_noise_m_s,
        force_noise_n: b.force_noise_n,
        bits: Some(16),
        disp_range_m: 1e-3,
        vel_range_m_s: 0.25,
        force_range_n: 1.0,
        force_cutoff_hz: None,
        force_lag_s: b.sensor_delay_s,
        thermal: None,
        ecr: None,
        seed: b.seed,
    };
    chain.apply(&mut rec, &filtered, &st);
    rec.force_cutoff_hz = match (b.filter, b.filter_stated) {
        (Filter::TwoPole(fc), true) => Some(fc),
        _ => None,
    };
    let mut rng = tribo_physics::sensor::Rng::new(b.seed ^ 0x7e57);
    rec.temp = Some(
        rec.t
            .iter()
            .map(|&t| temp_at(t - b.hold_s) + b.temp_noise_c * rng.normal())
            .collect(),
    );
    (rec, Truth { stop_s, motion_s })
}

/// A 1-pole low-pass `y' = ω_c (u − y)`, exact for an input linear between samples, at rest at 0.
pub fn one_pole(u: &[f64], fc: f64, dt: f64) -> Vec<f64> {
    let w = 2.0 * std::f64::consts::PI * fc;
    let a = (-w * dt).exp();
    let mut y = 0.0;
    let mut out = Vec::with_capacity(u.len());
    let mut prev = u.first().copied().unwrap_or(0.0);
    for &ui in u {
        let slope = (ui - prev) / dt;
        y = a * y + ui - a * prev - slope / w * (1.0 - a);
        prev = ui;
        out.push(y);
    }
    out
}
