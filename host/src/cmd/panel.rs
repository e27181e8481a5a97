//! `tribo panel`: the rig's front panel, a local web page served by this program
//! ([`crate::panel`]).

use crate::link::args::LinkArgs;

/// Arguments of `tribo panel`.
#[derive(clap::Args, Debug)]
#[command(after_help = "Examples:
  tribo panel
      the only attached rig (else tcp://127.0.0.1:7411); the page on http://127.0.0.1:7420/
  tribo panel --port tcp://127.0.0.1:7411 --listen 127.0.0.1:0
      a virtual rig (`tribo rig --virtual` in another terminal); the page on a free port
  tribo panel --listen 0.0.0.0:7420 --token S
      served to the lab network: open http://IP-OF-THIS-PC:7420/?token=S (the panel answers
      to its IP addresses; to open it by a name, listen on that name: --listen NAME:7420)

The page shows the rig (connected, serial, state, lease, last fault and reset), the plate's
temperature against its setpoint (\"settled\" within the settling tolerance for the settling
time), the run as it is recorded (displacement with its envelope, velocity, force, ECR; lost blocks
and acquisition gaps shaded), the result (on-board and host fit, as `tribo run` prints it, and a
link to the run's report) and the store's campaign grid (host μ0 per load × temperature, as `tribo
table`). Its controls (heater, configure, arm, release) go to the rig as `tribo run` sends them;
one page controls, the others view; Safe works from every page. Runs are stored as `tribo run`
stores them. GET /api/state gives the page's state as JSON, for scripts.

Closing the panel (Ctrl-C: exit status 130) makes the rig safe; a killed panel leaves it to the
rig's lease, which expires within 3 s.")]
pub struct Args {
    /// The rig the panel drives, and the run store.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Address the page is served on, IP:PORT or NAME:PORT (127.0.0.1:0 picks a free port; the
    /// address is printed). The panel answers only to requests addressed to it: this address,
    /// the name given here, or `localhost` on loopback.
    #[arg(long, default_value = "127.0.0.1:7420", value_name = "HOST:PORT")]
    pub listen: String,
    /// Access token the page must carry (`http://HOST:PORT/?token=…`); required when --listen is
    /// not a loopback address. Default: $TRIBO_PANEL_TOKEN.
    #[arg(long)]
    pub token: Option<String>,
    /// No progress messages: set by `tribo -q`/`--quiet`.
    #[arg(skip)]
    pub quiet: bool,
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    crate::panel::serve(&args.link, &args.listen, args.token, args.quiet)
}
