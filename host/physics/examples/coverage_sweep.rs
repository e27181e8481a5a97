//! A larger sweep than the coverage test: how often the true constants lie within 2 standard errors
//! of the fitted ones, over many seeded noisy repeats of one case.
//!
//! `cargo run --release -p tribo-physics --example coverage_sweep -- LOAD_N MU0 MU1 [MU2] --seeds 200`
//! (MU2 selects the quadratic law; the duration is 1 s at 10 kHz, the default sensor chain).

use tribo_physics::identify::{fit, FitOptions, LawSpec};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Model, Rig};

fn main() {
    let mut nums = Vec::new();
    let mut seeds = 100u64;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if a == "--seeds" {
            seeds = args.next().and_then(|s| s.parse().ok()).expect("--seeds N");
        } else {
            nums.push(a.parse::<f64>().expect("a number"));
        }
    }
    let load = nums.first().copied().unwrap_or(0.3);
    let truth: Vec<f64> = if nums.len() > 1 {
        nums[1..].to_vec()
    } else {
        vec![0.02, 0.01]
    };
    let (law, spec) = match truth.len() {
        2 => (
            FrictionLaw::coulomb_viscous(truth[0], truth[1]),
            LawSpec::CoulombViscous,
        ),
        3 => (
            FrictionLaw::quadratic(truth[0], truth[1], truth[2]),
            LawSpec::Quadratic,
        ),
        _ => panic!("give MU0 MU1 [MU2]"),
    };
    let mut inside = vec![0usize; truth.len()];
    let mut sq = vec![0.0f64; truth.len()];
    let mut se_sum = vec![0.0f64; truth.len()];
    let mut verdicts = std::collections::BTreeMap::new();
    let mut ratios = Vec::new();
    for seed in 1..=seeds {
        let rs = RecordSpec {
            rig: Rig::new(0.04, 1150.0, load).unwrap(),
            x0_m: 667e-6,
            v0_m_s: 0.0,
            duration_s: 1.0,
            rate_hz: 10_000.0,
        };
        let s = SensorModel {
            seed,
            ..SensorModel::default()
        };
        let rec = generate(
            &rs,
            &Model::new(law.clone()),
            Method::dopri(1e-10),
            Some(&s),
        )
        .unwrap();
        let r = fit(&rec, spec, &FitOptions::default()).unwrap();
        *verdicts.entry(r.verdict.name()).or_insert(0) += 1;
        ratios.push(r.gap_ratio());
        for j in 0..truth.len() {
            let e = r.mu[j] - truth[j];
            inside[j] += usize::from(e.abs() <= 2.0 * r.mu_se[j]);
            sq[j] += e * e;
            se_sum[j] += r.mu_se[j];
        }
    }
    ratios.sort_by(f64::total_cmp);
    println!(
        "load {load} N, truth {truth:?}, {seeds} seeds, verdicts {verdicts:?}, gap / noise floor \
         {:.3} .. {:.3} (median {:.3})",
        ratios[0],
        ratios[ratios.len() - 1],
        ratios[ratios.len() / 2]
    );
    for j in 0..truth.len() {
        println!(
            "mu{j}: {}/{seeds} within 2 SE ({:.1} %); RMS error {:.3e}, mean SE {:.3e}",
            inside[j],
            100.0 * inside[j] as f64 / seeds as f64,
            (sq[j] / seeds as f64).sqrt(),
            se_sum[j] / seeds as f64
        );
    }
}
