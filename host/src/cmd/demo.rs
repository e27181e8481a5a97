//! `tribo demo [--out DIR]`: a complete run on a virtual rig running in this process, through the
//! link's frames exactly as a USB rig sends them, saved, printed and drawn — no hardware, no set-up,
//! no socket or terminal.

use crate::link::firmware_version;
use crate::link::session::{record_run, Progress, RunPlan};
use crate::ui::{abort_flag, print_outcome, Ui};
use crate::virtual_rig::VirtualArgs;
use anyhow::Context;
use std::path::PathBuf;
use tribo_wire::Configure;

/// Arguments of `tribo demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output directory: the run store (`runs/`) and the report (`report/`).
    #[arg(long, default_value = "demo-out")]
    pub out: PathBuf,
    /// The virtual rig the demo runs on.
    #[command(flatten)]
    pub rig: VirtualArgs,
    /// No figures.
    #[arg(long)]
    pub no_report: bool,
    /// No progress bar or messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let o = demo(&args)?;
    println!(
        "next: `tribo fit {}` or `tribo report {}`",
        o.run.dir().display(),
        o.run.dir().display()
    );
    match o.incomplete() {
        // The run is not stored whole: exit status 3.
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

/// The demo, returning the recorded run (for tests).
pub fn demo(args: &Args) -> anyhow::Result<crate::link::session::Outcome> {
    let abort = abort_flag();
    let (mut link, cfg) = args.rig.in_process()?;
    let say = |m: String| {
        if !args.quiet {
            crate::errln!("{m}")
        }
    };
    say(format!(
        "virtual rig in this process (contact {}, load {} N); running through the link's frames",
        cfg.law, cfg.load_n
    ));
    let info = link.hello()?;
    say(format!(
        "hello: firmware {}, serial {:016x}",
        firmware_version(&info),
        info.serial
    ));
    let mut c = Configure::real_rig(cfg.load_n.min(0.7) as f32);
    c.rig.mass_kg = cfg.mass_kg as f32;
    c.rig.stiffness_n_per_m = cfg.stiffness_n_per_m as f32;
    c.initial_amplitude_m = cfg.x0_m as f32;
    c.max_duration_s = 20.0;
    let mut plan = RunPlan::new(c);
    plan.label = Some("demo".into());
    plan.sample = Some("virtual steel ball on flat".into());
    let store = args.out.join("runs");
    let mut ui = Ui::new(args.quiet);
    let started = std::time::Instant::now();
    let mut ended = None;
    let o = record_run(&mut link, &info, &store, &plan, &abort, &mut |p| {
        if let Progress::Ended(_) = &p {
            ended = Some(std::time::Instant::now());
        }
        ui.on(p)
    });
    // From the configuration to the run's end frame: the link's work, without the fit and saving.
    let wall = ended.map_or(f64::NAN, |e| (e - started).as_secs_f64());
    ui.finish();
    let o = o.context("demo run")?;
    print_outcome(&o)?;
    let st = link.stats();
    println!(
        "{:<10}{} frames, {} bytes in {wall:.3} s (configure to end of run) through the in-process link ({:.0} kB/s at \
         ×{} speed), {} bad frames",
        "link",
        st.frames_in,
        st.bytes_in,
        st.bytes_in as f64 / wall / 1e3,
        args.rig.speed,
        st.bad_frames
    );
    if let Some((m0, m1)) = cfg.law.as_coulomb_viscous() {
        println!(
            "{:<10}μ0 = {m0}, μ1 = {} (contact + apparatus {})",
            "simulated",
            m1 + cfg.apparatus_mu1,
            cfg.apparatus_mu1
        );
    }
    if !args.no_report {
        let dir = args.out.join("report");
        match write_report(&o.run, &dir) {
            Ok(msg) => println!("{msg}"),
            Err(e) => println!("figures not written: {e:#}"),
        }
    }
    Ok(o)
}

/// Writes the report of a stored run (figures and `report.html`) with `tribo-report`.
pub fn write_report(run: &tribo_store::Run, dir: &std::path::Path) -> anyhow::Result<String> {
    let rec = crate::load::open(run.dir(), crate::Holes::Keep)?.record;
    let files = tribo_report::store::write_run_report(run, &rec, dir)?;
    let mut s = format!(
        "report: {} ({} figures)",
        files.html.display(),
        files.figures.len()
    );
    for n in &files.notes {
        s.push_str(&format!("\n  note: {n}"));
    }
    Ok(s)
}
