//! The bench grid (`shared/docs/real-bench.md`): records made the way a lab bench makes them (held
//! before the release, seconds at rest after the stop, vibrometer noise from the simulator's
//! default to the noisiest bench, 16-bit channels) over contacts from μ0 = 1e-4 to 0.1, 20 and
//! 35 Hz rigs and 2–20 kS/s, each fitted by `tribo fit`'s estimator. Prints, per noise level and
//! contact: coverage (truth within 2σ, every constant), the worst bias in σ, the verdicts, and the
//! fit time.
//!
//! `cargo run --release -p tribo-physics --example bench_grid -- [--seeds N] [--held S] [--rest S]`

use std::collections::BTreeMap;
use std::time::Instant;
use tribo_physics::bench::grid;
use tribo_physics::identify::{fit, FitOptions, FitVerdict, LawSpec};

#[derive(Default)]
struct Cell {
    fits: usize,
    inside: usize,
    constants: usize,
    z: Vec<Vec<f64>>,
    adequate: usize,
    failed: usize,
    secs: f64,
}

fn main() {
    let mut seeds = 2u64;
    let mut held = 0.5;
    let mut rest = 1.0;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut val = || {
            args.next()
                .and_then(|s| s.parse::<f64>().ok())
                .expect("a number")
        };
        match a.as_str() {
            "--seeds" => seeds = val() as u64,
            "--held" => held = val(),
            "--rest" => rest = val(),
            other => panic!("unknown argument {other}"),
        }
    }
    let cases = grid(1..1 + seeds, held, rest);
    eprintln!("{} records", cases.len());
    let mut cells: BTreeMap<(usize, String), Cell> = BTreeMap::new();
    let levels: Vec<&str> = tribo_physics::bench::NOISE_LEVELS
        .iter()
        .map(|n| n.name)
        .collect();
    for (k, c) in cases.iter().enumerate() {
        let rec = c.record.make().expect("record");
        let truth = c.contact.law.mu().expect("polynomial").to_vec();
        let spec = if truth.len() == 3 {
            LawSpec::Quadratic
        } else {
            LawSpec::CoulombViscous
        };
        let li = levels.iter().position(|n| *n == c.noise.name).unwrap();
        let cell = cells.entry((li, c.contact.name.to_string())).or_default();
        let t0 = Instant::now();
        let r = fit(&rec, spec, &FitOptions::default());
        cell.secs += t0.elapsed().as_secs_f64();
        match r {
            Ok(r) => {
                cell.fits += 1;
                let mut all = true;
                let mut zs = Vec::new();
                for (j, t) in truth.iter().enumerate() {
                    let z = (r.mu[j] - t) / r.mu_se[j];
                    zs.push(z);
                    if z.is_nan() || z.abs() > 2.0 {
                        all = false;
                    }
                }
                cell.constants += truth.len();
                cell.inside += zs.iter().filter(|z| z.abs() <= 2.0).count();
                cell.z.push(zs);
                if r.verdict == FitVerdict::Adequate {
                    cell.adequate += 1;
                }
                if !all && std::env::var_os("GRID_VERBOSE").is_some() {
                    eprintln!(
                        "miss {} {} {} {} Hz: mu {:?} ± {:?} truth {:?} verdict {} span {:?}",
                        c.noise.name,
                        c.contact.name,
                        c.rig_name,
                        c.record.rate_hz,
                        r.mu,
                        r.mu_se,
                        truth,
                        r.verdict.name(),
                        r.span
                    );
                }
            }
            Err(e) => {
                cell.failed += 1;
                eprintln!(
                    "{} {} {} {} Hz: {e}",
                    c.noise.name, c.contact.name, c.rig_name, c.record.rate_hz
                );
            }
        }
        if (k + 1) % 40 == 0 {
            eprintln!("{} / {}", k + 1, cases.len());
        }
    }
    println!(
        "{:<6} {:<9} {:>5} {:>9} {:>10} {:>7} {:>9} {:>7} {:>8}",
        "noise",
        "contact",
        "fits",
        "within2σ",
        "max|bias|σ",
        "sd(z)",
        "adequate",
        "failed",
        "s/fit"
    );
    let (mut tot_c, mut tot_in, mut tot_fit, mut tot_ad) = (0, 0, 0, 0);
    for ((li, name), c) in &cells {
        let np = c.z.first().map_or(0, Vec::len);
        let bias = (0..np)
            .map(|j| {
                let v: Vec<f64> = c.z.iter().map(|z| z[j]).filter(|z| z.is_finite()).collect();
                (v.iter().sum::<f64>() / v.len().max(1) as f64).abs()
            })
            .fold(0.0, f64::max);
        let zs: Vec<f64> =
            c.z.iter()
                .flatten()
                .copied()
                .filter(|z| z.is_finite())
                .collect();
        let sdz = (zs.iter().map(|z| z * z).sum::<f64>() / zs.len().max(1) as f64).sqrt();
        println!(
            "{:<6} {:<9} {:>5} {:>8.0}% {:>10.2} {:>7.2} {:>8.0}% {:>7} {:>8.3}",
            levels[*li],
            name,
            c.fits,
            100.0 * c.inside as f64 / c.constants.max(1) as f64,
            bias,
            sdz,
            100.0 * c.adequate as f64 / c.fits.max(1) as f64,
            c.failed,
            c.secs / (c.fits + c.failed).max(1) as f64
        );
        tot_c += c.constants;
        tot_in += c.inside;
        tot_fit += c.fits;
        tot_ad += c.adequate;
    }
    println!(
        "all: {} records, constants within 2σ {:.1}%, adequate {:.1}%",
        cases.len(),
        100.0 * tot_in as f64 / tot_c.max(1) as f64,
        100.0 * tot_ad as f64 / tot_fit.max(1) as f64
    );
}
