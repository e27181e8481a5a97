//! One run's frames from the link into the run store: the live stream, then pulls of what is
//! missing, in rounds with backoff, until the run is whole or the rig is known not to hold the rest.
//! This file files what arrives (the live stream); `pull` asks for what did not.

mod pull;

use super::progress::Progress;
use super::{explain, explain_fault, Link, LinkError, LinkErrorKind};
use anyhow::bail;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tribo_store::{Filed, RunWriter};
use tribo_wire::{DeviceMsg, HostMsg, RigState, RunHeader, SampleBlock};

pub(super) enum StreamEnd {
    Ended,
    Aborted,
    Lost(LinkError),
}

/// Frames kept while waiting for a run's header (a lost one is asked again).
const MAX_PENDING: usize = 50_000;

/// Builds the run writer when the run's header arrives.
pub(super) type MakeWriter<'a> = dyn FnMut(&RunHeader) -> anyhow::Result<RunWriter> + 'a;

pub(super) struct Streamer<'a, 'o> {
    pub(super) link: &'a mut Link,
    pub(super) writer: Option<RunWriter>,
    pub(super) make: &'a mut MakeWriter<'a>,
    pub(super) abort: &'a AtomicBool,
    pub(super) obs: &'a mut (dyn FnMut(Progress<'_>) + 'o),
    pub(super) warnings: Vec<String>,
    pub(super) pulled: usize,
    pub(super) pulling: bool,
    /// A header that differs from the stored one starts a new folder (else it is an error).
    pub(super) new_on_mismatch: bool,
    /// The rig's run being recorded or fetched, once known.
    pub(super) run_id: Option<u32>,
    /// Run frames of runs numbered below this are an earlier run's (stale) and are ignored.
    pub(super) min_run: u32,
    /// The writer's run header was sent by the rig in this session (so the stored run is the
    /// rig's): until then, frames wait in `pending` rather than go into a stored run.
    pub(super) verified: bool,
    /// Run frames that arrived before their run's header was known or confirmed.
    pub(super) pending: Vec<super::Incoming>,
    /// A run frame came before its header: the header was asked for again.
    pub(super) asked_header: bool,
    pub(super) rounds: u32,
    pub(super) not_held: Option<String>,
}

/// The run a run frame belongs to.
fn run_of(msg: &DeviceMsg) -> Option<u32> {
    Some(match msg {
        DeviceMsg::RunStarted(h) => h.run_id,
        DeviceMsg::Samples(b) => b.run_id,
        DeviceMsg::Packed(p) => p.run_id,
        DeviceMsg::Gap(g) => g.run_id,
        DeviceMsg::EcrRange(e) => e.run_id,
        DeviceMsg::Chain(c) => c.run_id,
        DeviceMsg::Result(r) => r.run_id,
        DeviceMsg::RunEnded(e) => e.run_id,
        _ => return None,
    })
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
    fn warn(&mut self, msg: String) {
        self.warnings.push(msg.clone());
        (self.obs)(Progress::Warning(msg));
    }

    fn file(&mut self, f: super::Incoming) -> anyhow::Result<Option<StreamEnd>> {
        if let Some(r) = run_of(&f.frame.msg) {
            if r < self.min_run || self.run_id.is_some_and(|id| id != r) {
                // An earlier run's frame, still on its way: not this run.
                return Ok(None);
            }
        }
        match &f.frame.msg {
            DeviceMsg::RunStarted(h) => {
                let h = *h;
                if self.writer.is_none() {
                    self.writer = Some((self.make)(&h)?);
                }
                self.run_id = Some(h.run_id);
                let w = self.writer.as_mut().expect("just created");
                match w.file_frame(&f.raw)? {
                    Filed::New => {
                        let dir = w.dir().to_owned();
                        (self.obs)(Progress::Started {
                            header: &h,
                            dir: &dir,
                        });
                        if h.clock.is_valid() && !h.clock.is_exactly(h.config.sample_rate_hz) {
                            (self.obs)(Progress::RateUsed {
                                asked_hz: h.config.sample_rate_hz,
                                clock: h.clock,
                            });
                        }
                    }
                    Filed::Differs(what) => {
                        let old = w.header().map_or(0, |o| o.t_us);
                        self.mismatch(&format!(
                            "{what} differs: released at device time {} µs, the stored one at {old} µs",
                            h.t_us
                        ))?;
                        // The rig's run, into a new folder.
                        self.writer = Some((self.make)(&h)?);
                        self.writer
                            .as_mut()
                            .expect("just created")
                            .file_frame(&f.raw)?;
                    }
                    Filed::Same | Filed::Other => {}
                }
                self.verified = true;
                for p in std::mem::take(&mut self.pending) {
                    self.file(p)?;
                }
            }
            DeviceMsg::Samples(_)
            | DeviceMsg::Packed(_)
            | DeviceMsg::Gap(_)
            | DeviceMsg::EcrRange(_)
            | DeviceMsg::Chain(_)
            | DeviceMsg::Result(_)
            | DeviceMsg::RunEnded(_) => return self.file_run_frame(f),
            DeviceMsg::Error(e) if e.about_seq.is_none() => {
                let msg = explain(e.code);
                self.warn(msg);
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

    /// Files a run frame other than the header (blocks, events, result, end).
    fn file_run_frame(&mut self, f: super::Incoming) -> anyhow::Result<Option<StreamEnd>> {
        let is_end = matches!(f.frame.msg, DeviceMsg::RunEnded(_));
        let ready = self.verified && self.writer.as_ref().is_some_and(|w| w.header().is_some());
        if !ready {
            // Its header is not here yet (or the stored run is not confirmed as the rig's): keep
            // it until then. A run frame without a header in sight: the header was lost on the
            // way; ask for the run again from its start (the live stream carries on after it).
            if !self.asked_header && !self.pulling && self.writer.is_none() {
                if let Some(run_id) = run_of(&f.frame.msg) {
                    self.asked_header = true;
                    // The run is this one (earlier runs' frames were filtered out above): the
                    // pulls after the stream ask for its header again if this one is lost too.
                    self.run_id.get_or_insert(run_id);
                    match self.link.command(HostMsg::Pull {
                        run_id,
                        from_block: 0,
                    }) {
                        Ok(()) => {}
                        Err(e) if matches!(e.kind, LinkErrorKind::Closed) => {
                            return Ok(Some(StreamEnd::Lost(e)))
                        }
                        Err(_) => {} // asked again by the pulls after the stream
                    }
                }
            }
            if self.pending.len() < MAX_PENDING {
                self.pending.push(f);
            }
            return Ok(None);
        }
        if let DeviceMsg::Packed(p) = &f.frame.msg {
            if let Err(e) = p.unpack() {
                let msg = format!(
                    "sample block {} of run {} arrived intact but its counts do not decode ({e}): \
                     is this tribo older than the rig's firmware?",
                    p.block, p.run_id
                );
                if !self.warnings.contains(&msg) {
                    self.warn(msg);
                }
            }
        }
        let w = self.writer.as_mut().expect("checked");
        let next = w.resume_from();
        let last_seen = w.last_block().map_or(0, |b| b + 1);
        match w.file_frame(&f.raw)? {
            Filed::New => {}
            Filed::Same | Filed::Other => return Ok(is_end.then_some(StreamEnd::Ended)),
            Filed::Differs(what) => {
                self.mismatch(&format!("{what} differs from the stored one"))?;
                return Ok(None);
            }
        }
        match &f.frame.msg {
            DeviceMsg::Samples(_) | DeviceMsg::Packed(_) => {
                let k = match &f.frame.msg {
                    DeviceMsg::Samples(b) => b.block,
                    DeviceMsg::Packed(p) => p.block,
                    _ => unreachable!(),
                };
                if self.pulling {
                    self.pulled += 1;
                }
                if k > next && k >= last_seen && !self.pulling {
                    (self.obs)(Progress::Gap { from: next, to: k });
                }
                let w = self.writer.as_ref().expect("checked");
                if let (Some(h), Some(b)) = (w.header().copied(), w.block(k)) {
                    let samples = (b.first_sample as u64) + b.samples() as u64;
                    let env = envelope(&h, b);
                    let b = b.clone();
                    (self.obs)(Progress::Block {
                        block: &b,
                        envelope_m: env,
                        samples,
                        expected: h.config.max_samples() as u64,
                    });
                }
            }
            DeviceMsg::Gap(g) => {
                let g = *g;
                (self.obs)(Progress::Lost(&g));
            }
            DeviceMsg::RunEnded(e) => {
                let e = *e;
                (self.obs)(Progress::Ended(&e));
            }
            _ => {}
        }
        Ok(is_end.then_some(StreamEnd::Ended))
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
        self.warn(format!(
            "{dir} holds an older run with the same number ({what}; the rig was restarted since): fetching the \
             rig's run into a new folder"
        ));
        if let Some(w) = self.writer.take() {
            let _ = w.finish(false);
        }
        self.pending.clear();
        Ok(())
    }

    /// Receives until the run's end, an abort, or a lost link.
    pub(super) fn stream(&mut self) -> anyhow::Result<StreamEnd> {
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
                                    && (self.writer.as_ref().is_some_and(|w| w.header().is_some())
                                        || !self.pending.is_empty())
                                {
                                    // The end frame (or the header) was lost: the pulls fill in.
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
}
