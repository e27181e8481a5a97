//! The on-board pipeline over the bench grid (`shared/docs/real-bench.md`), beside the host fit on
//! the same records.
//!
//! Records made as a lab bench makes them (`tribo_physics::bench`): holds before the release,
//! seconds at rest after the stop, vibrometer noise ×1 … ×50 of the simulator's default, 16-bit
//! channels, 2–20 kS/s, the 20 and 45 Hz ends of the rig range, Coulomb–viscous contacts from
//! 3 half cycles to hundreds of cycles. Each record goes through `tribo onboard`'s code path (the
//! firmware's pipeline, the release read from the data) and through `tribo fit`'s estimator.
//! Prints, per noise level and for each of the two: the records analysed and refused (by verdict),
//! coverage (truth within 2σ) and sd(z) of μ0 and μ1, z = (estimate − truth) / σ (1 when the ±
//! means what it says). The on-board result shown is the averaging estimator's; the decrement
//! estimator's line (its ± is only used to tell whether the two agree, and errs wide) is printed
//! for the record.
//!
//! Grid per seed: 4 noise levels × 4 contacts (μ0 0.002 … 0.1, 5 to 220 cycles) × 2 rigs × 4
//! rates (2, 5, 10, 20 kS/s) × 4 holds (0, 0.3, 2, 5 s) = 512 records.
//!
//! `cargo run --release -p tribo --example onboard_grid -- [--seeds N] [--verbose]`

use std::collections::BTreeMap;
use tribo::onboard::analyse;
use tribo_physics::bench::{rigs, Bench, BenchRecord, NOISE_LEVELS};
use tribo_physics::identify::{fit, FitOptions, LawSpec};
use tribo_physics::sensor::SensorModel;
use tribo_physics::{FrictionLaw, Model};
use tribo_wire::Verdict;

/// Coulomb–viscous contacts (μ0, μ1, load N, seconds after the release).
const CONTACTS: [(&str, f64, f64, f64); 4] = [
    ("cv-0.002", 0.002, 0.006, 0.3),
    ("cv-0.012", 0.012, 0.004, 0.05),
    ("cv-0.02", 0.02, 0.01, 0.3),
    ("cv-0.1", 0.1, 0.002, 0.7),
];
const RATES: [f64; 4] = [2_000.0, 5_000.0, 10_000.0, 20_000.0];
const HOLDS: [f64; 4] = [0.0, 0.3, 2.0, 5.0];

#[derive(Default)]
struct Tally {
    n: usize,
    refused: BTreeMap<String, usize>,
    z: [Vec<f64>; 2],
}

impl Tally {
    fn add(&mut self, est: Option<([f64; 2], [f64; 2])>, truth: [f64; 2], why: &str) {
        self.n += 1;
        match est {
            Some((mu, se)) => {
                for j in 0..2 {
                    self.z[j].push((mu[j] - truth[j]) / se[j]);
                }
            }
            None => *self.refused.entry(why.to_string()).or_default() += 1,
        }
    }
    fn line(&self, who: &str, level: &str) -> String {
        let stat = |z: &[f64]| {
            let n = z.len().max(1) as f64;
            let inside = z.iter().filter(|z| z.abs() <= 2.0).count() as f64 / n;
            let sd = (z.iter().map(|z| z * z).sum::<f64>() / n).sqrt();
            (100.0 * inside, sd)
        };
        let (c0, s0) = stat(&self.z[0]);
        let (c1, s1) = stat(&self.z[1]);
        let refused: Vec<String> = self
            .refused
            .iter()
            .map(|(k, v)| format!("{k} {v}"))
            .collect();
        format!(
            "{level:<5} {who:<8} {:>4} {:>5} {:>7.0}% {:>6.2} {:>7.0}% {:>6.2}  {}",
            self.n,
            self.z[0].len(),
            c0,
            s0,
            c1,
            s1,
            refused.join(", ")
        )
    }
}

fn main() {
    let (mut seeds, mut verbose) = (2u64, false);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seeds" => seeds = args.next().and_then(|s| s.parse().ok()).expect("--seeds N"),
            "--verbose" => verbose = true,
            other => panic!("unknown argument {other}"),
        }
    }
    let mut onboard: Vec<Tally> = NOISE_LEVELS.iter().map(|_| Tally::default()).collect();
    let mut host: Vec<Tally> = NOISE_LEVELS.iter().map(|_| Tally::default()).collect();
    let mut dec: Vec<Tally> = NOISE_LEVELS.iter().map(|_| Tally::default()).collect();
    let mut k = 0;
    for (li, noise) in NOISE_LEVELS.iter().enumerate() {
        for &(cname, mu0, mu1, load) in &CONTACTS {
            for (rig_name, rig) in rigs(load) {
                for &rate in &RATES {
                    for &held in &HOLDS {
                        for seed in 0..seeds {
                            k += 1;
                            let law = FrictionLaw::coulomb_viscous(mu0, mu1);
                            let x0 = 667e-6;
                            let rec = BenchRecord {
                                rig,
                                model: Model::new(law.clone()),
                                x0_m: x0,
                                after_release_s: tribo_physics::bench::after_release_s(
                                    &rig, &law, x0, 1.0,
                                ),
                                rate_hz: rate,
                                sensor: SensorModel {
                                    disp_noise_m: noise.disp_m,
                                    vel_noise_m_s: noise.vel_m_s,
                                    seed: 1 + seed * 7919 + k as u64,
                                    ..SensorModel::default()
                                },
                                bench: Bench {
                                    held_s: held,
                                    ..Bench::default()
                                },
                            }
                            .make()
                            .expect("record");
                            let truth = [mu0, mu1];
                            let name = format!(
                                "{} {cname} {rig_name} {rate} Hz held {held} s seed {seed}",
                                noise.name
                            );
                            match analyse(&rec) {
                                Ok(r) if r.verdict == Verdict::Ok => {
                                    let e = r.decrement;
                                    dec[li].add(
                                        Some((
                                            [e.mu0 as f64, e.mu1 as f64],
                                            [e.mu0_se as f64, e.mu1_se as f64],
                                        )),
                                        truth,
                                        "",
                                    );
                                    let b = r.best;
                                    let mu = [b.mu0 as f64, b.mu1 as f64];
                                    let se = [b.mu0_se as f64, b.mu1_se as f64];
                                    let z0 = (mu[0] - mu0) / se[0];
                                    let z1 = (mu[1] - mu1) / se[1];
                                    if verbose && (z0.abs() > 3.0 || z1.abs() > 3.0) {
                                        eprintln!("onboard miss {name}: z {z0:.1} {z1:.1} {r:?}");
                                    }
                                    onboard[li].add(Some((mu, se)), truth, "");
                                }
                                Ok(r) => {
                                    if verbose {
                                        eprintln!(
                                            "onboard {name}: {} ({} cycles)",
                                            r.verdict.name(),
                                            r.cycles
                                        );
                                    }
                                    onboard[li].add(None, truth, r.verdict.name());
                                }
                                Err(e) => {
                                    eprintln!("onboard {name}: error {e:#}");
                                    onboard[li].add(None, truth, "error");
                                }
                            }
                            match fit(&rec, LawSpec::CoulombViscous, &FitOptions::default()) {
                                Ok(f) => host[li].add(
                                    Some(([f.mu[0], f.mu[1]], [f.mu_se[0], f.mu_se[1]])),
                                    truth,
                                    "",
                                ),
                                Err(e) => {
                                    if verbose {
                                        eprintln!("host {name}: {e}");
                                    }
                                    host[li].add(None, truth, "refused")
                                }
                            }
                        }
                    }
                }
            }
        }
        eprintln!("{} done ({k} records)", noise.name);
    }
    println!(
        "{:<5} {:<8} {:>4} {:>5} {:>8} {:>6} {:>8} {:>6}  refused",
        "noise", "who", "recs", "fits", "μ0 2σ", "sd(z)", "μ1 2σ", "sd(z)"
    );
    for (li, noise) in NOISE_LEVELS.iter().enumerate() {
        println!("{}", onboard[li].line("on-board", noise.name));
        println!("{}", host[li].line("host", noise.name));
        println!("{}", dec[li].line("(decr.)", noise.name));
    }
}
