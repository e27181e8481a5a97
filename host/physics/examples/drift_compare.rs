//! The drift check's fast search beside the exhaustive one on records given as CSV files:
//! `cargo run --release -p tribo-physics --example drift_compare -- LAW FILE…` (LAW: quadratic,
//! coulomb-viscous, …). Prints both trends and their times.

use std::time::Instant;
use tribo_physics::identify::{fit, mu0_trend, mu0_trend_exhaustive, FitOptions, LawSpec};
use tribo_physics::record::Record;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let law: LawSpec = args
        .next()
        .ok_or("usage: drift_compare LAW FILE…")?
        .parse()?;
    for path in args {
        let rec = Record::from_csv_str(&std::fs::read_to_string(&path)?)?;
        let r = fit(&rec, law, &FitOptions::default())?;
        let t0 = Instant::now();
        let fast = mu0_trend(&rec, &r);
        let t1 = Instant::now();
        let exh = mu0_trend_exhaustive(&rec, &r);
        let t2 = Instant::now();
        println!("{path}");
        for (name, t, dt) in [("fast", fast, t1 - t0), ("exhaustive", exh, t2 - t1)] {
            match t {
                Some(t) => println!(
                    "  {name:<10} {:+.6e} ± {:.6e} (z {:.3}, {}) in {:.3} s",
                    t.relative_change,
                    t.relative_change_se,
                    t.z,
                    if t.significant { "drift" } else { "no drift" },
                    dt.as_secs_f64()
                ),
                None => println!("  {name:<10} no trend in {:.3} s", dt.as_secs_f64()),
            }
        }
    }
    Ok(())
}
