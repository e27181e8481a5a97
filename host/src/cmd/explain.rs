//! `tribo explain RECORD [--base LAW] [--json] [--report DIR]`: find where a friction law fails to
//! explain a record, name the missing physics, add it and show the gap shrink (issue 7). The logic
//! lives in the `tribo-explain` crate.

use anyhow::{bail, Context, Result};
use clap::Parser;
use std::path::PathBuf;
use tribo_explain::{report::write_report, Effect, ExplainOptions, Prepared};
use tribo_physics::identify::LawSpec;

/// Explain the disagreement between a friction law and a record.
///
/// Fits the base law, measures where it disagrees (envelope residual against amplitude and time,
/// windowed fits, frequency against amplitude, force lag and dissipated energy when `ft_n` exists,
/// temperature drift when `temp_c` exists), then scores each candidate effect — quadratic-velocity,
/// stribeck, frictional-lag, cubic-stiffness, thermal-drift, sensor-lag — by how much adding it
/// explains (BIC on the envelope + force residuals), adds the best one when the evidence is clear,
/// refits, and repeats until nothing significant is left.
///
/// `--json` prints one object `{"missing_effects": [...], "steps": [{"effect", "gap_before",
/// "gap_after", "delta_bic", "params"}], "gap_initial", "gap_final", ...}`. The gap is RMS(measured
/// − fitted envelope) / initial amplitude, extended to the force channel as
/// √(gap_envelope² + gap_force²).
///
/// A record with holes (samples the rig lost, blocks not received, a time axis that jumps) is
/// refused; `--longest-clean-stretch` explains the longest stretch of consecutive samples instead.
#[derive(Parser, Debug)]
pub struct Args {
    /// The record (CSV `t_s,x_m,v_m_s[,ft_n,temp_c,ecr_ohm]` with rig constants, or `tau,y,ydot`).
    pub record: PathBuf,
    /// Base law: coulomb, viscous, coulomb-viscous, quadratic, poly:N.
    #[arg(long, default_value = "coulomb-viscous")]
    pub base: String,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write before/after figures (SVG) and an HTML page into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Only consider these effects (comma-separated names).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// At most this many effects are added.
    #[arg(long, default_value_t = 3)]
    pub max_steps: usize,
    /// If the record has holes (samples the rig lost, blocks not received), use the longest
    /// stretch of consecutive samples instead of refusing.
    #[arg(long)]
    pub longest_clean_stretch: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> Result<()> {
    let base: LawSpec = args.base.parse().map_err(anyhow::Error::msg)?;
    let mut opts = ExplainOptions {
        base,
        max_steps: args.max_steps,
        ..ExplainOptions::default()
    };
    if !args.only.is_empty() {
        opts.candidates = args
            .only
            .iter()
            .map(|n| {
                Effect::from_name(n.trim()).with_context(|| {
                    format!(
                        "unknown effect {n:?}: use {}",
                        Effect::ALL.map(|e| e.name()).join(", ")
                    )
                })
            })
            .collect::<Result<_>>()?;
    }
    let holes = if args.longest_clean_stretch {
        crate::Holes::LongestCleanStretch
    } else {
        crate::Holes::Refuse
    };
    let record = crate::load_for_fit(&args.record, holes)?;
    let data = Prepared::new(
        &record,
        opts.max_env_points,
        opts.max_force_points,
        opts.force_cutoff_hz,
    )
    .with_context(|| format!("{}", args.record.display()))?;
    let ex = tribo_explain::explain_prepared(&data, &opts)
        .with_context(|| format!("{}", args.record.display()))?;
    if args.json {
        println!("{}", ex.to_json());
    } else {
        print!("{}", ex.to_text());
    }
    if let Some(dir) = &args.report {
        let page = write_report(&data, &ex, dir)?;
        if !args.json {
            println!("report: {}", page.display());
        }
    }
    if !ex.gap_final.is_finite() {
        bail!("the fit diverged");
    }
    Ok(())
}
