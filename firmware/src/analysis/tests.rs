use super::*;
use crate::calib;
use crate::wire::{ChannelSet, RigConstants};
use proptest::prelude::*;

/// The rig's exact motion under Coulomb + viscous friction, piecewise closed form (f64): each
/// half-cycle between velocity reversals is a damped harmonic oscillation about the shifted
/// equilibrium −r·sgn(v); at a reversal inside the static band |x| ≤ r the pin sticks for good.
struct Exact {
    omega: f64,
    sigma: f64,
    wd: f64,
    r: f64,
    t0: f64,
    x_start: f64,
    e: f64,
    stuck: bool,
    half_cycles: u32,
}

impl Exact {
    fn new(k: f64, m: f64, load: f64, mu0: f64, mu1: f64, x0: f64) -> Self {
        let omega = (k / m).sqrt();
        let zeta = mu1 / 2.0;
        let r = mu0 * load / k;
        let mut s = Self {
            omega,
            sigma: zeta * omega,
            wd: omega * (1.0 - zeta * zeta).sqrt(),
            r,
            t0: 0.0,
            x_start: x0,
            e: 0.0,
            stuck: false,
            half_cycles: 0,
        };
        s.start(x0);
        s
    }

    fn start(&mut self, x: f64) {
        self.x_start = x;
        if x.abs() <= self.r {
            self.stuck = true;
        } else {
            // moving towards zero: sgn(v) = −sgn(x); equilibrium −r sgn(v) = r sgn(x)
            self.e = self.r * x.signum();
        }
    }

    fn half(&self) -> f64 {
        PI / self.wd
    }

    /// (x, v) at time t (non-decreasing between calls).
    fn at(&mut self, t: f64) -> (f64, f64) {
        while !self.stuck && t >= self.t0 + self.half() {
            let amp = self.x_start - self.e;
            let next = self.e - amp * (-self.sigma * self.half()).exp();
            self.t0 += self.half();
            self.half_cycles += 1;
            self.start(next);
        }
        if self.stuck {
            return (self.x_start, 0.0);
        }
        let tau = t - self.t0;
        let amp = self.x_start - self.e;
        let dec = (-self.sigma * tau).exp();
        let (s, c) = (self.wd * tau).sin_cos();
        let x = self.e + amp * dec * (c + self.sigma / self.wd * s);
        let v = -amp * dec * (self.omega * self.omega / self.wd) * s;
        (x, v)
    }
}

/// Deterministic Gaussian noise (xorshift64* + Box–Muller).
struct Noise(u64);
impl Noise {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn gauss(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * PI * v).cos()
    }
}

const K: f64 = 1150.0;
const M: f64 = 0.04;
const X0: f64 = 667e-6;
const RATE: u32 = 20_000;

/// A configuration whose displacement and velocity converters span ±1.2 x0 and ±1.2 x0 Ω over
/// 16 bits, with zeros that the capture must correct (offset by a few hundred counts).
fn configure(load: f64, max_s: f32) -> Configure {
    configure_at(load, max_s, RATE)
}

/// As [`configure`], at `rate` samples a second.
fn configure_at(load: f64, max_s: f32, rate: u32) -> Configure {
    let omega = (K / M).sqrt();
    let mut calibration = [ChannelCal {
        gain: 1.0,
        zero: 0.0,
    }; 5];
    calibration[0] = calib::spanning(-1.2 * X0, 1.2 * X0).unwrap();
    calibration[1] = calib::spanning(-1.2 * X0 * omega, 1.2 * X0 * omega).unwrap();
    calibration[2] = calib::spanning(-1.0, 1.0).unwrap();
    Configure {
        rig: RigConstants {
            mass_kg: M as f32,
            stiffness_n_per_m: K as f32,
            load_n: load as f32,
        },
        sample_rate_hz: rate,
        channels: ChannelSet(0b111),
        initial_amplitude_m: X0 as f32,
        max_duration_s: max_s,
        calibration,
    }
}

struct Run {
    result: OnboardResult,
    true_half_cycles: u32,
    pipeline_half_cycles: usize,
}

/// Simulates a run (hold, release, free oscillation) with noise of `noise_lsb` converter steps on
/// both vibrometer channels, 16-bit quantisation, and true ADC offsets shifted from the
/// configured zeros; feeds the counts through the pipeline as the MCU would.
fn simulate(load: f64, mu0: f64, mu1: f64, noise_lsb: f64, seed: u64) -> Run {
    let mut p = Pipeline::new(&configure(load, 40.0)).unwrap();
    simulate_into(&mut p, load, mu0, mu1, noise_lsb, seed)
}

/// As [`simulate`], into a pipeline already configured for `configure(load, 40.0)`.
fn simulate_into(
    p: &mut Pipeline,
    load: f64,
    mu0: f64,
    mu1: f64,
    noise_lsb: f64,
    seed: u64,
) -> Run {
    simulate_into_at(p, load, mu0, mu1, noise_lsb, seed, RATE)
}

/// As [`simulate`], at `rate` samples a second.
fn simulate_at(load: f64, mu0: f64, mu1: f64, noise_lsb: f64, seed: u64, rate: u32) -> Run {
    let mut p = Pipeline::new(&configure_at(load, 40.0, rate)).unwrap();
    simulate_into_at(&mut p, load, mu0, mu1, noise_lsb, seed, rate)
}

fn simulate_into_at(
    p: &mut Pipeline,
    load: f64,
    mu0: f64,
    mu1: f64,
    noise_lsb: f64,
    seed: u64,
    rate: u32,
) -> Run {
    let cfg = configure_at(load, 40.0, rate);
    let mut truth = Exact::new(K, M, load, mu0, mu1, X0);
    let mut noise = Noise(seed | 1);
    // the converters' real zeros differ from the configured ones
    let mut real = cfg.calibration;
    real[0].zero += 211.0;
    real[1].zero -= 97.0;
    real[2].zero += 13.0;
    let count = |cal: ChannelCal, si: f64, n: &mut Noise| {
        calib::to_count(cal, si + noise_lsb * cal.gain as f64 * n.gauss()).unwrap()
    };
    for _ in 0..2000 {
        let s = [
            count(real[0], X0, &mut noise),
            count(real[1], 0.0, &mut noise),
            count(real[2], 0.0, &mut noise),
        ];
        p.capture(&s);
    }
    p.release();
    let mut i = 0u64;
    while !p.is_finished() {
        let t = i as f64 / rate as f64;
        let (x, v) = truth.at(t);
        let f = -load * mu0 * v.signum() - mu1 * M * truth.omega * v;
        let s = [
            count(real[0], x, &mut noise),
            count(real[1], v, &mut noise),
            count(real[2], f, &mut noise),
        ];
        p.push(&s);
        i += 1;
    }
    Run {
        result: p.finish(7),
        true_half_cycles: truth.half_cycles,
        pipeline_half_cycles: p.half_cycles().len(),
    }
}

/// Released without any hold sample (as `tribo onboard` does with recorded runs), the velocity
/// noise is unknown at first: the detector must measure it from the motion and arm above it.
/// Otherwise, once the pin sticks, noise of a few LSB around zero is counted as reversals — the
/// run never ends `AtRest` and the spurious half-cycles bias μ0 low and μ1 high.
#[test]
fn without_a_hold_the_velocity_noise_is_measured_from_the_motion() {
    for (seed, noise_lsb) in [(3u64, 3.0), (4, 6.0), (5, 12.0)] {
        let (load, mu0, mu1) = (0.05, 0.05, 0.0011);
        let cfg = configure(load, 40.0);
        let mut p = Pipeline::new(&cfg).unwrap();
        let mut truth = Exact::new(K, M, load, mu0, mu1, X0);
        let mut noise = Noise(seed);
        let cal = cfg.calibration;
        let count = |cal: ChannelCal, si: f64, n: &mut Noise| {
            calib::to_count(cal, si + noise_lsb * cal.gain as f64 * n.gauss()).unwrap()
        };
        p.release();
        let mut i = 0u64;
        while !p.is_finished() {
            let (x, v) = truth.at(i as f64 / RATE as f64);
            p.push(&[
                count(cal[0], x, &mut noise),
                count(cal[1], v, &mut noise),
                count(cal[2], 0.0, &mut noise),
            ]);
            i += 1;
        }
        let tag = format!("noise {noise_lsb} LSB: {:?}", p.phase());
        assert_eq!(p.phase(), Phase::Finished(StopReason::AtRest), "{tag}");
        let seen = p.half_cycles().len() as i64;
        assert!(
            (seen - truth.half_cycles as i64).abs() <= 1,
            "{tag}: {seen} half-cycles, true {}",
            truth.half_cycles
        );
        let r = p.finish(1);
        assert_eq!(r.verdict, Verdict::Ok, "{tag}: {r:?}");
        assert!((r.best.mu0 as f64 - mu0).abs() <= 0.001, "{tag}: {r:?}");
        assert!((r.best.mu1 as f64 - mu1).abs() <= 0.0002, "{tag}: {r:?}");
    }
}

/// The first reversal when the noise is not known yet: no hold, or a hold of a few samples, and
/// the pin still at rest for a few samples after the release instant (a record's release read from
/// the data is a sample or two early or late). The detector armed at 8 × one count then took the
/// noise around the release for a reversal, of either sign; one of the wrong sign hid the real
/// first reversal and the run ended `AtRest` before the second: "no oscillation (0 cycles)" on
/// records held 0.3 s at 20 kS/s and 0.5 s at 5 kS/s.
#[test]
fn the_first_reversal_is_found_whatever_the_noise_at_the_release() {
    let mut failures = Vec::new();
    for seed in 1..=24u64 {
        let noise_lsb = [2.0, 5.0, 10.0, 20.0][(seed % 4) as usize];
        let (hold, lead) = [(0, 0), (0, 3), (3, 2), (1, 6)][(seed / 4 % 4) as usize];
        let (load, mu0, mu1) = (0.05, 0.012, 0.004);
        let cfg = configure(load, 40.0);
        let mut p = Pipeline::new(&cfg).unwrap();
        let mut truth = Exact::new(K, M, load, mu0, mu1, X0);
        let mut noise = Noise(seed);
        let cal = cfg.calibration;
        let count = |cal: ChannelCal, si: f64, n: &mut Noise| {
            calib::to_count(cal, si + noise_lsb * cal.gain as f64 * n.gauss()).unwrap()
        };
        for _ in 0..hold {
            p.capture(&[
                count(cal[0], X0, &mut noise),
                count(cal[1], 0.0, &mut noise),
                count(cal[2], 0.0, &mut noise),
            ]);
        }
        p.release();
        for _ in 0..lead {
            p.push(&[
                count(cal[0], X0, &mut noise),
                count(cal[1], 0.0, &mut noise),
                count(cal[2], 0.0, &mut noise),
            ]);
        }
        let mut i = 0u64;
        while !p.is_finished() {
            let (x, v) = truth.at(i as f64 / RATE as f64);
            p.push(&[
                count(cal[0], x, &mut noise),
                count(cal[1], v, &mut noise),
                count(cal[2], 0.0, &mut noise),
            ]);
            i += 1;
        }
        let seen = p.half_cycles().len() as i64;
        let first = p.half_cycles().first().map(|h| h.peak);
        let r = p.finish(1);
        let ok = r.verdict == Verdict::Ok
            && (seen - truth.half_cycles as i64).abs() <= 1
            // the first reversal is the first minimum, half a period after the release
            && first.is_some_and(|x| x < 0.0)
            && (r.best.mu0 as f64 - mu0).abs() <= 0.001
            && (r.best.mu1 as f64 - mu1).abs() <= 0.0002;
        if !ok {
            failures.push(format!(
                "noise {noise_lsb} LSB, hold {hold}, lead {lead}: {seen} half cycles (true {}), \
                 first peak {first:?}, {} ({} cycles)",
                truth.half_cycles,
                r.verdict.name(),
                r.cycles
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The acceptance grid on the real rig: N 0.05–0.7 N, μ0 0.005–0.2, μ1 0.0011–0.03,
/// 16-bit noisy records. Runs with at least 6 true cycles must give μ0 within ±0.001 and μ1 within
/// ±0.0002 (best and both estimators); runs below 5 cycles must be refused.
#[test]
fn accuracy_over_the_rig_grid() {
    let mut worst = [(0.0f64, 0.0f64); 3];
    let mut fitted = 0;
    let mut seed = 1u64;
    for (&load, noise) in [0.05, 0.2, 0.45, 0.7]
        .iter()
        .flat_map(|l| [(l, 1.0), (l, 4.0)])
    {
        for &mu0 in &[0.005, 0.02, 0.05, 0.2] {
            for &mu1 in &[0.0011, 0.005, 0.01, 0.03] {
                seed += 1;
                let run = simulate(load, mu0, mu1, noise, seed);
                let r = run.result;
                let true_cycles = run.true_half_cycles / 2;
                let tag = format!("N={load} mu0={mu0} mu1={mu1} noise={noise} LSB: {r:?} true cycles {true_cycles}, pipeline half-cycles {}", run.pipeline_half_cycles);
                if run.true_half_cycles < MIN_HALF_CYCLES as u32 {
                    assert_eq!(r.verdict, Verdict::TooFewCycles, "{tag}");
                    assert!(r.best.mu0.is_nan(), "{tag}");
                    continue;
                }
                if run.true_half_cycles < MIN_HALF_CYCLES as u32 + 1
                    && r.verdict == Verdict::TooFewCycles
                {
                    continue; // on the boundary: the final sticking reversal may go undetected
                }
                if true_cycles < MIN_CYCLES as u32 {
                    // a short run: the peaks' fit alone, within the method's precision
                    assert_eq!(r.verdict, Verdict::Ok, "{tag}");
                    let (d0, d1) = (
                        (r.best.mu0 as f64 - mu0).abs(),
                        (r.best.mu1 as f64 - mu1).abs(),
                    );
                    assert!(d0 <= 0.001 && d1 <= 0.0002, "{tag}");
                    continue;
                }
                assert_eq!(r.verdict, Verdict::Ok, "{tag}");
                fitted += 1;
                for (k, (name, e)) in [
                    ("best", r.best),
                    ("decrement", r.decrement),
                    ("averaging", r.averaging),
                ]
                .into_iter()
                .enumerate()
                {
                    let (d0, d1) = ((e.mu0 as f64 - mu0).abs(), (e.mu1 as f64 - mu1).abs());
                    assert!(
                        d0 <= 0.001 && d1 <= 0.0002,
                        "{name}: |Δμ0| = {d0:.2e}, |Δμ1| = {d1:.2e}; {tag}"
                    );
                    if let Some(w) = worst.get_mut(k) {
                        *w = (w.0.max(d0), w.1.max(d1));
                    }
                }
                let f0 = (K / M).sqrt() / (2.0 * PI);
                assert!((r.frequency_hz as f64 / f0 - 1.0).abs() < 1e-3, "{tag}");
                assert!(
                    (r.initial_amplitude_m as f64 / X0 - 1.0).abs() < 0.01,
                    "{tag}"
                );
            }
        }
    }
    for (name, w) in ["best", "decrement", "averaging"].iter().zip(worst) {
        eprintln!(
            "grid: {fitted} runs fitted; {name}: worst |Δμ0| = {:.2e}, worst |Δμ1| = {:.2e}",
            w.0, w.1
        );
    }
    assert!(fitted >= 60);
}

#[test]
fn pure_viscous_gives_zero_coulomb_and_a_convex_envelope() {
    // the apparatus alone: μ1 = 0.0011, no contact friction; load only scales y
    let run = simulate(0.2, 0.0, 0.0011, 1.0, 99);
    let r = run.result;
    assert_eq!(r.verdict, Verdict::Ok, "{r:?}");
    assert!(
        r.best.mu0.abs() < 1e-3 && (r.best.mu1 - 0.0011).abs() < 2e-4,
        "{r:?}"
    );
    assert_eq!(r.shape, EnvelopeShape::Convex, "{r:?}");
}

#[test]
fn coulomb_dominated_envelope_is_straight_and_viscous_one_convex() {
    // Coulomb only: F(A) = a0, straight; strong viscous: convex
    let run = simulate(0.05, 0.05, 0.0, 1.0, 5);
    assert_eq!(
        run.result.shape,
        EnvelopeShape::Straight,
        "{:?}",
        run.result
    );
    assert!((run.result.best.mu1).abs() < 2e-4);
    let run = simulate(0.2, 0.005, 0.03, 1.0, 6);
    assert_eq!(run.result.shape, EnvelopeShape::Convex, "{:?}", run.result);
}

/// Viscous + quadratic friction (no Coulomb term, so no sticking), integrated by RK4: the
/// quadratic term fitted alongside recovers the averaging law's a2 = −4 μ2 / (3π) and the
/// envelope is convex.
#[test]
fn curvature_recovers_a_quadratic_friction_term() {
    let (load, mu1, mu2) = (0.2, 0.002, 0.004);
    let mut p = Pipeline::new(&configure(load, 6.0)).unwrap();
    let omega = (K / M).sqrt();
    let accel = |x: f64, v: f64| {
        let yd = v * K / (load * omega);
        (-K * x - load * (mu1 * yd + mu2 * yd * yd.abs())) / M
    };
    let cal = configure(load, 6.0).calibration;
    let mut noise = Noise(77);
    let count = |c: ChannelCal, si: f64, n: &mut Noise| {
        calib::to_count(c, si + c.gain as f64 * n.gauss()).unwrap()
    };
    for _ in 0..1000 {
        p.capture(&[
            count(cal[0], X0, &mut noise),
            count(cal[1], 0.0, &mut noise),
            32768,
        ]);
    }
    p.release();
    let (mut x, mut v) = (X0, 0.0);
    let h = 1.0 / RATE as f64;
    while !p.is_finished() {
        p.push(&[
            count(cal[0], x, &mut noise),
            count(cal[1], v, &mut noise),
            32768,
        ]);
        let (k1x, k1v) = (v, accel(x, v));
        let (k2x, k2v) = (
            v + 0.5 * h * k1v,
            accel(x + 0.5 * h * k1x, v + 0.5 * h * k1v),
        );
        let (k3x, k3v) = (
            v + 0.5 * h * k2v,
            accel(x + 0.5 * h * k2x, v + 0.5 * h * k2v),
        );
        let (k4x, k4v) = (v + h * k3v, accel(x + h * k3x, v + h * k3v));
        x += h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
        v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
    }
    let r = p.finish(3);
    let a2 = -4.0 * mu2 / (3.0 * PI);
    eprintln!(
        "quadratic law: a2 {} (averaging law {a2:.3e}), {:?}, {} cycles",
        r.curvature, r.verdict, r.cycles
    );
    assert!(
        (r.curvature as f64 / a2 - 1.0).abs() < 0.15,
        "a2 {} vs {a2}: {r:?}",
        r.curvature
    );
    assert_eq!(r.shape, EnvelopeShape::Convex, "{r:?}");
}

/// Runs of 4 to 9 half-cycles (too short for the averaging fit) are analysed from their peaks
/// alone, with a ± that means it: over rates of 2–20 kS/s, noise of 0–50 converter steps (0 and
/// 0.3: the rounding not dithered), and contacts from Coulomb-only to viscous, z = (estimate −
/// truth)/σ has an sd near 1 and 90 % or more of the estimates lie within 2σ. Fails if the peaks
/// keep their vertex-offset bias (sd(z) of μ1 ≫ 1 at 2 kS/s), if the ± is the regression's
/// textbook one, if an undithered peak's ± is its residuals' alone (sd(z) 1.56, 86 % at 0–0.3
/// steps), or if such runs are refused.
#[test]
fn short_runs_are_analysed_from_their_peaks_with_a_true_error() {
    let mut z: [std::vec::Vec<f64>; 2] = Default::default();
    let mut analysed = 0;
    let mut seed = 500u64;
    for &rate in &[2_000u32, 5_000, 20_000] {
        for &noise in &[0.0, 0.3, 1.0, 5.0, 15.0, 50.0] {
            // r = μ0 N / k against x0 = 667 µm: 4–9 half-cycles
            for &(mu0, mu1) in &[(0.13, 0.002), (0.1, 0.01), (0.08, 0.0), (0.06, 0.02)] {
                for _ in 0..6 {
                    seed += 2; // the noise takes `seed | 1`
                    let run = simulate_at(0.7, mu0, mu1, noise, seed, rate);
                    let r = run.result;
                    let tag = format!(
                        "{rate}/s noise {noise} μ0 {mu0} μ1 {mu1}: {r:?}, {} half-cycles",
                        run.true_half_cycles
                    );
                    if run.true_half_cycles < MIN_HALF_CYCLES as u32 + 1 {
                        continue;
                    }
                    assert!(run.true_half_cycles < 2 * MIN_CYCLES as u32, "{tag}");
                    assert_eq!(r.verdict, Verdict::Ok, "{tag}");
                    assert!(r.averaging.mu0.is_nan(), "{tag}");
                    analysed += 1;
                    for (j, (est, se, truth)) in [
                        (r.best.mu0, r.best.mu0_se, mu0),
                        (r.best.mu1, r.best.mu1_se, mu1),
                    ]
                    .into_iter()
                    .enumerate()
                    {
                        z[j].push((est as f64 - truth) / se as f64);
                    }
                }
            }
        }
    }
    for (name, z) in ["mu0", "mu1"].iter().zip(&z) {
        let n = z.len() as f64;
        let sd = (z.iter().map(|z| z * z).sum::<f64>() / n).sqrt();
        let within = z.iter().filter(|z| z.abs() <= 2.0).count() as f64 / n;
        eprintln!(
            "short runs: {name}: {n} runs, sd(z) {sd:.2}, within 2σ {:.0} %",
            100.0 * within
        );
        // measured: sd(z) 0.93 / 0.91, 95 / 97 % (1.26 and 89 % with the vertex but not the
        // decay fitted, 2.2 and 65 % with the symmetric peak fit about the nearest sample)
        assert!(
            (0.8..=1.2).contains(&sd) && within >= 0.9,
            "{name}: sd(z) {sd:.2}, {:.0} % within 2σ",
            100.0 * within
        );
    }
    assert!(analysed >= 200, "{analysed}");
}

#[test]
fn fewer_than_four_half_cycles_is_refused() {
    // r = 0.2·0.7/1150 = 122 µm: 667 µm lasts 3 half-cycles
    let run = simulate(0.7, 0.2, 0.01, 1.0, 3);
    assert!(run.true_half_cycles < MIN_HALF_CYCLES as u32);
    assert_eq!(
        run.result.verdict,
        Verdict::TooFewCycles,
        "{:?}",
        run.result
    );
    assert!(run.result.best.mu0.is_nan() && run.result.best.mu1.is_nan());
    assert!(
        (run.result.frequency_hz - 26.97).abs() < 0.1,
        "{:?}",
        run.result
    );
}

#[test]
fn standard_errors_are_consistent_with_the_scatter() {
    // same physics, different noise: the spread of μ1 across seeds is comparable to the SE
    let mut vals = [0.0f64; 6];
    let mut se = 0.0f64;
    for (i, v) in vals.iter_mut().enumerate() {
        let r = simulate(0.05, 0.005, 0.01, 3.0, 100 + i as u64).result;
        *v = r.decrement.mu1 as f64;
        se = se.max(r.decrement.mu1_se as f64);
    }
    let mean = vals.iter().sum::<f64>() / 6.0;
    let sd = (vals.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / 5.0).sqrt();
    assert!(se > 0.0 && sd < 5.0 * se, "scatter {sd:.2e} vs SE {se:.2e}");
}

/// The end-of-run analysis spread over steps of any size gives exactly the one-call result
/// (bit for bit, NaNs included), and a step never takes more rows than it is allowed.
#[test]
fn finish_in_steps_equals_finish_in_one_call() {
    let bits = |r: &OnboardResult| {
        let e = |e: &Estimate| [e.mu0, e.mu1, e.mu0_se, e.mu1_se].map(f32::to_bits);
        (
            (r.run_id, r.verdict, r.cycles, r.shape),
            [
                r.frequency_hz,
                r.initial_amplitude_m,
                r.duration_s,
                r.curvature,
            ]
            .map(f32::to_bits),
            [e(&r.best), e(&r.averaging), e(&r.decrement)],
        )
    };
    // Ok, too few cycles, and a run refused mid-way (no motion at all).
    let runs = [
        (0.05, 0.005, 0.01, 1.0, 21),
        (0.7, 0.2, 0.01, 1.0, 22),
        (0.2, 0.0, 0.0011, 4.0, 23),
    ];
    for (load, mu0, mu1, noise, seed) in runs {
        let mut p = Pipeline::new(&configure(load, 40.0)).unwrap();
        let one = simulate_into(&mut p, load, mu0, mu1, noise, seed).result;
        for rows in [1u32, 7, 64] {
            let mut job = p.start_finish(7);
            let mut steps = 0u32;
            let stepped = loop {
                steps += 1;
                if let Some(r) = p.finish_step(&mut job, rows) {
                    break r;
                }
                assert!(steps < 1_000_000, "never finished");
            };
            assert!(job.is_done());
            assert_eq!(
                bits(&stepped),
                bits(&one),
                "{rows} rows per step: {stepped:?}"
            );
            // 36 passes over the half-cycles at most, so the steps are bounded accordingly
            let half_cycles = p.half_cycles().len() as u32;
            assert!(steps <= 36 * (half_cycles + 1) / rows + 37, "{steps} steps");
        }
    }
    let quiet = Pipeline::new(&configure(0.2, 1.0)).unwrap();
    let mut job = quiet.start_finish(1);
    assert_eq!(
        quiet.finish_step(&mut job, 1).map(|r| r.verdict),
        Some(Verdict::NoOscillation)
    );
}

#[test]
fn reset_reuses_the_pipeline_with_identical_results() {
    let mut p = Pipeline::new(&configure(0.7, 40.0)).unwrap();
    let first = simulate_into(&mut p, 0.7, 0.05, 0.03, 1.0, 11).result;
    assert!(p.is_finished());
    p.reset(&configure(0.2, 40.0)).unwrap();
    assert_eq!(p.phase(), Phase::Holding);
    assert!(p.half_cycles().is_empty());
    let again = simulate_into(&mut p, 0.2, 0.02, 0.005, 1.0, 12).result;
    let fresh = simulate(0.2, 0.02, 0.005, 1.0, 12).result;
    assert_eq!(again, fresh);
    assert_ne!(first, fresh);
    // a refused configuration leaves the pipeline as it was
    let mut bad = configure(0.2, 40.0);
    bad.rig.mass_kg = -1.0;
    assert_eq!(p.reset(&bad), Err(ConfigError::Mass));
    assert_eq!(p.finish(7), fresh);
}

#[test]
fn nonsense_constants_are_refused() {
    let good = configure(0.2, 10.0);
    assert!(Pipeline::new(&good).is_ok());
    let mut c = good;
    c.rig.mass_kg = f32::NAN;
    assert_eq!(Pipeline::new(&c).err(), Some(ConfigError::Mass));
    let mut c = good;
    c.rig.stiffness_n_per_m = -1.0;
    assert_eq!(Pipeline::new(&c).err(), Some(ConfigError::Stiffness));
    let mut c = good;
    c.rig.load_n = 0.0;
    assert_eq!(Pipeline::new(&c).err(), Some(ConfigError::Load));
    let mut c = good;
    c.sample_rate_hz = 0;
    assert_eq!(Pipeline::new(&c).err(), Some(ConfigError::SampleRate));
    let mut c = good;
    c.sample_rate_hz = 100;
    assert_eq!(Pipeline::new(&c).err(), Some(ConfigError::Undersampled));
    let mut c = good;
    c.channels = ChannelSet(0b101);
    assert_eq!(
        Pipeline::new(&c).err(),
        Some(ConfigError::MissingChannel(Channel::Velocity))
    );
    let mut c = good;
    c.calibration[0].gain = 0.0;
    assert_eq!(
        Pipeline::new(&c).err(),
        Some(ConfigError::Calibration(Channel::Displacement))
    );
    let mut c = good;
    c.max_duration_s = f32::INFINITY;
    assert_eq!(Pipeline::new(&c).err(), Some(ConfigError::MaxDuration));
}

#[test]
fn capture_sets_zeros_so_the_hold_reads_x0() {
    let cfg = configure(0.2, 1.0);
    let mut p = Pipeline::new(&cfg).unwrap();
    for i in 0..100u16 {
        p.capture(&[40000 + i % 2, 30000, 31000]);
    }
    p.release();
    assert!(
        (p.to_si(Channel::Displacement, 40000) as f64 - X0).abs()
            < 0.6 * cfg.calibration[0].gain as f64
    );
    assert!(p.to_si(Channel::Velocity, 30000).abs() < 1e-9);
    assert!(p.to_si(Channel::Force, 31000).abs() < 1e-9);
    // a sample vector too short is counted, not indexed
    p.push(&[1]);
    assert_eq!(p.rejected(), 1);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]
    /// Garbage counts, saturated rails and short vectors never panic, and what comes out is either
    /// a refusal or finite numbers.
    #[test]
    fn garbage_never_panics(
        hold in proptest::collection::vec(any::<u16>(), 0..60),
        body in proptest::collection::vec((any::<u16>(), any::<u16>(), 0u8..4), 0..6000),
    ) {
        let mut p = Pipeline::new(&configure(0.3, 0.5)).unwrap();
        for c in hold.chunks(3) {
            p.capture(c);
        }
        for (x, v, mode) in body {
            let s = match mode {
                0 => [x, v, 0],
                1 => [if x % 2 == 0 { 0 } else { u16::MAX }, v, x],
                2 => [x, ((v as u32 * 7) % 65536) as u16, v],
                _ => [x / 2 + 16384, if v % 64 < 32 { 60000 } else { 5000 }, 0],
            };
            let n = if mode == 3 && x % 5 == 0 { 1 } else { 3 };
            p.push(s.get(..n).unwrap_or(&s));
        }
        let r = p.finish(1);
        let numbers = [r.best.mu0, r.best.mu1, r.best.mu0_se, r.best.mu1_se];
        prop_assert!(r.verdict != Verdict::Ok || numbers.iter().all(|v| v.is_finite()), "{r:?}");
    }

    /// A square-wave velocity at the natural frequency with saturated displacement is flagged.
    #[test]
    fn saturated_displacement_is_flagged(period in 700u32..800) {
        let mut p = Pipeline::new(&configure(0.3, 1.0)).unwrap();
        for i in 0..20_000u32 {
            let phase = i % period;
            let v = if phase < period / 2 { 60000 } else { 5000 };
            let x = if phase < period / 2 { u16::MAX } else { 0 };
            p.push(&[x, v, 0]);
            if p.is_finished() { break; }
        }
        let r = p.finish(2);
        prop_assert!(r.verdict != Verdict::Ok, "{r:?}");
    }
}
