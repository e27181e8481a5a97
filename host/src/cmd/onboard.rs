//! `tribo onboard RECORD [--json]`: the firmware's on-board analysis over a record, as if the
//! record were being sampled live by the rig ([`crate::onboard`]).
use crate::onboard::{analyse, to_json, to_text};
use anyhow::Context;
use std::path::PathBuf;
use tribo_wire::Verdict;

/// Arguments of `tribo onboard`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Record to analyse: CSV `t_s,x_m,v_m_s[,ft_n,…]` with `# mass_kg=…`, `# stiffness_n_per_m=…`,
    /// `# load_n=…` comment lines.
    pub record: PathBuf,
    /// Print one JSON object instead of a table: set by the global `--json`.
    #[arg(skip)]
    pub json: bool,
}

/// Runs the subcommand. A record the pipeline refuses (too few cycles, no oscillation, a saturated
/// channel, a non-finite sample) ends with status 3 and no coefficients (JSON: `null`s).
pub fn run(args: Args) -> anyhow::Result<()> {
    let (json, path) = (args.json, args.record.clone());
    run_inner(args).map_err(|e| super::exit::json_on_error(json, &path, e))
}

fn run_inner(args: Args) -> anyhow::Result<()> {
    let record = crate::analysis::load_for_analysis(&args.record)?;
    // The host's screening first: a record clipped by another acquisition's converter looks
    // unsaturated to the pipeline, whose converter range is made to span the record.
    if let Ok((tau, y, ydot)) = record.dimensionless() {
        let r = tribo_physics::identify::motion_span(&tau, &y, &ydot).range();
        if let Err(why) = tribo_physics::identify::screen(&tau[r.clone()], &y[r.clone()], &ydot[r])
        {
            return Err(crate::exit::Incomplete(format!(
                "{}: not analysable: {why}; no coefficients",
                args.record.display()
            ))
            .into());
        }
    }
    let result = analyse(&record).with_context(|| format!("{}", args.record.display()))?;
    let usable = matches!(result.verdict, Verdict::Ok | Verdict::EstimatorsDisagree);
    if args.json {
        crate::out::print_json(to_json(&result))?;
    } else if usable {
        let dimensionless = record.units == tribo_physics::record::Units::Dimensionless;
        crate::out!("{}", to_text(&result, dimensionless))?;
    }
    if !usable {
        return Err(crate::exit::Incomplete(format!(
            "{}: not analysable by the on-board pipeline: {} ({} cycles); no coefficients",
            args.record.display(),
            result.verdict.name(),
            result.cycles
        ))
        .into());
    }
    Ok(())
}
