//! What the rig commands show while a run is taken and after: the progress bar and messages
//! ([`Ui`]), the result table, the outcome of a recording, the rig's interlocks for `--help`, and
//! the Ctrl-C flag they share (`tribo run`, `demo`, `campaign`, `pull`, the panel).

use crate::link::session::{Outcome, Progress};
use crate::link::{Link, LinkErrorKind};
use indicatif::{ProgressBar, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::Duration;
use tribo_store::Run;

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

/// Progress bar and messages for a run.
pub struct Ui {
    bar: Option<ProgressBar>,
    quiet: bool,
    /// Release amplitude (m) and sample rate of the run in progress.
    a0: f64,
    rate: f64,
}

impl Ui {
    /// A progress display on standard error; `quiet`: none.
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

    /// Clears the progress bar, if one is shown.
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
    // The velocity input against the displacement's derivative over the first cycles: the one
    // swap of input cables the self-test cannot see at rest (velocity ↔ force).
    if run.block_count() > 0 && run.gaps().next().is_none() {
        if let Some(c) = run
            .record()
            .ok()
            .and_then(|r| crate::analysis::identity::record_velocity_check(&r))
        {
            let _ = writeln!(s, "{:<10}{}", "channels", c.text());
        }
    }
    crate::out::text(&s)
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
