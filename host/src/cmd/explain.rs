//! `tribo explain RECORD [--base LAW] [--json] [--report DIR]`: find where a friction law fails to
//! explain a record, name the missing physics, add it and show the gap shrink. The logic
//! lives in the `tribo-explain` crate.

use crate::analysis::open_analysable;
use crate::exit::Incomplete;
use crate::{out, outln};
use anyhow::{bail, Context, Result};
use clap::Parser;
use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::PathBuf;
use tribo_explain::{report::write_report, Effect, ExplainOptions, Prepared};
use tribo_physics::identify::LawSpec;

fn base_law(s: &str) -> Result<LawSpec, String> {
    match s.parse::<LawSpec>().map_err(|e| e.to_string())? {
        LawSpec::LuGre => Err(
            "the base law must be polynomial: coulomb, viscous, coulomb-viscous, quadratic, poly:N"
                .into(),
        ),
        l => Ok(l),
    }
}

fn effect(s: &str) -> Result<Effect, String> {
    Effect::from_name(s.trim()).ok_or_else(|| {
        format!(
            "unknown effect {s:?}: use {}",
            Effect::ALL.map(|e| e.name()).join(", ")
        )
    })
}

/// A force in newtons that must be finite (`--force-zero-n`).
fn finite_newtons(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(v) => Err(format!(
            "the force channel's zero must be a finite force in N, got {v}"
        )),
        Err(e) => Err(format!("{s:?} is not a force in N: {e}")),
    }
}

/// The long `--help` of the command.
pub const LONG_ABOUT: &str = "Explain the disagreement between a friction law and a record.

Fits the base law to every channel (envelope from displacement and velocity; friction force when
`ft_n` exists; temperature when `temp_c` exists), measures where it disagrees, then tries each
candidate effect — quadratic-velocity, stribeck, frictional-lag, cubic-stiffness, thermal-drift,
sensor-lag, running-in (μ0 drifting in time at constant temperature). The force channel's
low-pass is the record's (`# force_cutoff_hz=`) or `--force-cutoff-hz` (a stated cut-off is a 2-pole
filter); when neither states it, its order (1-pole or 2-pole) and time constant are fitted with
everything else in every model and printed with its ±. The force channel's zero is the record's
(`# force_zero_n=`) or `--force-zero-n`, else, on a record held by the magnet before its release,
measured over the hold (no tangential force acts then; printed with its ±); only with it known can
a constant force while sliding be named direction-asymmetry (without, it is as much a zero offset
of the channel, and the answer is ambiguous). An effect is named only if adding it shrinks the misfit by more than chance would,
judged with a noise model of the residuals that includes their correlation (an effective sample
count per channel), and removes a material part of the misfit above the noise floor. The best one
is added, the model refitted, and the search repeats. Where no single effect removes enough of
the misfit but a pair of the strongest does, each needed beside the other, the stronger is added
(its step says so) and the other must qualify on its own; two effects that explain the record
about equally well are both named where the pair needs each, otherwise the record is ambiguous.
If a misfit well above the noise floor remains, the answer is \"unexplained: N % of the gap remains; not one of the known effects\" —
never a guess.

`--json` prints one object: `conclusion` (base-adequate, explained, partly-explained,
unexplained, ambiguous), `missing_effects`, `steps` (each with `effect`, `gap_before`,
`gap_after`, `evidence`, `params` and `params_se`: the final model's constants, a Stribeck rise's
with its exponent `delta`, 1 or 2, chosen as the better fit and so with a `null` ±, and
`paired_with`: `null`, or, for an effect that alone removed too little of the excess and was named
as the stronger of a pair that removes enough, the other's `effect` and the pair's `evidence`,
`threshold` and `excess_removed`),
`gap_initial`, `gap_final`, `noise_floor`,
`unexplained_fraction`, `force_cutoff_hz` and `force_cutoff_source` (`record`, `option`,
`fitted`, `none`), `force_lowpass` (`source`, `cutoff_hz` and `cutoff_hz_se`, `time_constant_s` and
`time_constant_s_se`, `cutoff_at_least_hz`, `poles`: the filter's order, 1 or 2, fitted from the
record when it states no filter, `digital`: a 2-pole filter applied digitally to the sampled force
(bilinear, as the rig's records are filtered) rather than the analog one, chosen from the record,
`order_evidence`: the evidence for that order over the other),
`disagreement` (where the final model still misses,
in sentences: each channel above its floor, the time third and amplitude band where it misses
most, a force misfit common to both sliding directions), `base_fit` (the base law's
constants: `tribo fit`'s result on the same record, the one estimator of a law), `base_model` (the
model of every channel the effects are added to) and `final_model`, `cross_check` (the on-board
result beside the host's, `null` for other base laws than coulomb-viscous),
every round's candidates and the diagnostics. The gap is RMS(measured − fitted envelope) /
initial amplitude, extended to the force channel as √(gap_envelope² + gap_force²).

Exit status 3 (and nothing explained) for a record that cannot be analysed.

A record with holes (samples the rig lost, blocks not received, a time axis that jumps) is
refused; `--longest-clean-stretch` explains the longest stretch of consecutive samples instead.";

///  Explain the disagreement between a friction law and a record.
#[derive(Parser, Debug)]
pub struct Args {
    /// The record (CSV `t_s,x_m,v_m_s[,ft_n,temp_c,ecr_ohm]` with rig constants, or `tau,y,ydot`).
    pub record: PathBuf,
    /// Base law: coulomb, viscous, coulomb-viscous, quadratic, poly:N.
    #[arg(long, default_value = "coulomb-viscous", value_parser = base_law)]
    pub base: LawSpec,
    /// Print one JSON object: set by the global `--json`.
    #[arg(skip)]
    pub json: bool,
    /// Write before/after figures (SVG) and an HTML page into this directory.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Only consider these effects (comma-separated names).
    #[arg(long, value_delimiter = ',', value_parser = effect)]
    pub only: Vec<Effect>,
    /// At most this many effects are added.
    #[arg(long, default_value_t = 3)]
    pub max_steps: usize,
    /// Low-pass of the force channel (Hz, a 2-pole filter), if the record does not state it
    /// (`# force_cutoff_hz=`); without either, its order and cut-off are fitted (with its ±) in
    /// every model of the search.
    #[arg(long)]
    pub force_cutoff_hz: Option<f64>,
    /// The force channel's zero (N: what it reads with no friction force), if the record does not
    /// state it (`# force_zero_n=`); with it stated, a constant force while sliding is named
    /// direction-asymmetry; without it a held record's zero is measured over the magnet's hold,
    /// any other's is fitted and such a force is ambiguous.
    #[arg(long, value_parser = finite_newtons, allow_negative_numbers = true)]
    pub force_zero_n: Option<f64>,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
    /// If the record has holes (samples the rig lost, blocks not received), use the longest
    /// stretch of consecutive samples instead of refusing.
    #[arg(long)]
    pub longest_clean_stretch: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> Result<()> {
    let (json, path) = (args.json, args.record.clone());
    run_inner(args).map_err(|e| super::exit::json_on_error(json, &path, e))
}

fn run_inner(args: Args) -> Result<()> {
    let base: LawSpec = args.base;
    let mut opts = ExplainOptions {
        base,
        max_steps: args.max_steps,
        force_cutoff_hz: args.force_cutoff_hz,
        force_zero_n: args.force_zero_n,
        ..ExplainOptions::default()
    };
    if !args.only.is_empty() {
        opts.candidates = args.only.clone();
    }
    let holes = if args.longest_clean_stretch {
        crate::Holes::LongestCleanStretch
    } else {
        crate::Holes::Refuse
    };
    let opened = open_analysable(&args.record, holes)?;
    let record = &opened.record;
    crate::analysis::plausible_record(record)
        .map_err(|e| e.of(args.record.display().to_string()))?;
    let not_analysable = |e: tribo_explain::ExplainError| -> anyhow::Error {
        if e.is_not_analysable() {
            Incomplete(format!(
                "{}: {e}; nothing is explained",
                args.record.display()
            ))
            .into()
        } else {
            anyhow::Error::new(e).context(format!("{}", args.record.display()))
        }
    };
    let data = Prepared::new(
        record,
        opts.max_env_points,
        opts.max_force_points,
        opts.force_cutoff_hz,
    )
    .map_err(not_analysable)?;
    let bar = if args.quiet || !std::io::stderr().is_terminal() {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::new_spinner();
        b.set_style(
            ProgressStyle::with_template("{spinner} explain: {msg} [{elapsed}]")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        b.enable_steady_tick(std::time::Duration::from_millis(120));
        b
    };
    let result = tribo_explain::explain_with_progress(&data, &opts, &mut |what, _, _| {
        bar.set_message(what.to_string())
    });
    bar.finish_and_clear();
    let (ex, data) = result.map_err(not_analysable)?;
    let check = crate::analysis::cross_check(opened.run.as_ref(), record, &ex.base_fit);
    if args.json {
        let j = crate::analysis::explanation_json(&ex, &check)
            .context("writing the explanation as JSON")?;
        crate::out::print_json(&j)?;
    } else {
        out!("{}", ex.to_text())?;
        if let Some(line) = crate::analysis::cross_check_text(&check) {
            outln!("{line}")?;
        }
    }
    if let Some(dir) = &args.report {
        let page = write_report(&data, &ex, dir)?;
        if !args.json {
            outln!("report: {}", page.display())?;
        }
    }
    if !ex.gap_final.is_finite() {
        bail!("the fit diverged");
    }
    Ok(())
}
