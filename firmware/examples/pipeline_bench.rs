//! Cost of the on-board analysis per sample, on the host.
//!
//! Runs the [`Pipeline`] over a 40 s, 20 kS/s, 5-channel record of the unloaded apparatus (viscous
//! μ1 = 0.0011 plus a trace of Coulomb friction, the longest run the rig makes) and prints the wall
//! time per sample, the time of `finish`, and `size_of::<Pipeline>()` (its static RAM).
//!
//! ```text
//! cargo build --release -p tribo-firmware --example pipeline_bench
//! valgrind --tool=callgrind --toggle-collect='*pipeline_bench*feed*' \
//!     target/release/examples/pipeline_bench     # instructions of the per-sample path only
//! ```
//! Divide the collected instruction count by the sample count the program prints.
use std::hint::black_box;
use std::time::Instant;
use tribo_firmware::analysis::Pipeline;
use tribo_firmware::calib;
use tribo_firmware::wire::{ChannelCal, ChannelSet, Configure, RigConstants};

const RATE: u32 = 20_000;
const SECONDS: f64 = 40.0;

/// Piecewise closed-form Coulomb + viscous motion: (x, v) at every sample.
fn record(k: f64, m: f64, load: f64, mu0: f64, mu1: f64, x0: f64) -> Vec<(f64, f64)> {
    let omega = (k / m).sqrt();
    let sigma = 0.5 * mu1 * omega;
    let wd = (omega * omega - sigma * sigma).sqrt();
    let r = mu0 * load / k;
    let half = std::f64::consts::PI / wd;
    let (mut t0, mut xs) = (0.0, x0);
    let mut stuck = x0.abs() <= r;
    let n = (SECONDS * RATE as f64) as usize;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let t = i as f64 / RATE as f64;
        let mut e = r * xs.signum();
        while !stuck && t >= t0 + half {
            xs = e - (xs - e) * (-sigma * half).exp();
            t0 += half;
            stuck = xs.abs() <= r;
            e = r * xs.signum();
        }
        if stuck {
            out.push((xs, 0.0));
            continue;
        }
        let tau = t - t0;
        let (s, c) = (wd * tau).sin_cos();
        let d = (-sigma * tau).exp();
        out.push((
            e + (xs - e) * d * (c + sigma / wd * s),
            -(xs - e) * d * omega * omega / wd * s,
        ));
    }
    out
}

#[inline(never)]
fn feed(p: &mut Pipeline, samples: &[[u16; 5]]) -> u32 {
    for s in samples {
        p.push(s);
    }
    p.samples()
}

fn main() {
    let (k, m, load, x0) = (1150.0, 0.04, 0.05, 667e-6);
    let omega = f64::sqrt(k / m);
    let mut calibration = [ChannelCal {
        gain: 1.0,
        zero: 0.0,
    }; 5];
    calibration[0] = calib::spanning(-1.2 * x0, 1.2 * x0).unwrap();
    calibration[1] = calib::spanning(-1.2 * x0 * omega, 1.2 * x0 * omega).unwrap();
    calibration[2] = calib::spanning(-1.0, 1.0).unwrap();
    calibration[3] = calib::spanning(0.0, 10.0).unwrap();
    calibration[4] = calib::spanning(0.0, 150.0).unwrap();
    let cfg = Configure {
        rig: RigConstants {
            mass_kg: m as f32,
            stiffness_n_per_m: k as f32,
            load_n: load as f32,
        },
        sample_rate_hz: RATE,
        channels: ChannelSet(0b1_1111),
        initial_amplitude_m: x0 as f32,
        max_duration_s: SECONDS as f32,
        calibration,
    };
    // dither of about one step on every channel (deterministic)
    let mut seed = 0x9E37_79B9_7F4A_7C15u64;
    let mut dither = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let motion = record(k, m, load, 1e-4, 0.0011, x0);
    let samples: Vec<[u16; 5]> = motion
        .iter()
        .map(|&(x, v)| {
            let c = |i: usize, si: f64, d: f64| {
                calib::to_count(calibration[i], si + d * calibration[i].gain as f64).unwrap()
            };
            [
                c(0, x, dither()),
                c(1, v, dither()),
                c(2, -0.0011 * m * omega * v, dither()),
                c(3, 7.0, dither()),
                c(4, 25.0, dither()),
            ]
        })
        .collect();
    let mut p = Pipeline::new(&cfg).expect("valid configuration");
    for _ in 0..2000 {
        p.capture(&[
            calib::to_count(calibration[0], x0).unwrap(),
            32768,
            32768,
            45875,
            11141,
        ]);
    }
    p.release();
    let t = Instant::now();
    let n = feed(&mut p, black_box(&samples));
    let per_sample = t.elapsed().as_secs_f64() / n.max(1) as f64;
    let t = Instant::now();
    let r = black_box(p.finish(1));
    let finish = t.elapsed().as_secs_f64();
    println!(
        "samples analysed: {n} of {} ({:?})",
        samples.len(),
        p.phase()
    );
    println!("per sample: {:.1} ns (host wall time)", per_sample * 1e9);
    println!(
        "finish: {:.3} ms over {} half-cycles",
        finish * 1e3,
        p.half_cycles().len()
    );
    println!(
        "size_of::<Pipeline>() = {} bytes",
        std::mem::size_of::<Pipeline>()
    );
    println!(
        "result: {:?} cycles {} f {:.3} Hz mu0 {:.5} mu1 {:.6} (truth mu0 {:.5}, mu1 0.0011)",
        r.verdict, r.cycles, r.frequency_hz, r.best.mu0, r.best.mu1, 1e-4
    );
}
