//! A recorded run replayed (`tribo replay RUN`): feeds its sample frames back through the firmware's analysis
//! pipeline and through the simulator, and reports where the replayed results differ from the
//! recorded ones.
//!
//! * Pipeline: the very `tribo_firmware::analysis::Pipeline` the rig ran, fed the logged counts in
//!   order. Its result should equal the one the rig sent unless the firmware changed (or the run is
//!   incomplete). The samples the rig captured while the magnet held the pin (which set the zeros
//!   and the noise thresholds) are not in the log; [`hold_capture`] stands in for them with the
//!   run's last samples, at rest, which reproduces the rig's result on the virtual rig.
//! * Simulator: the Coulomb–viscous law the rig found (μ0, μ1) is simulated from the run's first
//!   sample, and the Mark & Crandall envelopes are compared cycle by cycle: where the recorded
//!   envelope leaves the simulated one, the law stops describing the contact.

use crate::firmware::analysis::{Phase, Pipeline};
use anyhow::{bail, Context};
use tribo_physics::envelope::mark_crandall;
use tribo_physics::identify::FitOptions;
use tribo_physics::{simulate, FrictionLaw, Model, Record};
use tribo_store::Run;
use tribo_wire::{Estimate, OnboardResult};

/// Samples taken as the emulated hold capture.
const HOLD_SAMPLES: usize = 64;
/// Largest spread of the velocity counts over those samples for the pin to count as at rest: about
/// ten times the noise of the thesis's rig (~2.6 counts rms; 64 samples span ~5 rms), while a pin
/// released from the magnet changes it by ~100 counts per 0.1 ms.
const HOLD_COUNTS: u16 = 24;

/// Samples standing in for the hold capture the log lacks: the run's last samples, where the pin
/// rests (velocity zero, sensor noise only), with the displacement moved to the first sample's
/// (the held position) and every other channel to its calibrated zero, keeping their noise.
pub fn hold_capture(run: &Run) -> Vec<Vec<u16>> {
    let cfg = run.config();
    let ch: Vec<tribo_wire::Channel> = cfg.channels.iter().collect();
    let all: Vec<&[u16]> = run
        .blocks()
        .flat_map(|b| (0..b.samples()).filter_map(move |i| b.sample(i)))
        .collect();
    let (Some(first), true) = (all.first(), all.len() > 2 * HOLD_SAMPLES) else {
        return vec![];
    };
    let tail = &all[all.len() - HOLD_SAMPLES..];
    let Some(pv) = cfg.channels.position(tribo_wire::Channel::Velocity) else {
        return vec![];
    };
    // Only if the pin is at rest there: the velocity stays within a few noise counts.
    let vmin = tail.iter().map(|s| s[pv]).min().unwrap_or(0);
    let vmax = tail.iter().map(|s| s[pv]).max().unwrap_or(u16::MAX);
    if vmax - vmin > HOLD_COUNTS {
        return vec![];
    }
    let mean: Vec<f64> = (0..ch.len())
        .map(|k| tail.iter().map(|s| s[k] as f64).sum::<f64>() / tail.len() as f64)
        .collect();
    tail.iter()
        .map(|s| {
            ch.iter()
                .enumerate()
                .map(|(k, c)| {
                    let target = match c {
                        tribo_wire::Channel::Velocity => return s[k],
                        tribo_wire::Channel::Displacement => first[k] as f64,
                        _ => cfg.calibration[c.index()].zero as f64,
                    };
                    (target + s[k] as f64 - mean[k]).round().clamp(0.0, 65535.0) as u16
                })
                .collect()
        })
        .collect()
}

/// One field that differs between the recorded and replayed on-board results.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    /// The on-board result's name.
    pub field: String,
    /// Its value as recorded by the rig.
    pub recorded: String,
    /// Its value from the replay.
    pub replayed: String,
}

/// Runs the firmware pipeline over the run's logged samples.
pub fn replay_pipeline(run: &Run) -> anyhow::Result<OnboardResult> {
    let cfg = run.config();
    let mut p = Pipeline::new(&cfg).context("the run's configuration")?;
    // The hold capture is not logged: emulate it (see `hold_capture`), or failing that with the
    // first samples of the run, before the velocity leaves zero.
    let hold = hold_capture(run);
    if !hold.is_empty() {
        for s in &hold {
            p.capture(s);
        }
    } else if let (Some(first), Some(pv)) = (
        run.blocks().next(),
        cfg.channels.position(tribo_wire::Channel::Velocity),
    ) {
        let v0 = first.sample(0).map_or(0, |s| s[pv]);
        for i in 0..first.samples() {
            let Some(s) = first.sample(i) else { break };
            if s[pv].abs_diff(v0) > HOLD_COUNTS / 2 {
                break;
            }
            p.capture(s);
        }
    }
    p.release();
    let mut next_sample = 0u32;
    'blocks: for (expected_block, b) in (0u32..).zip(run.blocks()) {
        if b.block != expected_block {
            bail!(
                "block {expected_block} is missing from the log: the pipeline needs every sample; complete the run with \
                 `tribo pull {}` first",
                run.dir().display()
            );
        }
        // An acquisition gap the rig reported: the firmware's pipeline stepped over it too.
        if b.first_sample > next_sample {
            p.gap(b.first_sample - next_sample);
        }
        next_sample = b.first_sample + b.samples() as u32;
        for i in 0..b.samples() {
            let Some(s) = b.sample(i) else { break };
            if p.push(s) != Phase::Running {
                break 'blocks;
            }
        }
    }
    Ok(p.finish(run.header().map_or(0, |h| h.run_id)))
}

/// Field-by-field comparison (relative tolerance `tol` on the floating-point numbers).
pub fn compare(rec: &OnboardResult, rep: &OnboardResult, tol: f64) -> Vec<Difference> {
    let mut d = vec![];
    let mut f = |name: &str, a: f32, b: f32| {
        let (a, b) = (a as f64, b as f64);
        let same =
            (a.is_nan() && b.is_nan()) || (a - b).abs() <= tol * a.abs().max(b.abs()).max(1e-12);
        if !same {
            d.push(Difference {
                field: name.into(),
                recorded: format!("{a:.6e}"),
                replayed: format!("{b:.6e}"),
            });
        }
    };
    let mut est = |name: &str, a: &Estimate, b: &Estimate| {
        f(&format!("{name}.mu0"), a.mu0, b.mu0);
        f(&format!("{name}.mu1"), a.mu1, b.mu1);
    };
    est("best", &rec.best, &rep.best);
    est("averaging", &rec.averaging, &rep.averaging);
    est("decrement", &rec.decrement, &rep.decrement);
    let mut g = |name: &str, a: String, b: String| {
        if a != b {
            d.push(Difference {
                field: name.into(),
                recorded: a,
                replayed: b,
            });
        }
    };
    g(
        "verdict",
        rec.verdict.name().into(),
        rep.verdict.name().into(),
    );
    g("cycles", rec.cycles.to_string(), rep.cycles.to_string());
    g("shape", rec.shape.name().into(), rep.shape.name().into());
    let mut f2 = |name: &str, a: f32, b: f32| {
        if (a - b).abs() as f64 > tol * (a.abs().max(b.abs()) as f64).max(1e-12)
            && !(a.is_nan() && b.is_nan())
        {
            d.push(Difference {
                field: name.into(),
                recorded: format!("{a}"),
                replayed: format!("{b}"),
            });
        }
    };
    f2("frequency_hz", rec.frequency_hz, rep.frequency_hz);
    d
}

/// Envelope of a run's record (as [`crate::load::open`] opened it) vs the simulated Coulomb–viscous law, per cycle: `(cycle, t_s, recorded A,
/// simulated A)` (SI, m), one row per cycle.
pub fn envelope_vs_simulation(
    rec: &Record,
    mu0: f64,
    mu1: f64,
) -> anyhow::Result<Vec<(usize, f64, f64, f64)>> {
    let rig = rec.rig()?;
    let (tau, y, yd) = rec.dimensionless()?;
    let model = Model::new(FrictionLaw::coulomb_viscous(mu0, mu1));
    let taus: Vec<f64> = tau.iter().map(|t| t - tau[0]).collect();
    let sim = simulate(&model, y[0], yd[0], &taus, FitOptions::default().method)?;
    let a_rec = mark_crandall(&y, &yd);
    let a_sim = mark_crandall(&sim.y, &sim.ydot);
    let per_cycle = (2.0 * std::f64::consts::PI / (taus[1] - taus[0]).max(1e-12))
        .round()
        .max(1.0) as usize;
    let mut rows = vec![];
    let scale = rig.x_of_y(1.0);
    for (c, i) in (0..tau.len()).step_by(per_cycle).enumerate() {
        rows.push((c, rec.t[i], a_rec[i] * scale, a_sim[i] * scale));
    }
    Ok(rows)
}
