//! `tribo run`: one run on the rig — configure, settle the heater, arm, release (or wait for the
//! button), stream with a live progress bar, save, and print μ0/μ1 on-board vs host fit.

use crate::link::args::LinkArgs;
use crate::link::plan::check_settle;
use crate::link::session::{record_run, HeaterPlan, RunPlan};
use crate::ui::{abort_flag, no_constant, print_outcome, Ui};
use anyhow::Context;
use std::sync::atomic::Ordering;
use tribo_wire::{Configure, HeaterSetpoint};

/// Arguments of `tribo run`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The rig to run on, and the run store.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Normal load set on the rig's knob, N (0–0.7).
    #[arg(long, visible_alias = "load-n", allow_negative_numbers = true)]
    pub load: f32,
    /// Heat the plate to this temperature first, °C (15–100; default: heater off).
    #[arg(long, allow_negative_numbers = true)]
    pub temp: Option<f32>,
    /// Runs to take in a row (at least 1).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
    /// Free label stored with the run (and in its folder name).
    #[arg(long)]
    pub label: Option<String>,
    /// Sample (pin/plane materials, finish), stored in the run's metadata.
    #[arg(long)]
    pub sample: Option<String>,
    /// Lubricant, stored in the run's metadata.
    #[arg(long)]
    pub lubricant: Option<String>,
    /// Wait for the button on the rig instead of releasing from here.
    #[arg(long)]
    pub button: bool,
    /// Sample rate, Hz.
    #[arg(long, default_value_t = 10_000)]
    pub rate: u32,
    /// Longest run, s (it ends earlier when the pin stops).
    #[arg(long, default_value_t = 40.0, allow_negative_numbers = true)]
    pub max_duration: f32,
    /// Moving mass, kg.
    #[arg(
        long,
        visible_alias = "mass-kg",
        default_value_t = 0.04,
        allow_negative_numbers = true
    )]
    pub mass: f32,
    /// Blade stiffness, N/m.
    #[arg(long, default_value_t = 1150.0, allow_negative_numbers = true)]
    pub stiffness: f32,
    /// Initial displacement held by the magnet, m.
    #[arg(long, default_value_t = 667e-6, allow_negative_numbers = true)]
    pub x0: f32,
    /// Heater: settled when within this many °C…
    #[arg(long, default_value_t = tribo_wire::limits::SETTLE_TOL_C, allow_negative_numbers = true)]
    pub settle_tol: f32,
    /// …for this many seconds.
    #[arg(long, default_value_t = tribo_wire::limits::SETTLE_S, allow_negative_numbers = true)]
    pub settle_secs: f64,
    /// Give up heating after this many seconds.
    #[arg(long, default_value_t = tribo_wire::limits::SETTLE_TIMEOUT_S, allow_negative_numbers = true)]
    pub settle_timeout: f64,
    /// Heater ramp, °C/min.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub ramp: f32,
    /// No progress bar or messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

impl Args {
    /// The run plan these arguments describe.
    pub fn plan(&self) -> RunPlan {
        let mut c = Configure::real_rig(self.load);
        c.rig.mass_kg = self.mass;
        c.rig.stiffness_n_per_m = self.stiffness;
        c.sample_rate_hz = self.rate;
        c.max_duration_s = self.max_duration;
        c.initial_amplitude_m = self.x0;
        let mut p = RunPlan::new(c);
        p.heater = self.temp.map(|t| HeaterPlan {
            setpoint_c: t,
            ramp_c_per_min: self.ramp,
            tolerance_c: self.settle_tol,
            settle_s: self.settle_secs,
            timeout_s: self.settle_timeout,
        });
        p.button = self.button;
        p.keep_heater = self.repeat > 1;
        p.label = self.label.clone();
        p.sample = self.sample.clone();
        p.lubricant = self.lubricant.clone();
        p
    }
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let plan = args.plan();
    if let Err(f) = plan.config.validate() {
        return Err(crate::exit::Usage(format!(
            "{}: {} is out of the rig's range",
            flag_of(f),
            crate::link::field_name(f)
        ))
        .into());
    }
    if let Some(t) = args.temp {
        if let Err(f) = (HeaterSetpoint {
            setpoint_c: t,
            ramp_c_per_min: args.ramp,
        })
        .validate()
        {
            return Err(crate::exit::Usage(format!(
                "--temp {t} °C, --ramp {} °C/min: {} is out of the rig's range",
                args.ramp,
                crate::link::field_name(f)
            ))
            .into());
        }
    }
    check_settle(args.settle_tol, args.settle_secs, args.settle_timeout).map_err(|why| {
        crate::exit::Usage(format!(
            "--settle-tol {} °C, --settle-secs {} s, --settle-timeout {} s: {why}",
            args.settle_tol, args.settle_secs, args.settle_timeout
        ))
    })?;
    let abort = abort_flag();
    let store = args.link.writable_store()?;
    let (mut link, info) = args.link.connect_and_announce(args.quiet)?;
    // From here on every exit leaves the rig safe (see `link::hold`).
    let _hold = link.hold();
    // Runs stored whole of which no constant could be printed (status 3 once the runs are taken).
    let mut unanalysed: Vec<String> = Vec::new();
    for k in 1..=args.repeat.max(1) {
        let mut plan = plan.clone();
        if args.repeat > 1 {
            plan.repeat = Some(k);
            plan.keep_heater = k < args.repeat;
            if !args.quiet {
                crate::errln!("repetition {k}/{}", args.repeat);
            }
        }
        let mut ui = Ui::new(args.quiet);
        let o = record_run(&mut link, &info, &store, &plan, &abort, &mut |p| ui.on(p));
        ui.finish();
        let o = o.with_context(|| format!("run {k} on {}", link.name()))?;
        print_outcome(&o)?;
        let taken = if args.repeat > 1 {
            format!("; {} of {} runs taken", k - 1, args.repeat)
        } else {
            String::new()
        };
        if o.aborted {
            // Interrupted: status 130 (or 143, 129: the signal's), whatever the interrupted run kept.
            return Err(crate::exit::Interrupted(format!(
                "interrupted during run {k}: what it received is kept as an aborted run{taken}"
            ))
            .into());
        }
        if let Some(e) = o.incomplete() {
            // Finished, but the run is not stored whole: exit status 3.
            return Err(anyhow::Error::new(e).context(format!("run {k}{taken}")));
        }
        if let Some(why) = no_constant(&o.run) {
            unanalysed.push(format!("run {k} ({}): {why}", o.run.dir().display()));
        }
        if o.link_lost.is_some() {
            break;
        }
        if abort.load(Ordering::Relaxed) && k < args.repeat.max(1) {
            return Err(crate::exit::Interrupted(format!(
                "interrupted after run {k}: {k} of {} runs taken",
                args.repeat
            ))
            .into());
        }
    }
    if !unanalysed.is_empty() {
        // Stored whole, but nothing to print for it: as `tribo fit` on the same run, status 3.
        return Err(crate::exit::Incomplete(format!(
            "no constant could be printed for {} of {} run{}: {}; the run is stored whole (`tribo \
             report` shows its motion)",
            unanalysed.len(),
            args.repeat.max(1),
            if args.repeat > 1 { "s" } else { "" },
            unanalysed.join("; ")
        ))
        .into());
    }
    Ok(())
}

/// The `tribo run` option that sets a configuration field.
fn flag_of(f: tribo_wire::Field) -> &'static str {
    use tribo_wire::Field;
    match f {
        Field::Mass => "--mass",
        Field::Stiffness => "--stiffness",
        Field::Load => "--load",
        Field::SampleRate => "--rate",
        Field::InitialAmplitude => "--x0",
        Field::MaxDuration => "--max-duration",
        Field::HeaterSetpoint => "--temp",
        Field::HeaterRamp => "--ramp",
        Field::Channels | Field::Calibration | Field::RunId => "the configuration",
    }
}
