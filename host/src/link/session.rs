//! A whole run over a [`Link`]: configure, heat and settle, arm, release (or wait for the button),
//! stream into the run store with gap detection, and fill gaps with `Pull`; and `pull` of a run the
//! rig already took.

pub use super::plan::{HeaterPlan, RunPlan};
pub use super::progress::Progress;
use super::stream::{StreamEnd, Streamer};
use super::{explain, explain_fault, firmware_version, Link, LinkError, LinkErrorKind};
use crate::archive::{analyse_and_catalog, find_run};
use anyhow::{anyhow, bail, Context};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tribo_store::{DeviceMeta, Run, RunMeta, RunWriter};
use tribo_wire::{DeviceInfo, ErrorCode, HeaterSetpoint, HostMsg, Interlock, RunHeader};

/// How a recording or a pull ended.
#[derive(Debug)]
pub struct Outcome {
    /// The run as stored.
    pub run: Run,
    /// The run was stopped before its end (Ctrl-C, a signal, the rig's stop).
    pub aborted: bool,
    /// The link was lost (or the rig stopped answering) before the run was complete: the rig may
    /// still hold what is missing, and `tribo pull` fetches it.
    pub link_lost: Option<LinkError>,
    /// Blocks that arrived through a pull rather than live.
    pub pulled_blocks: usize,
    /// Pull rounds made (each asks for missing blocks, then the run's end).
    pub pull_rounds: u32,
    /// What the rig does not hold any more, as the rig showed it (it answered `NoRun`, or never
    /// sent these frames in the pulls it answered): lost for good.
    pub not_held: Option<String>,
    /// What the operator should know about the run (printed after it).
    pub warnings: Vec<String>,
}

impl Outcome {
    /// Every frame of the run is stored.
    pub fn is_complete(&self) -> bool {
        self.run.is_complete()
    }

    /// The error a command that took or fetched this run returns when the run is not stored whole
    /// (exit status 3): how much is held, why the rest is not, and what to do. `None` when whole.
    pub fn incomplete(&self) -> Option<crate::exit::Incomplete> {
        if self.run.is_complete() {
            return None;
        }
        let dir = self.run.dir().display();
        let next = if let Some(n) = &self.not_held {
            n.clone()
        } else if let Some(e) = &self.link_lost {
            format!(
                "{} ({e}); the rig may still hold the rest: reconnect it and run `tribo pull {dir}`",
                if e.kind == LinkErrorKind::NoAnswer {
                    "the rig stopped answering"
                } else {
                    "the link was lost"
                }
            )
        } else if self.aborted {
            format!("aborted before the whole run arrived; `tribo pull {dir}` fetches what the rig holds")
        } else {
            format!("`tribo pull {dir}` asks the rig again")
        };
        Some(crate::exit::Incomplete(format!(
            "run {} is {}: {next}",
            self.run.id(),
            self.run.completeness().summary()
        )))
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
            return Err(crate::exit::Interrupted(
                "interrupted while heating; the heater was switched off".into(),
            )
            .into());
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
        return Err(crate::exit::Interrupted(
            "interrupted before the release; nothing was recorded".into(),
        )
        .into());
    }
    let previous_run = arm(link, info, store)?;
    if plan.button {
        obs(Progress::WaitingForButton);
    } else {
        release(link)?;
    }
    stream_run(link, info, store, plan, previous_run, abort, obs)
}

/// Arms the rig for a run filed in `store`; returns the rig's run number before it (frames of
/// that run still on their way are not the new run's). First the rig is told the highest run
/// number of it the store holds ([`HostMsg::RunFloor`]): a rig whose power went after a release,
/// before the run's header reached its flash, would give that number again. (A firmware older
/// than `RunFloor` refuses it as malformed: it is armed all the same. A store that cannot be
/// listed tells no floor: writing the run there fails later, and says why.)
pub fn arm(link: &mut Link, info: &DeviceInfo, store: &Path) -> Result<u32, LinkError> {
    let serial = format!("{:016x}", info.serial);
    if let Some(run_id) = crate::archive::highest_run(store, &serial).ok().flatten() {
        match link.command(HostMsg::RunFloor { run_id }) {
            Ok(()) => {}
            Err(e) if e.code == Some(ErrorCode::Malformed) => {}
            Err(e) => return Err(e),
        }
    }
    let previous_run = link.status()?.run_id;
    link.command(HostMsg::Arm)?;
    Ok(previous_run)
}

/// Releases the armed pin: `Release`, retried for up to 3 s while the rig is still starting (the
/// acquisition not sampling yet, the plate's temperature not read yet). Any other refusal disarms
/// the rig and is returned: the rig's own rule, in words.
pub fn release(link: &mut Link) -> Result<(), LinkError> {
    let t0 = Instant::now();
    loop {
        match link.command(HostMsg::Release) {
            Ok(()) => return Ok(()),
            Err(e) if t0.elapsed() < Duration::from_secs(3) && still_starting(link, &e) => {
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(e) => {
                let _ = link.command(HostMsg::Disarm);
                return Err(e);
            }
        }
    }
}

/// Whether a refused `Release` is a wait, not a rule: the acquisition not sampling yet after
/// arming (`NotSampling`), or the plate's temperature not read yet (the thermocouple's first
/// conversion after a boot: `HeaterUnhealthy` while the status shows no heater fault and no
/// temperature). A real heater fault shows in the status and is reported at once.
fn still_starting(link: &mut Link, e: &LinkError) -> bool {
    match e.code {
        Some(ErrorCode::Interlock(Interlock::NotSampling)) => true,
        Some(ErrorCode::Interlock(Interlock::HeaterUnhealthy)) => link
            .status()
            .is_ok_and(|s| s.heater_fault.is_none() && !s.temp_c.is_finite()),
        _ => false,
    }
}

/// After the release (or while waiting for the button): streams the run into a new run folder
/// under `store`, completes it with `Pull` if frames were lost, then fits and catalogs it.
/// `previous_run` is the rig's run id before arming (frames of that run still on their way are
/// not this run's). [`record_run`] is configure, heat, arm, [`release`], then this.
pub fn stream_run(
    link: &mut Link,
    info: &DeviceInfo,
    store: &Path,
    plan: &RunPlan,
    previous_run: u32,
    abort: &AtomicBool,
    obs: &mut dyn FnMut(Progress<'_>),
) -> anyhow::Result<Outcome> {
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
        new_on_mismatch: false,
        run_id: None,
        min_run: previous_run.wrapping_add(1),
        verified: true,
        pending: vec![],
        asked_header: false,
        rounds: 0,
        not_held: None,
    };
    let end = s.stream()?;
    let (aborted, mut lost) = match end {
        StreamEnd::Ended => (false, None),
        StreamEnd::Aborted => (true, None),
        StreamEnd::Lost(e) => (false, Some(e)),
    };
    if !aborted && lost.is_none() {
        lost = s.fill(false)?;
    }
    let Streamer {
        writer,
        warnings,
        pulled,
        link,
        rounds,
        not_held,
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
        pull_rounds: rounds,
        not_held,
        warnings,
    })
}

/// The rig no longer holds the run a folder is a copy of (a newer run replaced it, or it was
/// lost): nothing of it can be fetched. The folder (resumed, and repaired if salvaging) is what
/// there is of it; whether that is the whole run the folder says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunNotHeld(pub String);

impl std::fmt::Display for RunNotHeld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RunNotHeld {}

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
        match m.device_run_id {
            Some(id) if id < status.run_id => {
                return Err(RunNotHeld(format!(
                    "{} is the rig's run {id}, but the rig now holds run {} (a newer run replaced it): \
                     nothing more of that run can be fetched; `tribo pull` without a folder fetches the newer one",
                    dir.display(),
                    status.run_id
                ))
                .into())
            }
            Some(id) if id > status.run_id => {
                return Err(RunNotHeld(format!(
                    "{} is the rig's run {id}, but the rig holds run {} only: it lost run {id} (its power \
                     went before the run reached its flash): what the folder holds is all there is of that run",
                    dir.display(),
                    status.run_id
                ))
                .into())
            }
            _ => {}
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
    let mut s = Streamer {
        link,
        writer,
        make: &mut make,
        abort: &AtomicBool::new(false),
        obs,
        warnings,
        pulled: 0,
        pulling: true,
        new_on_mismatch: target.is_none(),
        run_id: Some(status.run_id),
        min_run: status.run_id,
        verified: false,
        pending: vec![],
        asked_header: false,
        rounds: 0,
        not_held: None,
    };
    // Every pull first asks for the run's end (and, if the rig is still running it, follows the
    // live stream to it): the header that comes with it says whether the stored run is the rig's
    // run or an older one with its number. Then what is missing, range by range.
    let lost = s.fill(true)?;
    let Streamer {
        writer,
        warnings,
        pulled,
        rounds,
        not_held,
        ..
    } = s;
    let Some(writer) = writer else {
        return Err(match lost {
            Some(e) => anyhow!(e).context(format!("fetching run {}", status.run_id)),
            None => anyhow!(
                "the rig sent no run header for run {}: try again",
                status.run_id
            ),
        });
    };
    let mut run = writer.finish(false)?;
    analyse_and_catalog(&mut run, store)?;
    Ok(Outcome {
        run,
        aborted: false,
        link_lost: lost,
        pulled_blocks: pulled,
        pull_rounds: rounds,
        not_held,
        warnings,
    })
}
