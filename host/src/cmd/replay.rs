//! `tribo replay RUN`: a recorded run fed back through the firmware's pipeline and the simulator
//! ([`crate::replay`]), and where the replayed results differ from the recorded ones.

use crate::replay::{compare, envelope_vs_simulation, replay_pipeline};
use std::path::PathBuf;
use tribo_store::Run;

/// Arguments of `tribo replay`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run folder.
    pub run: PathBuf,
    /// Relative difference of μ0/μ1 reported as a discrepancy.
    #[arg(long, default_value_t = 1e-4)]
    pub tol: f64,
}
/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.run.is_dir() {
        // The store's own error ("not a run folder"), not a CSV reader's.
        Run::open(&args.run)?;
    }
    // The one loader: the run and its samples as recorded (a run that is not whole as far as it
    // goes), with the store's warnings about it.
    let opened = crate::load::open(&args.run, crate::Holes::Keep)?;
    let (rec, run) = match opened.run {
        Some(run) => (opened.record, run),
        None => anyhow::bail!("{} is not a run folder", args.run.display()),
    };
    let c = run.completeness();
    // An incomplete run is replayed as far as it goes, said so, and ends with exit status 3.
    let incomplete = (!c.is_complete()).then(|| {
        crate::exit::Incomplete(format!(
            "run {} is {}: the replay covers what is stored only; `tribo pull {}` fetches the rest while the \
             rig holds it",
            run.id(),
            c.summary(),
            args.run.display()
        ))
    });
    println!("{}: {}", run.id(), c.summary());
    if run.config().rig.load_n == 0.0 {
        // The apparatus alone: the rig's analysis does not run on it (its friction coefficients
        // are undefined); its damping, fitted by the host, is simulated instead.
        println!(
            "the apparatus alone (load 0): the on-board analysis does not run on it, nothing to \
             replay through the pipeline"
        );
        let Some(mu_a) = run.host_fit().map(|h| h.mu1).filter(|m| m.is_finite()) else {
            println!("no fitted apparatus damping to simulate (`tribo fit` the run first)");
            return incomplete.map_or(Ok(()), |i| Err(i.into()));
        };
        return simulate_and_compare(&rec, 0.0, mu_a, incomplete);
    }
    let replayed = match replay_pipeline(&run) {
        Ok(r) => r,
        Err(e) => {
            let e = e.context("replaying through the firmware pipeline");
            return Err(match incomplete {
                Some(i) => anyhow::Error::new(i).context(format!("{e:#}")),
                None => e,
            });
        }
    };
    println!(
        "replayed {} blocks of {} through the firmware pipeline{}",
        run.block_count(),
        run.id(),
        if incomplete.is_some() {
            " (an incomplete run: the replayed result is not the whole run's)"
        } else {
            ""
        }
    );
    match run.result() {
        None => {
            println!("the run holds no on-board result to compare with (aborted or incomplete?)")
        }
        Some(recorded) => {
            let d = compare(recorded, &replayed, args.tol);
            if d.is_empty() {
                println!(
                    "on-board result reproduced: every field equal (relative tolerance {:e})",
                    args.tol
                );
            } else {
                println!(
                    "{} fields differ (relative tolerance {:e}):",
                    d.len(),
                    args.tol
                );
                println!("  {:<18} {:>16} {:>16}", "field", "recorded", "replayed");
                for x in &d {
                    println!("  {:<18} {:>16} {:>16}", x.field, x.recorded, x.replayed);
                }
                println!(
                    "  (the log has no hold samples: the replay stands in for them with the run's last samples, at \
                     rest; a run that ended moving has none, and its zeros are the nominal ones)"
                );
            }
        }
    }
    let (mu0, mu1) = match (run.host_fit(), run.result()) {
        (Some(h), _) => (h.mu0, h.mu1),
        (None, Some(r)) => (r.best.mu0 as f64, r.best.mu1 as f64),
        _ => (replayed.best.mu0 as f64, replayed.best.mu1 as f64),
    };
    if !(mu0.is_finite() && mu1.is_finite() && mu0 >= 0.0 && mu1 >= 0.0) {
        println!("no usable μ0/μ1 to simulate (μ0 = {mu0}, μ1 = {mu1})");
        return incomplete.map_or(Ok(()), |i| Err(i.into()));
    }
    simulate_and_compare(&rec, mu0, mu1, incomplete)
}

/// The envelope against the simulated Coulomb–viscous law, per cycle, and the exit status.
fn simulate_and_compare(
    rec: &tribo_physics::Record,
    mu0: f64,
    mu1: f64,
    incomplete: Option<crate::exit::Incomplete>,
) -> anyhow::Result<()> {
    let rows = envelope_vs_simulation(rec, mu0, mu1)?;
    let a0 = rows.first().map_or(1.0, |r| r.2.max(1e-12));
    println!(
        "envelope vs the simulated Coulomb–viscous law (μ0 = {mu0:.5}, μ1 = {mu1:.5}), per cycle:"
    );
    println!(
        "  {:>5} {:>8} {:>12} {:>12} {:>9}",
        "cycle", "t (s)", "recorded µm", "simulated µm", "Δ/A0"
    );
    let mut first_off = None;
    for (c, t, a, s) in &rows {
        let rel = (a - s) / a0;
        if rel.abs() > 0.02 && first_off.is_none() {
            first_off = Some((*c, *t));
        }
        if c % 5 == 0 || rows.len() < 30 {
            println!(
                "  {:>5} {:>8.3} {:>12.2} {:>12.2} {:>+9.4}",
                c,
                t,
                a * 1e6,
                s * 1e6,
                rel
            );
        }
    }
    match first_off {
        None => println!("the recorded envelope stays within 2 % of A0 of the simulated one over the whole run"),
        Some((c, t)) => println!(
            "the recorded envelope leaves the simulated one (> 2 % of A0) from cycle {c} (t = {t:.3} s): the \
             Coulomb–viscous law stops describing the contact there; try `tribo fit --law quadratic` or windowed fits"
        ),
    }
    incomplete.map_or(Ok(()), |i| Err(i.into()))
}
