//! Benchmark: simulate and fit a 40 s record sampled at 10 kHz (the real rig, unloaded-like
//! light friction), then run the same fit with SciPy (`bench/scipy_fit.py`, solve_ivp +
//! least_squares) on the same CSV and print both times.
//!
//! `cargo run --release -p tribo-physics --bin physics-bench` (needs `python3` with numpy and
//! scipy for the comparison; without them the SciPy line says so).

use std::time::Instant;
use tribo_physics::identify::{fit, FitOptions, LawSpec};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec};
use tribo_physics::{FrictionLaw, Model, Record, Rig};

/// Thesis Tables 2–4: fitted constants of each law for each simulated case.
fn tables() {
    use tribo_physics::identify::fit_dimensionless;
    use tribo_physics::integrate::{grid, simulate};
    let cases = [
        [0.2, 0.0, 0.0],
        [0.0, 0.1, 0.0],
        [0.08, 0.04, 0.0],
        [0.4, -0.04, 0.0],
        [0.1, 0.04, 0.005],
        [0.904, -0.125, 0.004],
        [0.6, -0.02, -0.003],
        [0.4, -0.05, 0.0012],
        [0.6, -0.25, 0.03],
        [0.12, 0.03, -0.004],
    ];
    println!("thesis Tables 2-4 (Y0 = 10): fitted mu per law, quadratic max error, shape");
    for mu in cases {
        let law = FrictionLaw::quadratic(mu[0], mu[1], mu[2]);
        let taus = grid(6001, 0.02);
        let tr = simulate(&Model::new(law), 10.0, 0.0, &taus, Method::default()).expect("sim");
        let mut line = format!("{mu:?}:");
        for spec in [
            LawSpec::Coulomb,
            LawSpec::Viscous,
            LawSpec::CoulombViscous,
            LawSpec::Quadratic,
        ] {
            let r = fit_dimensionless(&tr.tau, &tr.y, &tr.ydot, spec, &FitOptions::default())
                .expect("fit");
            let shown: Vec<String> = spec
                .powers()
                .iter()
                .map(|&j| format!("{:.4}", r.mu[j]))
                .collect();
            line += &format!("  {} [{}] gap {:.1e}", spec.name(), shown.join(", "), r.gap);
            if spec == LawSpec::Quadratic {
                let err = (0..3).map(|j| (r.mu[j] - mu[j]).abs()).fold(0.0, f64::max);
                line += &format!(" maxerr {err:.1e} shape {}", r.shape.name());
            }
        }
        println!("{line}");
    }
}

fn main() {
    tables();
    let rig = Rig::new(0.04, 1150.0, 0.05).expect("rig");
    let mu = [0.0008, 0.0011];
    let model = Model::new(FrictionLaw::coulomb_viscous(mu[0], mu[1]));
    let spec = RecordSpec {
        rig,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 40.0,
        rate_hz: 10_000.0,
    };
    let t0 = Instant::now();
    let rec = generate(&spec, &model, Method::default(), None).expect("simulate");
    let t_sim = t0.elapsed();
    let t0 = Instant::now();
    let r = fit(&rec, LawSpec::CoulombViscous, &FitOptions::default()).expect("fit");
    let t_fit = t0.elapsed();
    println!(
        "record: {} samples (40 s at 10 kHz), true mu = {mu:?}",
        rec.len()
    );
    println!("rust  simulate: {:8.3} s", t_sim.as_secs_f64());
    println!(
        "rust  fit     : {:8.3} s  mu = {:?}  gap = {:.2e}  ({} iterations)",
        t_fit.as_secs_f64(),
        r.mu,
        r.gap,
        r.iterations
    );
    let dir = std::env::temp_dir().join(format!("tribo-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp");
    let csv = dir.join("bench.csv");
    rec.save(&csv).expect("write csv");
    // The SciPy fit needs minutes on the full record (one Python-level solve_ivp call per half
    // cycle); compare both on the first 2 s (≈ 54 cycles, 20 000 samples) as well.
    let short = Record::new(
        rec.t[..20_001].to_vec(),
        rec.x[..20_001].to_vec(),
        rec.v[..20_001].to_vec(),
        rec.rig,
        rec.units,
    );
    let t0 = Instant::now();
    let r2 = fit(&short, LawSpec::CoulombViscous, &FitOptions::default()).expect("fit");
    println!(
        "rust  fit 2 s : {:8.3} s  mu = {:?}  gap = {:.2e}",
        t0.elapsed().as_secs_f64(),
        r2.mu,
        r2.gap
    );
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/bench/scipy_fit.py");
    let seconds = std::env::args().nth(1).unwrap_or_else(|| "2".into());
    println!("(scipy on the first {seconds} s; pass `40` as argument for the full record)");
    match std::process::Command::new("python3")
        .arg(script)
        .arg(&csv)
        .arg(&seconds)
        .output()
    {
        Ok(out) if out.status.success() => print!("{}", String::from_utf8_lossy(&out.stdout)),
        Ok(out) => println!(
            "scipy : failed: {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ),
        Err(e) => println!("scipy : python3 not available ({e})"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}
