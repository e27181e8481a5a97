//! Where a fit's time goes: times `fit` of a CSV record, then one simulation of its envelope at
//! the fitted constants (the mean of 5), with its integration steps, and says how many such
//! simulations the fit's time would hold.
//! `cargo run --release -p tribo-physics --example fit_steps -- LAW FILE`
use std::time::Instant;
use tribo_physics::identify::{fit, motion_span, EnvelopeData, FitOptions, LawSpec};
use tribo_physics::integrate::Simulator;
use tribo_physics::model::Model;
use tribo_physics::record::Record;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let law: LawSpec = args.next().ok_or("usage: LAW FILE")?.parse()?;
    let path = args.next().ok_or("usage: LAW FILE")?;
    let rec = Record::from_csv_str(&std::fs::read_to_string(&path)?)?;
    let opts = FitOptions::default();
    let t0 = Instant::now();
    let r = fit(&rec, law, &opts)?;
    let tf = t0.elapsed().as_secs_f64();
    println!(
        "fit {tf:.3} s, {} iterations, mu {:?} y0 {}",
        r.iterations, r.mu, r.y0
    );
    let (tau, y, ydot) = rec.dimensionless()?;
    let span = motion_span(&tau, &y, &ydot);
    let data = EnvelopeData::over(&tau, &y, &ydot, &span, opts.max_points)?;
    let model = Model::new(r.friction_law());
    let t1 = Instant::now();
    let reps = 5;
    let mut steps = 0;
    for _ in 0..reps {
        let mut sim = Simulator::new(model.clone(), data.y0, data.ydot0, opts.method);
        for &t in &data.tau {
            sim.step_to(t)?;
        }
        steps = sim.steps();
    }
    let ts = t1.elapsed().as_secs_f64() / reps as f64;
    println!(
        "one simulation: {} points, τ_end {:.1}, {steps} steps, {:.2} ms ({:.1} ns/step); fit ≈ {:.1} simulations' time",
        data.tau.len(),
        data.tau.last().unwrap(),
        ts * 1e3,
        ts * 1e9 / steps as f64,
        tf / ts
    );
    Ok(())
}
