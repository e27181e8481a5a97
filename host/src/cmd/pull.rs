//! `tribo pull [RUN]`: completes a stored run from the rig — the stored copy of the rig's last run
//! (found by the rig's serial number and run number), or the run folder RUN — fetching exactly the
//! blocks it lacks and the run's end, with retries while the rig answers; or fetches the rig's last
//! run into a new folder. Exits 3 when the run is still not whole (the rig no longer holds part of
//! it, or stopped answering), saying exactly what is missing and why.

use super::run::{print_outcome, LinkArgs, Ui};
use crate::link::session::pull_run;
use std::path::PathBuf;

/// Arguments of `tribo pull`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub link: LinkArgs,
    /// Run folder to complete (default: the stored copy of the rig's last run, or a new folder).
    pub run: Option<PathBuf>,
    /// Repair a damaged frame log: keep every record whose checksum holds, wherever the damage is
    /// (the damaged file is kept beside it as frames.log.damaged), then fetch what is missing.
    #[arg(long)]
    pub salvage: bool,
    /// No progress bar or messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    let (mut link, info) = args.link.connect()?;
    let mut ui = Ui::new(args.quiet);
    let o = pull_run(
        &mut link,
        &info,
        &args.link.store(),
        args.run.as_deref(),
        args.salvage,
        &mut |p| ui.on(p),
    );
    ui.finish();
    let o = o?;
    print_outcome(&o)?;
    match o.incomplete() {
        // Finished, but the run is not stored whole: exit status 3.
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
