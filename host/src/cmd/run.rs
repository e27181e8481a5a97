//! `tribo run`: one run on the rig — configure, settle the heater, arm, release (or wait for the
//! button), stream with a live progress bar, save, and print μ0/μ1 on-board vs host fit.
//!
//! Also the pieces the other rig commands share: choosing the port and the store, the Ctrl-C flag,
//! the progress display and the result table.

use crate::link::session::{record_run, HeaterPlan, Outcome, Progress, RunPlan};
use crate::link::transport::DEFAULT_VIRTUAL_RIG;
use crate::link::{devices, firmware_version, Address, Link, LinkErrorKind};
use anyhow::{bail, Context};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;
use tribo_store::Run;
use tribo_wire::{Configure, HeaterSetpoint};

/// How to reach the rig and where to store runs.
#[derive(clap::Args, Debug, Clone)]
pub struct LinkArgs {
    /// The rig's port: a serial port as the system names it (Windows: COM3; macOS:
    /// /dev/cu.usbmodem…; Linux: /dev/ttyACM0; `tribo devices` lists them), or tcp://HOST:PORT for
    /// a virtual rig (`tribo rig --virtual` prints it). Default: $TRIBO_PORT, else the only attached
    /// rig, else a virtual rig at tcp://127.0.0.1:7411.
    #[arg(long, short, value_name = "PORT")]
    pub port: Option<Address>,
    /// Run store directory (default: $TRIBO_STORE, else ./runs).
    #[arg(long)]
    pub store: Option<PathBuf>,
}

impl LinkArgs {
    pub fn store(&self) -> PathBuf {
        self.store
            .clone()
            .unwrap_or_else(tribo_store::default_store_dir)
    }

    /// The store, checked writable before anything is armed (a file in the way, a read-only
    /// folder): a sphere released with nobody able to record it is a run lost.
    pub fn writable_store(&self) -> anyhow::Result<PathBuf> {
        let store = self.store();
        let fail = |e: std::io::Error| {
            anyhow::anyhow!(
                "the run store {} cannot be written ({e}): nothing was sent to the rig; pass --store with a folder you can write",
                store.display()
            )
        };
        std::fs::create_dir_all(&store).map_err(fail)?;
        let probe = store.join(format!(".tribo-write-test-{}", std::process::id()));
        std::fs::write(&probe, b"").map_err(fail)?;
        std::fs::remove_file(&probe).map_err(fail)?;
        Ok(store)
    }

    /// The port to use, and, when no rig was named nor found and the default virtual rig's address
    /// is tried instead, why. An error lists what to do.
    pub fn port(&self) -> anyhow::Result<(Address, Option<String>)> {
        if let Some(p) = &self.port {
            return Ok((p.clone(), None));
        }
        if let Some(p) = std::env::var_os("TRIBO_PORT").filter(|p| !p.is_empty()) {
            let p = Address::parse(&p.to_string_lossy())
                .map_err(|e| anyhow::anyhow!("$TRIBO_PORT: {e}"))?;
            return Ok((p, None));
        }
        let why = match devices::rigs() {
            Ok(rigs) if rigs.len() == 1 => return Ok((Address::Serial(rigs[0].name.clone()), None)),
            Ok(rigs) if rigs.len() > 1 => bail!(
                "several rigs are attached ({}): choose one with --port (`tribo devices` shows their serial numbers)",
                rigs.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(", ")
            ),
            Ok(_) => "no USB serial port with the rig's id 1209:0001".to_string(),
            Err(e) => e,
        };
        Ok((Address::Tcp(DEFAULT_VIRTUAL_RIG.into()), Some(why)))
    }

    /// Opens the link and says hello.
    pub fn connect(&self) -> anyhow::Result<(Link, tribo_wire::DeviceInfo)> {
        let (port, fallback) = self.port()?;
        let mut link = match (Link::open(&port), fallback) {
            (Ok(l), _) => l,
            (Err(e), Some(why)) if e.kind == LinkErrorKind::Open => bail!(
                "no rig found ({why}; no virtual rig at {port}): attach one (see `tribo devices`) and give \
                 --port, or start a virtual rig with `tribo rig --virtual` in another terminal"
            ),
            (Err(e), _) => return Err(e.into()),
        };
        let info = match link.hello() {
            Ok(i) => i,
            // Closed before it said hello: a rig serving another host turns a second one away.
            Err(e) if e.kind == LinkErrorKind::Closed => bail!(
                "the rig on {port} closed the connection before answering: it serves one host at a \
                 time, so another `tribo` is probably connected to it (wait for it, or stop it); \
                 nothing was sent to the rig and nothing was recorded"
            ),
            Err(e) => return Err(e.into()),
        };
        Ok((link, info))
    }

    /// [`LinkArgs::connect`], then says which rig answered (unless `quiet`) and warns when it
    /// reset by itself since a host last spoke to it.
    pub fn connect_and_announce(
        &self,
        quiet: bool,
    ) -> anyhow::Result<(Link, tribo_wire::DeviceInfo)> {
        let (link, info) = self.connect()?;
        if !quiet {
            crate::errln!(
                "rig on {}: firmware {}, serial {:016x}",
                link.name(),
                firmware_version(&info),
                info.serial
            );
        }
        warn_about_reset(&link);
        Ok((link, info))
    }
}

/// Set on Ctrl-C, SIGTERM or SIGHUP: the command stops cleanly and the rig is made safe. A second
/// one exits at once, after sending `Safe` to every rig this process holds. Either way the exit
/// status names the signal (130, 143, 129: [`crate::exit`]).
pub fn abort_flag() -> Arc<AtomicBool> {
    static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();
    FLAG.get_or_init(|| {
        let f = Arc::new(AtomicBool::new(false));
        let g = f.clone();
        let _ = crate::signals::set_handler(move |signal| {
            if g.swap(true, Ordering::SeqCst) {
                crate::link::hold::make_all_safe();
                crate::errln!(
                    "\ninterrupted twice: exiting now; heater and magnet were switched off (the run folder stays \
                     readable)"
                );
                std::process::exit(signal.status().into());
            }
            crate::errln!("\ninterrupted: aborting the run cleanly (Ctrl-C again to quit at once)…");
        });
        f
    })
    .clone()
}

/// The rig's interlocks, for `--help` (every number from `tribo_wire::limits`).
pub fn safety_help() -> String {
    use tribo_wire::limits as l;
    format!(
        "Safety: the rig enforces its limits itself, whatever this program does. While it heats or holds \
         the magnet it needs a word from this program at least every {lease} s (a heartbeat is sent every \
         {hb} s); without one it switches heater and magnet off. Every exit of this program (end, error, \
         Ctrl-C, closed pipe) switches them off too. Heater: cut off above {cut} °C, on {bad} bad \
         thermocouple reads in a row, if heating gains less than {gain} °C in {period} s, or if the plate \
         rises {rise} °C with no heat asked for; settled within {tol} °C for {settle} s by default. \
         Magnet: at most {hold} s at a stretch and {duty:.0} % of the time. `tribo status` shows the last \
         fault and the last reset.",
        lease = l::HOST_LEASE_MS as f64 / 1000.0,
        hb = l::HEARTBEAT_MS as f64 / 1000.0,
        cut = l::HEATER_CUTOFF_C,
        bad = l::TC_BAD_READS,
        gain = l::HEATER_WATCH_GAIN_C,
        period = l::HEATER_WATCH_PERIOD_S,
        rise = l::HEATER_RUNAWAY_RISE_C,
        tol = l::SETTLE_TOL_C,
        settle = l::SETTLE_S,
        hold = l::MAGNET_MAX_HOLD_MS / 1000,
        duty = l::MAGNET_MAX_DUTY * 100.0,
    )
}

/// Writes to standard output. A closed pipe (`tribo run … | head`) is an error that stops the
/// command, unwinding through its hold on the rig (which sends `Safe`); `main` ends quietly on it
/// (`crate::out`).
pub fn out(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut o = std::io::stdout().lock();
    o.write_all(text.as_bytes())
        .and_then(|_| o.flush())
        .map_err(|e| anyhow::Error::new(e).context("cannot write to standard output"))
}

/// Progress bar and messages for a run.
pub struct Ui {
    bar: Option<ProgressBar>,
    quiet: bool,
    /// Release amplitude (m) and sample rate of the run in progress.
    a0: f64,
    rate: f64,
}

impl Ui {
    pub fn new(quiet: bool) -> Ui {
        Ui {
            bar: None,
            quiet,
            a0: 0.0,
            rate: 1.0,
        }
    }

    fn bar(&mut self, len: u64) -> &ProgressBar {
        self.bar.get_or_insert_with(|| {
            let b = if self.quiet {
                ProgressBar::hidden()
            } else {
                ProgressBar::new(len)
            };
            b.set_style(
                ProgressStyle::with_template("{spinner} [{elapsed_precise}] {bar:30} {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
            );
            b.enable_steady_tick(Duration::from_millis(200));
            b
        })
    }

    fn say(&self, s: &str) {
        if self.quiet {
            return;
        }
        match &self.bar {
            Some(b) if !b.is_hidden() => b.println(s),
            _ => crate::errln!("{s}"),
        }
    }

    /// Shows one progress event.
    pub fn on(&mut self, p: Progress<'_>) {
        match p {
            Progress::Heating {
                temp_c,
                setpoint_c,
                elapsed_s,
            } => {
                let b = self.bar(0);
                b.set_message(format!(
                    "heating: plate {temp_c:.1} °C → {setpoint_c:.1} °C ({elapsed_s:.0} s)"
                ));
            }
            Progress::WaitingForButton => {
                self.say("armed: press the button on the rig to release the pin")
            }
            Progress::Started { header, dir } => {
                // The bar follows the envelope's decay from the release amplitude to zero: the run
                // ends when the pin stops, long before its maximum duration.
                self.a0 = header.config.initial_amplitude_m as f64;
                self.rate = if header.clock.is_valid() {
                    header.clock.rate_hz()
                } else {
                    header.config.sample_rate_hz as f64
                };
                let b = self.bar(1000);
                b.set_length(1000);
                b.set_position(0);
                b.set_message(format!("run {} released", header.run_id));
                let msg = format!("recording run {} into {}", header.run_id, dir.display());
                self.say(&msg);
            }
            Progress::Block {
                envelope_m,
                samples,
                ..
            } => {
                let a0 = self.a0;
                let rate = self.rate;
                let b = self.bar(1000);
                if a0 > 0.0 && envelope_m.is_finite() {
                    let done = ((1.0 - envelope_m / a0).clamp(0.0, 1.0) * 1000.0) as u64;
                    b.set_position(b.position().max(done));
                }
                b.set_message(format!(
                    "envelope {:.1} µm of {:.0} µm, {:.2} s, {samples} samples",
                    envelope_m * 1e6,
                    a0 * 1e6,
                    samples as f64 / rate.max(1.0)
                ));
            }
            Progress::Gap { from, to } => self.say(&format!(
                "frames lost: blocks {from}..{to} (they will be pulled again)"
            )),
            Progress::Pulling { from_block } => {
                self.say(&format!("fetching the run from block {from_block} on"))
            }
            Progress::PullRound {
                round,
                first,
                blocks,
                missing,
                tail_from,
            } => self.say(&match first {
                Some(f) => format!(
                    "pull {round}: asking for blocks {f}–{} ({missing} missing), then the run's end",
                    f + blocks.saturating_sub(1)
                ),
                None if missing > 0 => format!(
                    "pull {round}: asking for the run from block {tail_from} on ({missing} blocks missing)"
                ),
                None => format!("pull {round}: asking for the run from block {tail_from} on"),
            }),
            Progress::Backoff { wait, why } => self.say(&format!(
                "{why}: next pull in {:.1} s",
                wait.as_secs_f64()
            )),
            Progress::Lost(g) => self.say(&format!(
                "acquisition gap: the rig lost samples {}..{} ({} samples); the run goes on, and fits \
                 will not cross the gap",
                g.first_sample,
                g.first_sample as u64 + g.count as u64,
                g.count
            )),
            Progress::RateUsed { asked_hz, clock } => self.say(&format!(
                "sample clock: {} Hz / {} = {:.4} S/s (the timer cannot make {asked_hz} S/s exactly; \
                 the record's time axis uses the rate used)",
                clock.timer_hz,
                clock.ticks_per_sample,
                clock.rate_hz()
            )),
            Progress::Warning(w) => self.say(&format!("warning: {w}")),
            Progress::Ended(e) => {
                if let Some(b) = &self.bar {
                    b.set_position(1000);
                }
                self.say(&format!(
                    "run {} ended ({:?}): {} blocks, {} samples",
                    e.run_id, e.reason, e.blocks, e.samples
                ));
            }
        }
    }

    pub fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

fn num(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.5}")
    } else {
        "—".into()
    }
}

/// μ0/μ1 of the rig and of the host fit, side by side.
pub fn result_table(run: &Run) -> String {
    let mut s = String::new();
    let ob = run.result();
    let host = run.host_fit();
    let pm = |v: f32, se: f32| {
        if se.is_finite() && se > 0.0 {
            format!("{} ± {:.1e}", num(v as f64), se)
        } else {
            num(v as f64)
        }
    };
    s.push_str(&format!(
        "{:<10}{:<26}{}\n",
        "", "on-board", "host fit (Levenberg–Marquardt)"
    ));
    let (o0, o1) = ob.map_or(("—".into(), "—".into()), |r| {
        (pm(r.best.mu0, r.best.mu0_se), pm(r.best.mu1, r.best.mu1_se))
    });
    let pm64 = |v: f64, se: f64| {
        if se.is_finite() && se > 0.0 {
            format!("{} ± {:.1e}", num(v), se)
        } else {
            num(v)
        }
    };
    let (h0, h1) = host.map_or(("—".into(), "—".into()), |h| {
        (pm64(h.mu0, h.mu0_se), pm64(h.mu1, h.mu1_se))
    });
    s.push_str(&format!("{:<10}{:<26}{}\n", "μ0", o0, h0));
    s.push_str(&format!("{:<10}{:<26}{}\n", "μ1", o1, h1));
    if let Some(r) = ob {
        let hz = if r.frequency_hz.is_finite() {
            format!("{:.2} Hz", r.frequency_hz)
        } else {
            "no frequency".into()
        };
        s.push_str(&format!(
            "{:<10}{}, {} cycles, {hz}, envelope {}\n",
            "rig",
            r.verdict.name(),
            r.cycles,
            r.shape.name()
        ));
    }
    if let Some(h) = host {
        s.push_str(&format!(
            "{:<10}envelope misfit {:.2e} of A0, {}\n",
            "host",
            h.gap,
            h.verdict.as_deref().unwrap_or(if h.converged {
                "converged"
            } else {
                "not converged"
            })
        ));
    } else if let Some(e) = &run.results.host_error {
        s.push_str(&format!("{:<10}no fit: {e}\n", "host"));
    }
    if run.config().rig.load_n == 0.0 {
        s.push_str(&format!(
            "{:<10}the apparatus alone (load 0): no friction coefficient; μ1 is the blades' damping \
             μ_a (hold it in a contact's fit with `tribo fit --apparatus-mu1`)\n",
            "note"
        ));
    }
    if let (Some(h), Some(r)) = (host, ob) {
        if let Some(c) = crate::crosscheck::CrossCheck::of_stored(h, r) {
            s.push_str(&format!("{:<10}{}\n", "check", c.summary()));
        }
    }
    s
}

/// Prints what a recording gave and what to do if it is incomplete (an error if standard output
/// is closed).
pub fn print_outcome(o: &Outcome) -> anyhow::Result<()> {
    let run = &o.run;
    let samples: usize = run.blocks().map(|b| b.samples()).sum();
    let mut s = String::new();
    use std::fmt::Write;
    let _ = writeln!(
        s,
        "run {} saved in {} ({}, {} samples{})",
        run.id(),
        run.dir().display(),
        run.completeness().summary(),
        samples,
        match (o.pulled_blocks, o.pull_rounds) {
            (0, _) => String::new(),
            (n, r) => format!(
                ", {n} block{} fetched again in {r} pull{}",
                if n == 1 { "" } else { "s" },
                if r == 1 { "" } else { "s" }
            ),
        }
    );
    if run.lost_samples() > 0 {
        let spans = crate::load::gap_spans(run);
        let _ = writeln!(
            s,
            "acquisition gaps: the rig lost {} samples (samples {}); fits refuse to cross a gap: \
             `tribo fit {} {}` fits the longest stretch without one",
            run.lost_samples(),
            spans.join(", "),
            crate::LONGEST_CLEAN_STRETCH_FLAG,
            run.dir().display()
        );
    }
    if let Some(n) = &o.not_held {
        let _ = writeln!(s, "lost for good: {n}");
    }
    if let Some(e) = &o.link_lost {
        if e.kind == LinkErrorKind::NoAnswer {
            let _ = writeln!(s, "the rig stopped answering: {e}");
        } else {
            let _ = writeln!(s, "the link was lost: {e}");
        }
        if !run.is_complete() {
            let _ = writeln!(
                s,
                "the rig may still hold the rest: reconnect it and run `tribo pull {}`",
                run.dir().display()
            );
        }
    }
    if o.aborted {
        let _ = writeln!(s, "aborted: what was received is kept (status: aborted)");
    }
    s.push_str(&result_table(run));
    out(&s)
}

/// Tells the operator when the rig reset abnormally since the last host spoke to it.
pub fn warn_about_reset(link: &Link) {
    use tribo_wire::ResetCause;
    if let Some(b) = link.boot_report() {
        if matches!(
            b.cause,
            ResetCause::Watchdog | ResetCause::Panic | ResetCause::CpuFault | ResetCause::Brownout
        ) {
            crate::errln!(
                "warning: the rig reset by itself since a host last spoke to it: {}{}{} (see `tribo status`)",
                crate::link::reset_cause_text(b.cause),
                if b.message.is_empty() { "" } else { ": " },
                b.message
            );
        }
    }
}

/// Arguments of `tribo run`.
#[derive(clap::Args, Debug)]
pub struct Args {
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

/// Why no friction constant of a stored run could be printed: the host could not fit it (the
/// record is not analysable: the pin never moved, a channel stuck…), or its fit did not converge
/// (its constants are not trustworthy: `tribo fit` exits 3 on it too). `None` when the host's
/// constants are printed.
pub fn no_constant(run: &Run) -> Option<String> {
    if run.block_count() == 0 {
        return Some("the run holds no samples".into());
    }
    match run.host_fit() {
        Some(h) if !h.converged => Some(
            "the host's fit did not converge: its constants are not trustworthy (`tribo fit` \
             says more)"
                .into(),
        ),
        Some(h) if !(h.mu0.is_finite() || h.mu1.is_finite()) => {
            Some("the host's fit gave no finite constant".into())
        }
        Some(_) => None,
        None => Some(format!(
            "the host fitted nothing: {}",
            run.results
                .host_error
                .as_deref()
                .unwrap_or("the run was not analysed")
        )),
    }
}

/// The heater's settling rule (`tribo run --settle-tol/--settle-secs/--settle-timeout`, a
/// campaign's `settle_tol_c`, `settle_s`, `settle_timeout_s`) as a plate can meet it: a tolerance
/// above 0 (a reading never equals its setpoint: 0 waits the whole timeout) and inside the
/// heater's band (±[`limits::HEATER_BAND_C`], where the plate counts as at its setpoint), a time
/// of 0 s or more, and a timeout longer than that time.
///
/// [`limits::HEATER_BAND_C`]: tribo_wire::limits::HEATER_BAND_C
pub fn check_settle(tol_c: f32, settle_s: f64, timeout_s: f64) -> Result<(), String> {
    let band = tribo_wire::limits::HEATER_BAND_C;
    if !(tol_c.is_finite() && tol_c > 0.0 && tol_c < band) {
        return Err(format!(
            "the settle tolerance must be above 0 and below {band} °C (the heater's band; default {} °C)",
            tribo_wire::limits::SETTLE_TOL_C
        ));
    }
    if !(settle_s.is_finite() && settle_s >= 0.0) {
        return Err(format!(
            "the settle time must be 0 s or more (default {} s)",
            tribo_wire::limits::SETTLE_S
        ));
    }
    if !(timeout_s.is_finite() && timeout_s > settle_s) {
        return Err(format!(
            "the settle timeout must be longer than the settle time (default {} s)",
            tribo_wire::limits::SETTLE_TIMEOUT_S
        ));
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
