//! A run folder: [`RunWriter`] records one, [`Run`] reads one back.

use crate::log::{LogContents, LogHeader, LogReader, LogWriter, Recovery};
use crate::{ErrorKind, Result, StoreError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tribo_physics::record::Units;
use tribo_physics::{Record, Rig};
use tribo_wire::{
    AnalogChain, Channel, Configure, DeviceMsg, EcrRangeChange, EndReason, Gap, OnboardResult,
    RunEnd, RunHeader, SampleBlock, SampleClock,
};

/// The run's frame log in its folder.
pub const LOG_FILE: &str = "frames.log";
/// The run's metadata in its folder.
pub const META_FILE: &str = "meta.toml";
/// The run's results in its folder.
pub const RESULT_FILE: &str = "result.toml";
/// A CSV export of the samples in its folder.
pub const CSV_FILE: &str = "samples.csv";
/// Version of the run folder layout written in [`RunMeta::format`].
pub const RUN_FORMAT: u32 = 1;

mod assembled;
mod completeness;
mod meta;
mod writer;
pub use assembled::*;
pub use completeness::*;
pub use meta::*;
pub use writer::*;

/// A run's samples in SI units, in time order (`t` from the release).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Samples {
    /// Time from the release (s).
    pub t: Vec<f64>,
    /// Displacement (m).
    pub x: Vec<f64>,
    /// Velocity (m/s).
    pub v: Vec<f64>,
    /// Tangential force, N (if the channel was on).
    pub force: Option<Vec<f64>>,
    /// Plane temperature, °C (the channel if on, else the block's reading).
    pub temp_c: Option<Vec<f64>>,
    /// Contact resistance, Ω (one value per block, held over its samples; NaN for a block in which
    /// the autoranger had no reading, typically the first few while it searches its range).
    pub ecr_ohm: Option<Vec<f64>>,
    /// Index in the run of each sample (its time is `clock.time_s(index)`); consecutive except
    /// across gaps.
    pub index: Vec<u64>,
    /// The ECR transimpedance range each sample was converted on, and whether the amplifier was
    /// still settling from a change (from the run's `EcrRange` frames; `None` for a run without
    /// them, recorded by older firmware).
    pub ecr_range: Option<Vec<u8>>,
    /// Whether the ECR amplifier was still settling, per sample (as `ecr_range`).
    pub ecr_settling: Option<Vec<bool>>,
}

impl Samples {
    /// Samples held.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// No sample held.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
}

/// A logged frame: decoded with the protocol the log says the rig spoke (`None`: not recorded;
/// then today's protocol, else v1's).
fn decode_record(protocol: Option<u16>, raw: &[u8]) -> Option<tribo_wire::Frame<DeviceMsg>> {
    tribo_wire::v1::decode_as(protocol, raw).ok()
}

fn read_toml<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            StoreError::new(
                ErrorKind::NotFound,
                format!(
                    "{} is missing: is {} a run folder?",
                    path.display(),
                    path.parent().unwrap_or(path).display()
                ),
            )
        } else {
            StoreError::io(format!("cannot read {}", path.display()), e)
        }
    })?;
    toml::from_str(&text).map_err(|e| {
        StoreError::caused(
            ErrorKind::Corrupt,
            format!("{} is damaged: fix or delete the file", path.display()),
            e,
        )
    })
}

/// Writes `value` to `path` atomically (temporary file, fsync, rename).
fn write_toml_atomic<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = toml::to_string(value).map_err(|e| {
        StoreError::caused(
            ErrorKind::Invalid,
            format!("cannot encode {}", path.display()),
            e,
        )
    })?;
    write_atomic(path, text.as_bytes())
}

pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let tmp = path.with_extension("tmp");
    let io = |e| StoreError::io(format!("cannot write {}", path.display()), e);
    let mut f = std::fs::File::create(&tmp).map_err(io)?;
    f.write_all(bytes).and_then(|_| f.sync_all()).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// A stored run, read back from its folder.
#[derive(Debug, Clone)]
pub struct Run {
    dir: PathBuf,
    /// Its metadata (`meta.toml`).
    pub meta: RunMeta,
    /// Its results (`result.toml`).
    pub results: Results,
    /// What had to be cut off the frame log's end (or, salvaging, skipped), if anything.
    pub recovery: Option<Recovery>,
    data: Assembled,
    log_header: LogHeader,
}

/// A run's status from what its log holds: `Complete` only when every frame of the run is there;
/// `recorded` (the metadata's) says whether it was aborted or is still being recorded.
fn derive_status(recorded: RunStatus, data: &Assembled) -> RunStatus {
    let aborted = recorded == RunStatus::Aborted
        || matches!(
            data.end,
            Some(RunEnd {
                reason: EndReason::Aborted,
                ..
            })
        );
    if data.completeness().is_complete() {
        if aborted {
            RunStatus::Aborted
        } else {
            RunStatus::Complete
        }
    } else {
        match recorded {
            RunStatus::Aborted | RunStatus::Recording => recorded,
            _ => RunStatus::Incomplete,
        }
    }
}

impl Run {
    /// Opens the run in folder `dir`. A torn tail of the log is dropped and reported in
    /// [`Run::recovery`]; corruption before the end is an error.
    pub fn open(dir: impl AsRef<Path>) -> Result<Run> {
        Self::open_with(dir.as_ref(), false)
    }

    /// Like [`Run::open`] but keeps the intact prefix of a corrupt log.
    pub fn open_salvage(dir: impl AsRef<Path>) -> Result<Run> {
        Self::open_with(dir.as_ref(), true)
    }

    fn open_with(dir: &Path, salvage: bool) -> Result<Run> {
        if !dir.is_dir() {
            return Err(StoreError::new(
                ErrorKind::NotFound,
                format!(
                    "{} is not a run folder (list runs with `tribo runs`)",
                    dir.display()
                ),
            ));
        }
        let meta: RunMeta = read_toml(&dir.join(META_FILE))?;
        if meta.format > RUN_FORMAT {
            return Err(StoreError::new(
                ErrorKind::Corrupt,
                format!(
                    "{}: run format v{} is newer than this tribo (v{RUN_FORMAT}): update tribo",
                    dir.display(),
                    meta.format
                ),
            ));
        }
        let results = match read_toml(&dir.join(RESULT_FILE)) {
            Ok(r) => r,
            Err(e) if e.kind == ErrorKind::NotFound => Results::default(),
            Err(e) => return Err(e),
        };
        let LogContents {
            header,
            records,
            recovery,
        } = LogReader::read(&dir.join(LOG_FILE), salvage)?;
        let data = Assembled::from_records(&records, header.protocol);
        let mut results = results;
        if results.onboard.is_none() {
            results.onboard = data.result;
        }
        let mut meta = meta;
        // The log is the truth: a run whose log lost frames since it was finished is not complete.
        meta.status = derive_status(meta.status, &data);
        Ok(Run {
            dir: dir.to_owned(),
            meta,
            results,
            recovery,
            data,
            log_header: header,
        })
    }

    /// How much of the run is held (blocks, events, result, end).
    pub fn completeness(&self) -> Completeness {
        self.data.completeness()
    }

    /// The run frames held, byte for byte as the rig sent them, in the rig's order (by sequence
    /// number), each once: for a complete run, exactly the frames the rig stored.
    pub fn frames(&self) -> Vec<&[u8]> {
        self.data.frames()
    }

    /// The frame log's header (its format, and the wire protocol of its frames).
    pub fn log_header(&self) -> LogHeader {
        self.log_header
    }

    /// The run's folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The run's id (its folder name).
    pub fn id(&self) -> &str {
        &self.meta.id
    }

    /// Its metadata.
    pub fn meta(&self) -> &RunMeta {
        &self.meta
    }

    /// The on-board analysis, if the rig sent it.
    pub fn result(&self) -> Option<&OnboardResult> {
        self.results.onboard.as_ref()
    }

    /// The host's fit, if one was made.
    pub fn host_fit(&self) -> Option<&HostFit> {
        self.results.host.as_ref()
    }

    /// The run's header frame, if received.
    pub fn header(&self) -> Option<&RunHeader> {
        self.data.header.as_ref()
    }

    /// The run's end frame, if received.
    pub fn end(&self) -> Option<&RunEnd> {
        self.data.end.as_ref()
    }

    /// Sample blocks received, in index order.
    pub fn blocks(&self) -> impl Iterator<Item = &SampleBlock> {
        self.data.blocks.values()
    }

    /// Sample blocks received.
    pub fn block_count(&self) -> usize {
        self.data.blocks.len()
    }

    /// Indices of blocks known to exist that were not received.
    pub fn missing_blocks(&self) -> Vec<u32> {
        self.data.missing()
    }

    /// First block a resumed `Pull` should ask for.
    pub fn resume_from(&self) -> u32 {
        self.data.resume_from()
    }

    /// Log records that did not decode as frames of this protocol.
    pub fn undecodable_records(&self) -> usize {
        self.data.undecodable
    }

    /// The acquisition gaps the rig reported: samples it lost (a reader that fell behind, an ADC
    /// overrun), in order. A fit must not run across one ([`Run::clean_stretches`]).
    pub fn gaps(&self) -> impl Iterator<Item = &Gap> {
        self.data.gaps.values()
    }

    /// Samples the rig lost, in all.
    pub fn lost_samples(&self) -> u64 {
        self.data.gaps.values().map(|g| g.count as u64).sum()
    }

    /// The ECR range changes the rig reported, in order.
    pub fn ecr_changes(&self) -> impl Iterator<Item = &EcrRangeChange> {
        self.data.ecr_changes.values()
    }

    /// The analog chain the rig said the run's channels went through (`None`: a run recorded
    /// before the rig said, or whose chain frame is not held).
    pub fn chain(&self) -> Option<&AnalogChain> {
        self.data.chain.as_ref()
    }

    /// The sample clock of the run: the header's (the rate the timer really produced), or, for a
    /// run recorded before the rig reported one, exactly the configured rate.
    pub fn clock(&self) -> SampleClock {
        match self.data.header {
            Some(h) if h.clock.is_valid() => h.clock,
            _ => SampleClock::exact(self.config().sample_rate_hz),
        }
    }

    /// The stretches of consecutive samples held, as run sample index ranges, in order: split at
    /// each gap the rig reported and at each block not received (missing blocks leave holes too).
    pub fn clean_stretches(&self) -> Vec<std::ops::Range<u64>> {
        let mut out: Vec<std::ops::Range<u64>> = Vec::new();
        for b in self.data.blocks.values() {
            let (a, e) = (
                b.first_sample as u64,
                b.first_sample as u64 + b.samples() as u64,
            );
            match out.last_mut() {
                Some(last) if last.end == a => last.end = e,
                _ => out.push(a..e),
            }
        }
        out
    }

    /// Every frame of the run held: header, blocks, events, result and end
    /// ([`Completeness::is_complete`]).
    pub fn is_complete(&self) -> bool {
        self.data.completeness().is_complete()
    }

    /// The configuration the samples were taken with (the rig's header, else the metadata's).
    pub fn config(&self) -> Configure {
        self.data
            .header
            .map(|h| h.config)
            .unwrap_or(self.meta.config)
    }

    /// The samples in SI units (calibrated with the run's own calibration). Missing blocks leave
    /// gaps in `t`, never misplaced samples.
    pub fn samples_si(&self) -> Result<Samples> {
        let cfg = self.config();
        let clock = self.clock();
        if !clock.is_valid() {
            return Err(StoreError::new(
                ErrorKind::Corrupt,
                format!(
                    "{}: sample clock {} Hz / {} ticks is not a rate",
                    self.dir.display(),
                    clock.timer_hz,
                    clock.ticks_per_sample
                ),
            ));
        }
        let cal = cfg.calibration;
        let events = !self.data.ecr_changes.is_empty();
        let mut ecr_range = Vec::new();
        let mut ecr_settling = Vec::new();
        let mut s = Samples::default();
        let any = |c: Channel| {
            self.data.blocks.values().all(|b| b.channels.contains(c))
                && !self.data.blocks.is_empty()
        };
        let (has_f, has_t) = (any(Channel::Force), any(Channel::Temperature));
        let mut force = Vec::new();
        let mut temp = Vec::new();
        let mut ecr = Vec::new();
        for b in self.data.blocks.values() {
            let ch = b.channels;
            let (Some(px), Some(pv)) = (
                ch.position(Channel::Displacement),
                ch.position(Channel::Velocity),
            ) else {
                return Err(StoreError::new(
                    ErrorKind::Corrupt,
                    format!(
                        "{}: block {} lacks displacement or velocity",
                        self.dir.display(),
                        b.block
                    ),
                ));
            };
            for i in 0..b.samples() {
                let Some(c) = b.sample(i) else { break };
                let index = b.first_sample as u64 + i as u64;
                s.t.push(clock.time_s(index));
                s.index.push(index);
                if events {
                    let change = self
                        .data
                        .ecr_changes
                        .range(..=index.min(u32::MAX as u64) as u32)
                        .next_back()
                        .map(|(_, c)| c);
                    ecr_range.push(change.map_or(b.ecr_range, |c| c.range));
                    ecr_settling.push(
                        change.is_some_and(|c| index < c.first_sample as u64 + c.settling as u64),
                    );
                }
                s.x.push(cal[Channel::Displacement.index()].to_si(c[px]) as f64);
                s.v.push(cal[Channel::Velocity.index()].to_si(c[pv]) as f64);
                if let (true, Some(p)) = (has_f, ch.position(Channel::Force)) {
                    force.push(cal[Channel::Force.index()].to_si(c[p]) as f64);
                }
                match (has_t, ch.position(Channel::Temperature)) {
                    (true, Some(p)) => {
                        temp.push(cal[Channel::Temperature.index()].to_si(c[p]) as f64)
                    }
                    _ => temp.push(b.temp_c as f64),
                }
                ecr.push(10f64.powf(b.log10_ecr_ohm as f64));
            }
        }
        s.force = has_f.then_some(force);
        s.temp_c = temp.iter().all(|v| v.is_finite()).then_some(temp);
        s.ecr_ohm = ecr.iter().any(|v| v.is_finite() && *v > 0.0).then_some(ecr);
        s.ecr_range = events.then_some(ecr_range);
        s.ecr_settling = events.then_some(ecr_settling);
        Ok(s)
    }

    /// The run as a physics [`Record`] (SI, with its rig constants), for `tribo fit` and the reports.
    /// A record's columns must be finite, so blocks without an ECR reading (see [`Samples::ecr_ohm`])
    /// take the nearest reading: the previous one, or the first one for the blocks before it.
    pub fn record(&self) -> Result<Record> {
        self.record_with(true)
    }

    /// [`Run::record`], with the samples that have no ECR reading left NaN unless `fill_ecr`
    /// (what the exports write: nothing the rig did not measure).
    pub fn record_with(&self, fill_ecr: bool) -> Result<Record> {
        let mut s = self.samples_si()?;
        if let (true, Some(e)) = (fill_ecr, &mut s.ecr_ohm) {
            tribo_physics::record::fill_missing(e);
        }
        let cfg = self.config();
        // The apparatus alone (load 0): a token load, so that the record has a dimensionless form
        // (`Record::apparatus`).
        let apparatus = cfg.rig.load_n == 0.0;
        let load = if apparatus {
            Record::apparatus_token_load(clean(cfg.rig.stiffness_n_per_m), &s.x)
        } else {
            clean(cfg.rig.load_n)
        };
        let rig = Rig::new(
            clean(cfg.rig.mass_kg),
            clean(cfg.rig.stiffness_n_per_m),
            load,
        )
        .map_err(|e| {
            StoreError::caused(
                ErrorKind::Corrupt,
                format!("{}: the run's rig constants", self.dir.display()),
                e,
            )
        })?;
        let mut r = Record::new(s.t, s.x, s.v, Some(rig), Units::Si);
        r.apparatus = apparatus;
        // The record states the force channel's low-pass when the rig said it and it is the
        // 2-pole Butterworth a record's `force_cutoff_hz` means; otherwise it is left unstated, and
        // an analysis fits it.
        r.force_cutoff_hz = self
            .chain()
            .map(|c| c.force_lowpass)
            .filter(|lp| lp.poles == 2 && lp.cutoff_hz.is_finite() && lp.cutoff_hz > 0.0)
            .map(|lp| clean(lp.cutoff_hz));
        r.ft = s.force;
        r.temp = s.temp_c;
        r.ecr = s.ecr_ohm;
        Ok(r)
    }

    /// Writes the samples as CSV in the physics format (`# mass_kg=…` lines, `t_s,x_m,v_m_s,…`).
    pub fn export_csv(&self, path: &Path) -> Result<()> {
        let rec = self.record_with(false)?;
        write_atomic(path, rec.to_csv_string().as_bytes())
    }

    /// Replaces the stored results (atomically).
    pub fn save_results(&mut self, results: Results) -> Result<()> {
        write_toml_atomic(&self.dir.join(RESULT_FILE), &results)?;
        self.results = results;
        Ok(())
    }

    /// Replaces the stored metadata (atomically).
    pub fn save_meta(&mut self) -> Result<()> {
        write_toml_atomic(&self.dir.join(META_FILE), &self.meta)
    }
}

/// Lists run folders under a store (those with a `meta.toml`), sorted by name (= creation time).
pub fn list_run_dirs(store: &Path) -> Result<Vec<PathBuf>> {
    let rd = match std::fs::read_dir(store) {
        Ok(rd) => rd,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(vec![]),
        Err(e) => {
            return Err(StoreError::io(
                format!("cannot list the store {}", store.display()),
                e,
            ))
        }
    };
    let mut dirs: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join(META_FILE).is_file())
        .collect();
    dirs.sort();
    Ok(dirs)
}

/// An `f32` setting as the `f64` a person typed (0.3, not 0.30000001192092896).
pub fn clean(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(x as f64)
}
