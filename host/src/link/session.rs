//! A whole run over a [`Link`]: configure, heat and settle, arm, release (or wait for the button),
//! stream into the run store with gap detection, and fill gaps with `Pull`; and `pull` of a run the
//! rig already took.

use super::{explain, explain_fault, firmware_version, Link, LinkError, LinkErrorKind};
use anyhow::{anyhow, bail, Context};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tribo_store::{Catalog, DeviceMeta, HostFit, Results, Run, RunMeta, RunWriter};
use tribo_wire::{
    Configure, DeviceInfo, DeviceMsg, ErrorCode, Gap, HeaterSetpoint, HostMsg, Interlock, RigState,
    RunEnd, RunHeader, SampleBlock, SampleClock,
};

/// Heat the plate to a setpoint and wait until it holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeaterPlan {
    pub setpoint_c: f32,
    pub ramp_c_per_min: f32,
    /// Settled when within this of the setpoint…
    pub tolerance_c: f32,
    /// …for this long.
    pub settle_s: f64,
    /// Give up after this long.
    pub timeout_s: f64,
}

impl HeaterPlan {
    /// Heat to `setpoint_c` at `ramp_c_per_min`, settled by the defaults of
    /// [`tribo_wire::limits`] (within [`tribo_wire::limits::SETTLE_TOL_C`] for
    /// [`tribo_wire::limits::SETTLE_S`], giving up after [`tribo_wire::limits::SETTLE_TIMEOUT_S`]).
    pub fn new(setpoint_c: f32, ramp_c_per_min: f32) -> HeaterPlan {
        HeaterPlan {
            setpoint_c,
            ramp_c_per_min,
            tolerance_c: tribo_wire::limits::SETTLE_TOL_C,
            settle_s: tribo_wire::limits::SETTLE_S,
            timeout_s: tribo_wire::limits::SETTLE_TIMEOUT_S,
        }
    }
}

/// Everything `tribo run` needs to take one run.
#[derive(Debug, Clone)]
pub struct RunPlan {
    pub config: Configure,
    /// `None`: heater off.
    pub heater: Option<HeaterPlan>,
    /// Wait for the rig's button instead of releasing from here.
    pub button: bool,
    /// Leave the heater on after the run (campaigns).
    pub keep_heater: bool,
    pub label: Option<String>,
    pub sample: Option<String>,
    pub lubricant: Option<String>,
    pub campaign: Option<String>,
    pub repeat: Option<u32>,
    /// Rig constants a default stood in for (recorded in the run's metadata).
    pub defaults: Vec<String>,
}

impl RunPlan {
    pub fn new(config: Configure) -> RunPlan {
        RunPlan {
            config,
            heater: None,
            button: false,
            keep_heater: false,
            label: None,
            sample: None,
            lubricant: None,
            campaign: None,
            repeat: None,
            defaults: Vec::new(),
        }
    }
}

/// What happens during a run, for a progress display.
#[derive(Debug)]
pub enum Progress<'a> {
    Heating {
        temp_c: f32,
        setpoint_c: f32,
        elapsed_s: f64,
    },
    WaitingForButton,
    Started {
        header: &'a RunHeader,
        dir: &'a Path,
    },
    /// A block arrived; `envelope_m` is the Mark & Crandall amplitude at its last sample.
    Block {
        block: &'a SampleBlock,
        envelope_m: f64,
        samples: u64,
        expected: u64,
    },
    Gap {
        from: u32,
        to: u32,
    },
    Pulling {
        from_block: u32,
    },
    /// The rig lost these samples (an acquisition gap); the run goes on.
    Lost(&'a Gap),
    /// The rig's sample clock is not exactly the rate asked for (the timer cannot make it).
    RateUsed {
        asked_hz: u32,
        clock: SampleClock,
    },
    Warning(String),
    Ended(&'a RunEnd),
}

/// How a recording ended.
#[derive(Debug)]
pub struct Outcome {
    pub run: Run,
    pub aborted: bool,
    /// The link was lost before the run was complete: `tribo pull` can fetch the rest.
    pub link_lost: Option<LinkError>,
    /// Blocks that arrived through `Pull` rather than live.
    pub pulled_blocks: usize,
    pub warnings: Vec<String>,
}

enum StreamEnd {
    Ended,
    Aborted,
    Lost(LinkError),
}

/// Builds the run writer when the run's header arrives.
type MakeWriter<'a> = dyn FnMut(&RunHeader) -> anyhow::Result<RunWriter> + 'a;

struct Streamer<'a, 'o> {
    link: &'a mut Link,
    writer: Option<RunWriter>,
    make: &'a mut MakeWriter<'a>,
    abort: &'a AtomicBool,
    obs: &'a mut (dyn FnMut(Progress<'_>) + 'o),
    warnings: Vec<String>,
    pulled: usize,
    pulling: bool,
    /// Blocks missing when the last pull was sent (no progress = the rig no longer has them).
    last_pull_missing: Option<Vec<u32>>,
    /// A header that differs from the stored one starts a new folder (else it is an error).
    new_on_mismatch: bool,
}

/// Bit-for-bit equality of two wire values (NaN included), by their encoding.
fn same<T: serde::Serialize>(a: T, b: T) -> bool {
    match (
        tribo_wire::frame::encode_vec(0, &a),
        tribo_wire::frame::encode_vec(0, &b),
    ) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Blocks a pull could not bring back, as ranges, with why.
fn lost_blocks_message(missing: &[u32]) -> String {
    let mut ranges: Vec<String> = vec![];
    let mut i = 0;
    while i < missing.len() {
        let mut j = i;
        while j + 1 < missing.len() && missing[j + 1] == missing[j] + 1 {
            j += 1;
        }
        ranges.push(if i == j {
            format!("{}", missing[i])
        } else {
            format!("{}–{}", missing[i], missing[j])
        });
        i = j + 1;
    }
    format!(
        "{} sample blocks ({}) are no longer held by the rig, so they are lost and the run is stored incomplete: \
         the rig keeps a whole run in RAM and flash (about 60 s with all five channels at 10 kS/s; after a power \
         cut, what its flash held, about the first 35 s), and this one was longer or the power went during it",
        missing.len(),
        ranges.join(", ")
    )
}

fn envelope(h: &RunHeader, b: &SampleBlock) -> f64 {
    let cfg = &h.config;
    let (Some(px), Some(pv)) = (
        cfg.channels.position(tribo_wire::Channel::Displacement),
        cfg.channels.position(tribo_wire::Channel::Velocity),
    ) else {
        return f64::NAN;
    };
    let Some(s) = b.samples().checked_sub(1).and_then(|i| b.sample(i)) else {
        return f64::NAN;
    };
    let x = cfg.calibration[0].to_si(s[px]) as f64;
    let v = cfg.calibration[1].to_si(s[pv]) as f64;
    let w = cfg.omega() as f64;
    (x * x + (v / w).powi(2)).sqrt()
}

impl Streamer<'_, '_> {
    fn file(&mut self, f: super::Incoming) -> anyhow::Result<Option<StreamEnd>> {
        match &f.frame.msg {
            DeviceMsg::RunStarted(h) => {
                let stored = self.writer.as_ref().and_then(|w| w.header().copied());
                if let Some(old) = stored.filter(|old| !same(*old, *h)) {
                    self.mismatch(&format!(
                        "released at device time {} µs, the stored one at {} µs",
                        h.t_us, old.t_us
                    ))?;
                }
                if self.writer.is_none() {
                    self.writer = Some((self.make)(h)?);
                }
                let w = self.writer.as_mut().expect("just created");
                if w.header().is_none() {
                    w.append_frame(&f.raw)?;
                    let dir = w.dir().to_owned();
                    (self.obs)(Progress::Started {
                        header: h,
                        dir: &dir,
                    });
                    if h.clock.is_valid() && !h.clock.is_exactly(h.config.sample_rate_hz) {
                        (self.obs)(Progress::RateUsed {
                            asked_hz: h.config.sample_rate_hz,
                            clock: h.clock,
                        });
                    }
                }
            }
            DeviceMsg::Gap(_) | DeviceMsg::EcrRange(_) => {
                // Run events: stored with the run once (a Pull sends them again).
                let Some(w) = self.writer.as_mut() else {
                    return Ok(None);
                };
                if !w.has_event(&f.frame.msg) {
                    if w.is_complete() {
                        // A run stored whole gets no new events: this is another run.
                        self.mismatch(
                            "it reports an acquisition event the stored run does not have",
                        )?;
                        return Ok(None);
                    }
                    w.append_frame(&f.raw)?;
                    if let DeviceMsg::Gap(g) = &f.frame.msg {
                        (self.obs)(Progress::Lost(g));
                    }
                }
            }
            DeviceMsg::Samples(b) => return self.file_block(&f.raw, b),
            DeviceMsg::Packed(p) => match p.unpack() {
                Ok(b) => return self.file_block(&f.raw, &b),
                Err(e) => {
                    let msg = format!(
                        "sample block {} of run {} arrived intact but its counts do not decode ({e}): \
                         is this tribo older than the rig's firmware?",
                        p.block, p.run_id
                    );
                    self.warnings.push(msg.clone());
                    (self.obs)(Progress::Warning(msg));
                }
            },
            DeviceMsg::Result(r) => {
                if let Some(old) = self.writer.as_ref().and_then(|w| w.onboard().copied()) {
                    if !same(old, *r) {
                        self.mismatch("its on-board result differs from the stored one")?;
                    }
                    return Ok(None);
                }
                if let Some(w) = self.writer.as_mut() {
                    w.append_frame(&f.raw)?;
                }
            }
            DeviceMsg::RunEnded(e) => {
                if let Some(w) = self.writer.as_mut() {
                    w.append_frame(&f.raw)?;
                }
                (self.obs)(Progress::Ended(e));
                return Ok(Some(StreamEnd::Ended));
            }
            DeviceMsg::Error(e) if e.about_seq.is_none() => {
                let msg = explain(e.code);
                self.warnings.push(msg.clone());
                (self.obs)(Progress::Warning(msg));
            }
            DeviceMsg::Fault(r) => {
                let msg = format!("the rig made itself safe: {}", explain_fault(r));
                self.warnings.push(msg.clone());
                (self.obs)(Progress::Warning(msg));
            }
            _ => {}
        }
        Ok(None)
    }

    /// Files a sample block (from a v1 `Samples` or an unpacked v2 `Packed` frame, `raw`).
    fn file_block(&mut self, raw: &[u8], b: &SampleBlock) -> anyhow::Result<Option<StreamEnd>> {
        let Some(w) = self.writer.as_mut() else {
            return Ok(None);
        }; // before its header: pulled later
        if let Some(old) = w.block(b.block) {
            if !same(old, b) {
                self.mismatch(&format!(
                    "its block {} differs from the stored one",
                    b.block
                ))?;
            }
            return Ok(None);
        }
        let next = w.resume_from();
        let last_seen = w.blocks() as u32;
        w.append_frame(raw)?;
        if self.pulling {
            self.pulled += 1;
        }
        if b.block > next && b.block >= last_seen && !self.pulling {
            (self.obs)(Progress::Gap {
                from: next,
                to: b.block,
            });
        }
        if let Some(h) = w.header().copied() {
            let samples = (b.first_sample as u64) + b.samples() as u64;
            let env = envelope(&h, b);
            (self.obs)(Progress::Block {
                block: b,
                envelope_m: env,
                samples,
                expected: h.config.max_samples() as u64,
            });
        }
        Ok(None)
    }

    /// The rig's run is not the stored one: an error, or (pulling with no folder named) a new
    /// folder for the rig's run.
    fn mismatch(&mut self, what: &str) -> anyhow::Result<()> {
        let dir = self
            .writer
            .as_ref()
            .map(|w| w.dir().display().to_string())
            .unwrap_or_default();
        if !self.new_on_mismatch {
            bail!(
                "the rig's run is not the run stored in {dir} ({what}): the rig was restarted since. Fetch the \
                 rig's run into a new folder with `tribo pull` (no folder argument)"
            );
        }
        let msg = format!(
            "{dir} holds an older run with the same number ({what}; the rig was restarted since): fetching the \
             rig's run into a new folder"
        );
        self.warnings.push(msg.clone());
        (self.obs)(Progress::Warning(msg));
        self.writer = None;
        self.last_pull_missing = None;
        Ok(())
    }

    /// Receives until the run's end, an abort, or a lost link.
    fn stream(&mut self) -> anyhow::Result<StreamEnd> {
        let mut abort_deadline: Option<Instant> = None;
        let mut last_frame = Instant::now();
        loop {
            if self.abort.load(Ordering::Relaxed) && abort_deadline.is_none() {
                // Best effort: if the rig does not hear it, the run ends by itself anyway.
                let _ = self.link.command(HostMsg::Abort);
                abort_deadline = Some(Instant::now() + Duration::from_secs(3));
            }
            if abort_deadline.is_some_and(|d| Instant::now() > d) {
                return Ok(StreamEnd::Aborted);
            }
            match self.link.next(Duration::from_millis(200)) {
                Ok(Some(f)) => {
                    last_frame = Instant::now();
                    if let Some(end) = self.file(f)? {
                        return Ok(if abort_deadline.is_some() {
                            StreamEnd::Aborted
                        } else {
                            end
                        });
                    }
                }
                Ok(None) => {
                    if last_frame.elapsed() >= self.link.timeouts.stream_idle {
                        match self.link.status() {
                            Ok(s) => {
                                last_frame = Instant::now();
                                let waiting =
                                    matches!(s.state, RigState::Running | RigState::Armed);
                                if !waiting
                                    && self.writer.as_ref().is_some_and(|w| w.header().is_some())
                                {
                                    // The end frame was lost: Pull fills in.
                                    return Ok(StreamEnd::Ended);
                                }
                                if !waiting && abort_deadline.is_some() {
                                    return Ok(StreamEnd::Aborted);
                                }
                                if matches!(s.state, RigState::Fault) {
                                    bail!(
                                        "the rig went into fault before the run started ({}); check the heater and \
                                         the magnet, then run again",
                                        self.warnings.last().map_or("no reason given", String::as_str)
                                    );
                                }
                                if !waiting && !self.pulling && self.writer.is_none() {
                                    bail!(
                                        "the rig is no longer armed and no run started ({}): arm and release again \
                                         (with --button, press it within the magnet's hold limit)",
                                        self.warnings.last().map_or("no reason given", String::as_str)
                                    );
                                }
                            }
                            Err(e) => return Ok(StreamEnd::Lost(e)),
                        }
                    }
                }
                Err(e) => return Ok(StreamEnd::Lost(e)),
            }
        }
    }

    /// Pulls what is missing until the run is complete (a few attempts).
    fn fill(&mut self) -> anyhow::Result<Option<LinkError>> {
        for _ in 0..4 {
            let Some(w) = self.writer.as_ref() else {
                return Ok(None);
            };
            if w.is_complete() {
                return Ok(None);
            }
            let Some(run_id) = w.meta().device_run_id else {
                return Ok(None);
            };
            let from_block = w.resume_from();
            let missing_before = w.missing_blocks();
            if self.last_pull_missing.as_ref() == Some(&missing_before)
                && !missing_before.is_empty()
            {
                // The rig answered a pull without them: its memory no longer holds them.
                let msg = lost_blocks_message(&missing_before);
                self.warnings.push(msg.clone());
                (self.obs)(Progress::Warning(msg));
                return Ok(None);
            }
            self.last_pull_missing = Some(missing_before);
            (self.obs)(Progress::Pulling { from_block });
            self.pulling = true;
            match self.link.command(HostMsg::Pull { run_id, from_block }) {
                Ok(()) => {}
                Err(e) if e.code == Some(ErrorCode::NoRun) => {
                    let msg = format!("cannot complete the run: {}", e.msg);
                    self.warnings.push(msg.clone());
                    (self.obs)(Progress::Warning(msg));
                    return Ok(None);
                }
                Err(e) if e.kind == LinkErrorKind::Closed || e.kind == LinkErrorKind::NoAnswer => {
                    return Ok(Some(e))
                }
                Err(e) => return Err(e.into()),
            }
            match self.stream()? {
                StreamEnd::Ended => {}
                StreamEnd::Aborted => return Ok(None),
                StreamEnd::Lost(e) => return Ok(Some(e)),
            }
        }
        Ok(None)
    }
}

fn device_meta(info: &DeviceInfo, port: &str) -> DeviceMeta {
    DeviceMeta {
        firmware: firmware_version(info),
        serial: format!("{:016x}", info.serial),
        protocol: info.protocol,
        port: port.to_string(),
    }
}

/// Heats to the plan's setpoint and waits until the plate holds it.
pub fn settle(
    link: &mut Link,
    h: &HeaterPlan,
    abort: &AtomicBool,
    obs: &mut dyn FnMut(Progress<'_>),
) -> anyhow::Result<()> {
    let sp = HeaterSetpoint {
        setpoint_c: h.setpoint_c,
        ramp_c_per_min: h.ramp_c_per_min,
    };
    if sp.validate().is_err() {
        bail!(
            "heater setpoint {} °C at {} °C/min is out of range: the plate takes 15–100 °C, ramps of 0.1–30 °C/min",
            h.setpoint_c,
            h.ramp_c_per_min
        );
    }
    link.command(HostMsg::SetHeater(sp))?;
    let start = Instant::now();
    let mut stable_since: Option<Instant> = None;
    let mut first: Option<tribo_wire::Status> = None;
    loop {
        if abort.load(Ordering::Relaxed) {
            let _ = link.command(HostMsg::HeaterOff);
            bail!("interrupted while heating; the heater was switched off");
        }
        let s = link.status()?;
        if let Some(f) = s.heater_fault {
            bail!("{}", explain(ErrorCode::Heater(f)));
        }
        let before = *first.get_or_insert(s);
        if s.uptime_ms < before.uptime_ms || s.reset_cause != before.reset_cause {
            bail!(
                "the rig reset itself while heating ({}): it is safe, with the heater off; `tribo status` \
                 says more, then run again",
                super::reset_cause_text(s.reset_cause)
            );
        }
        if s.heater_setpoint_c.is_none() {
            // Switched off by the rig itself (lease, stand-alone limit) or by another program.
            bail!(
                "the rig switched the heater off while it was heating ({}); run again to heat again",
                s.last_fault
                    .map(|f| explain_fault(&f))
                    .unwrap_or_else(|| "no fault reported: another program sent heater-off or safe".into())
            );
        }
        obs(Progress::Heating {
            temp_c: s.temp_c,
            setpoint_c: h.setpoint_c,
            elapsed_s: start.elapsed().as_secs_f64(),
        });
        if (s.temp_c - h.setpoint_c).abs() <= h.tolerance_c {
            let since = *stable_since.get_or_insert_with(Instant::now);
            if since.elapsed().as_secs_f64() >= h.settle_s {
                return Ok(());
            }
        } else {
            stable_since = None;
        }
        if start.elapsed().as_secs_f64() > h.timeout_s {
            bail!(
                "the plate did not settle at {} °C within {:.0} s (it is at {:.1} °C): raise --settle-timeout or \
                 --settle-tol, or check the heater",
                h.setpoint_c,
                h.timeout_s,
                s.temp_c
            );
        }
        // Stale frames (none are expected while idle) are dropped with the wait.
        let _ = link.drain(Duration::from_millis(300))?;
    }
}

/// Takes one run: configure, heat, arm, release, stream into a new run folder under `store`,
/// complete it with `Pull` if frames were lost, then fit and catalog it.
pub fn record_run(
    link: &mut Link,
    info: &DeviceInfo,
    store: &Path,
    plan: &RunPlan,
    abort: &AtomicBool,
    obs: &mut dyn FnMut(Progress<'_>),
) -> anyhow::Result<Outcome> {
    if let Err(f) = plan.config.validate() {
        bail!(
            "configuration refused before sending: {} is out of range",
            format!("{f:?}").to_lowercase()
        );
    }
    if let Some(h) = &plan.heater {
        if (HeaterSetpoint {
            setpoint_c: h.setpoint_c,
            ramp_c_per_min: h.ramp_c_per_min,
        })
        .validate()
        .is_err()
        {
            bail!(
                "heater setpoint {} °C at {} °C/min is out of range: the plate takes 15–100 °C, ramps of 0.1–30 °C/min",
                h.setpoint_c,
                h.ramp_c_per_min
            );
        }
    }
    link.command(HostMsg::Configure(plan.config))?;
    match &plan.heater {
        Some(h) => settle(link, h, abort, obs)?,
        None => link.command(HostMsg::HeaterOff)?,
    }
    if abort.load(Ordering::Relaxed) {
        bail!("interrupted before the release; nothing was recorded");
    }
    link.command(HostMsg::Arm)?;
    if plan.button {
        obs(Progress::WaitingForButton);
    } else {
        // The acquisition may need a moment after arming: retry an interlock refusal briefly.
        let t0 = Instant::now();
        loop {
            match link.command(HostMsg::Release) {
                Ok(()) => break,
                Err(e)
                    if matches!(e.code, Some(ErrorCode::Interlock(Interlock::NotSampling)))
                        && t0.elapsed() < Duration::from_secs(3) =>
                {
                    std::thread::sleep(Duration::from_millis(50));
                }
                Err(e) => {
                    let _ = link.command(HostMsg::Disarm);
                    return Err(e.into());
                }
            }
        }
    }
    let port = link.name().to_string();
    let mut make = |h: &RunHeader| -> anyhow::Result<RunWriter> {
        let mut meta = RunMeta::new(h.config);
        meta.label = plan.label.clone();
        meta.sample = plan.sample.clone();
        meta.lubricant = plan.lubricant.clone();
        meta.campaign = plan.campaign.clone();
        meta.repeat = plan.repeat;
        meta.defaults = plan.defaults.clone();
        meta.temp_setpoint_c = plan.heater.map(|h| h.setpoint_c as f64);
        meta.device = Some(device_meta(info, &port));
        Ok(RunWriter::create(store, meta)?)
    };
    let mut s = Streamer {
        link,
        writer: None,
        make: &mut make,
        abort,
        obs,
        warnings: vec![],
        pulled: 0,
        pulling: false,
        last_pull_missing: None,
        new_on_mismatch: false,
    };
    let end = s.stream()?;
    let (aborted, mut lost) = match end {
        StreamEnd::Ended => (false, None),
        StreamEnd::Aborted => (true, None),
        StreamEnd::Lost(e) => (false, Some(e)),
    };
    if !aborted && lost.is_none() {
        lost = s.fill()?;
    }
    let Streamer {
        writer,
        warnings,
        pulled,
        link,
        ..
    } = s;
    if !plan.keep_heater && plan.heater.is_some() && lost.is_none() {
        let _ = link.command(HostMsg::HeaterOff);
    }
    let Some(writer) = writer else {
        return Err(match lost {
            Some(e) => anyhow!(e).context("the run never started"),
            None => anyhow!("the rig never started the run (no run header arrived); check the magnet and run again"),
        });
    };
    let mut run = writer.finish(aborted)?;
    analyse_and_catalog(&mut run, store)?;
    Ok(Outcome {
        run,
        aborted,
        link_lost: lost,
        pulled_blocks: pulled,
        warnings,
    })
}

/// Fetches the rig's last run (or completes `target`, a run folder), resuming after the last block
/// already stored. With `salvage`, a corrupt log is cut after its intact prefix first.
pub fn pull_run(
    link: &mut Link,
    info: &DeviceInfo,
    store: &Path,
    target: Option<&Path>,
    salvage: bool,
    obs: &mut dyn FnMut(Progress<'_>),
) -> anyhow::Result<Outcome> {
    let status = link.status()?;
    let serial = format!("{:016x}", info.serial);
    if status.run_id == 0 {
        bail!("the rig holds no run yet (it was power-cycled since, or never ran): take one with `tribo run`");
    }
    let dir: Option<PathBuf> = match target {
        Some(t) => Some(t.to_owned()),
        None => find_run(store, &serial, status.run_id)?,
    };
    let mut writer = None;
    let mut warnings = vec![];
    if let Some(dir) = &dir {
        let (w, rec) = RunWriter::resume(dir, salvage)
            .with_context(|| format!("cannot resume {}", dir.display()))?;
        if let Some(r) = rec {
            let msg = format!("{}: {r}", dir.display());
            obs(Progress::Warning(msg.clone()));
            warnings.push(msg);
        }
        let m = w.meta();
        if let Some(d) = &m.device {
            if d.serial != serial {
                bail!("{} was taken on rig {} but this is rig {serial}: connect that rig, or run `tribo pull` without a folder to fetch this rig's last run", dir.display(), d.serial);
            }
        }
        if m.device_run_id.is_some_and(|id| id != status.run_id) {
            bail!(
                "{} is the rig's run {}, but the rig now holds run {} (a newer run replaced it): that run cannot be \
                 completed; `tribo pull` without a folder fetches the newer one",
                dir.display(),
                m.device_run_id.unwrap_or(0),
                status.run_id
            );
        }
        writer = Some(w);
    }
    let port = link.name().to_string();
    let mut make = |h: &RunHeader| -> anyhow::Result<RunWriter> {
        let mut meta = RunMeta::new(h.config);
        meta.label = Some("pulled".into());
        meta.device = Some(device_meta(info, &port));
        Ok(RunWriter::create(store, meta)?)
    };
    let running = matches!(status.state, RigState::Running);
    let mut s = Streamer {
        link,
        writer,
        make: &mut make,
        abort: &AtomicBool::new(false),
        obs,
        warnings,
        pulled: 0,
        pulling: true,
        last_pull_missing: None,
        new_on_mismatch: target.is_none(),
    };
    if running {
        // Take the rest of the live stream first.
        if let StreamEnd::Lost(e) = s.stream()? {
            return Err(e.into());
        }
    }
    {
        // Always pull, if only the header (from past the last block) of a complete run: the
        // header tells whether the stored run is the rig's run or an older one with its number.
        // One block already held is asked again: the rig's copy must be identical.
        let from_block = s.writer.as_ref().map_or(0, |w| {
            if w.is_complete() {
                (w.blocks() as u32).saturating_sub(1)
            } else if w.header().is_some() {
                w.resume_from().saturating_sub(1)
            } else {
                0
            }
        });
        if s.writer.as_ref().is_none_or(|w| !w.is_complete()) {
            (s.obs)(Progress::Pulling { from_block });
        }
        s.link.command(HostMsg::Pull {
            run_id: status.run_id,
            from_block,
        })?;
        match s.stream()? {
            StreamEnd::Lost(e) => {
                if let Some(w) = s.writer.take() {
                    let _ = w.finish(false);
                }
                return Err(e.into());
            }
            _ => {
                if s.writer.is_none() {
                    // The stored run was another one: the rig's run from its start, in a new folder.
                    (s.obs)(Progress::Pulling { from_block: 0 });
                    s.link.command(HostMsg::Pull {
                        run_id: status.run_id,
                        from_block: 0,
                    })?;
                    if let StreamEnd::Lost(e) = s.stream()? {
                        return Err(e.into());
                    }
                }
                if let Some(e) = s.fill()? {
                    return Err(e.into());
                }
            }
        }
    }
    let Streamer {
        writer,
        warnings,
        pulled,
        ..
    } = s;
    let writer = writer.ok_or_else(|| {
        anyhow!(
            "the rig sent no run header for run {}: try again",
            status.run_id
        )
    })?;
    let mut run = writer.finish(false)?;
    analyse_and_catalog(&mut run, store)?;
    Ok(Outcome {
        run,
        aborted: false,
        link_lost: None,
        pulled_blocks: pulled,
        warnings,
    })
}

/// The stored run taken on rig `serial` as its run `run_id`, if any (newest first).
pub fn find_run(store: &Path, serial: &str, run_id: u32) -> anyhow::Result<Option<PathBuf>> {
    let mut dirs = tribo_store::run::list_run_dirs(store)?;
    dirs.reverse();
    for d in dirs {
        let Ok(text) = std::fs::read_to_string(d.join(tribo_store::run::META_FILE)) else {
            continue;
        };
        let Ok(m) = toml::from_str::<RunMeta>(&text) else {
            continue;
        };
        if m.device_run_id == Some(run_id) && m.device.as_ref().is_some_and(|x| x.serial == serial)
        {
            return Ok(Some(d));
        }
    }
    Ok(None)
}

/// The host's Coulomb–viscous fit of a run (Levenberg–Marquardt on the envelope).
pub fn host_fit(run: &Run) -> Result<HostFit, String> {
    use tribo_physics::identify::{fit, FitOptions};
    if run.gaps().next().is_some() {
        return Err(format!(
            "the rig lost {} samples in {} acquisition gap(s): not fitted across them; \
             `tribo fit {} {}` fits the longest stretch without one",
            run.lost_samples(),
            run.gaps().count(),
            crate::LONGEST_CLEAN_STRETCH_FLAG,
            run.dir().display()
        ));
    }
    let rec = run.record().map_err(|e| e.msg)?;
    rec.validate().map_err(|e| e.0)?;
    let r = fit(
        &rec,
        tribo_physics::LawSpec::CoulombViscous,
        &FitOptions::default(),
    )
    .map_err(|e| e.to_string())?;
    Ok(HostFit {
        law: r.law.clone(),
        mu0: r.mu.first().copied().unwrap_or(f64::NAN),
        mu1: r.mu.get(1).copied().unwrap_or(f64::NAN),
        gap: r.gap,
        converged: r.converged,
        mu0_se: r.mu_se.first().copied().unwrap_or(f64::NAN),
        mu1_se: r.mu_se.get(1).copied().unwrap_or(f64::NAN),
        verdict: Some(r.verdict.name().into()),
    })
}

/// Fits the run on the host, saves the results and the CSV export, and catalogs it.
pub fn analyse_and_catalog(run: &mut Run, store: &Path) -> anyhow::Result<()> {
    let mut results = Results {
        onboard: run.result().copied(),
        host: None,
        host_error: None,
    };
    if run.block_count() > 0 {
        match host_fit(run) {
            Ok(f) => results.host = Some(f),
            Err(e) => results.host_error = Some(e),
        }
        run.export_csv(&run.dir().join(tribo_store::run::CSV_FILE))?;
    }
    run.save_results(results)?;
    Catalog::open(store)?.upsert(run)?;
    Ok(())
}
