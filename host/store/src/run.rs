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
    Channel, Configure, DeviceMsg, EcrRangeChange, EndReason, Gap, OnboardResult, RunEnd,
    RunHeader, SampleBlock, SampleClock,
};

pub const LOG_FILE: &str = "frames.log";
pub const META_FILE: &str = "meta.toml";
pub const RESULT_FILE: &str = "result.toml";
pub const CSV_FILE: &str = "samples.csv";
/// Version of the run folder layout written in [`RunMeta::format`].
pub const RUN_FORMAT: u32 = 1;

/// Where a run stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunStatus {
    /// Being recorded (or the recorder was killed: see [`Run::is_complete`]).
    Recording,
    /// Every block and the run's end were received.
    Complete,
    /// Aborted by the operator (Ctrl-C) or the rig; what was received is kept.
    Aborted,
    /// The link was lost before the end; `tribo pull` can fetch the rest.
    Incomplete,
}

impl RunStatus {
    /// Every status, in the order a run goes through them.
    pub const ALL: [RunStatus; 4] = [
        RunStatus::Recording,
        RunStatus::Complete,
        RunStatus::Aborted,
        RunStatus::Incomplete,
    ];

    pub fn name(self) -> &'static str {
        match self {
            RunStatus::Recording => "recording",
            RunStatus::Complete => "complete",
            RunStatus::Aborted => "aborted",
            RunStatus::Incomplete => "incomplete",
        }
    }
}

impl std::str::FromStr for RunStatus {
    type Err = StoreError;
    fn from_str(s: &str) -> Result<RunStatus> {
        RunStatus::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| {
                StoreError::new(
                    ErrorKind::Invalid,
                    format!(
                        "unknown run status {s:?}: use {}",
                        RunStatus::ALL.map(RunStatus::name).join(", ")
                    ),
                )
            })
    }
}

/// The rig the run was taken on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceMeta {
    /// `major.minor.patch`.
    pub firmware: String,
    /// Serial number, 16 hex digits.
    pub serial: String,
    pub protocol: u16,
    /// Port it was reached through (`COM3`, `/dev/ttyACM0`, `tcp://127.0.0.1:7411`…).
    pub port: String,
}

/// Everything known about a run besides its samples (`meta.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunMeta {
    /// Folder layout version ([`RUN_FORMAT`]).
    pub format: u32,
    /// The run's id in the store (its folder name).
    pub id: String,
    /// Creation time, UTC, `YYYY-MM-DDTHH:MM:SSZ`.
    pub created: String,
    pub status: RunStatus,
    #[serde(default)]
    pub label: Option<String>,
    #[serde(default)]
    pub sample: Option<String>,
    #[serde(default)]
    pub lubricant: Option<String>,
    /// Campaign name and this run's repetition index (from 1), if part of one.
    #[serde(default)]
    pub campaign: Option<String>,
    #[serde(default)]
    pub repeat: Option<u32>,
    /// Normal load N.
    pub load_n: f64,
    pub mass_kg: f64,
    pub stiffness_n_per_m: f64,
    pub sample_rate_hz: u32,
    pub initial_amplitude_m: f64,
    /// Heater setpoint asked for (`None` = heater off, room temperature).
    #[serde(default)]
    pub temp_setpoint_c: Option<f64>,
    /// Plane temperature measured at the release.
    #[serde(default)]
    pub temp_c: Option<f64>,
    #[serde(default)]
    pub device: Option<DeviceMeta>,
    /// The rig's own number for the run (what `Pull` asks for).
    #[serde(default)]
    pub device_run_id: Option<u32>,
    /// The full configuration sent to the rig.
    pub config: Configure,
    /// Rig constants (`mass_kg`, `stiffness_n_per_m`, `x0_m`, …) that no plan or flag gave, for
    /// which a default stood in (a campaign plan that leaves them out takes the real rig's).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub defaults: Vec<String>,
}

impl RunMeta {
    /// Metadata for a run about to be taken with `config`.
    pub fn new(config: Configure) -> RunMeta {
        RunMeta {
            format: RUN_FORMAT,
            id: String::new(),
            created: crate::utc_now_rfc3339(),
            status: RunStatus::Recording,
            label: None,
            sample: None,
            lubricant: None,
            campaign: None,
            repeat: None,
            load_n: clean(config.rig.load_n),
            mass_kg: clean(config.rig.mass_kg),
            stiffness_n_per_m: clean(config.rig.stiffness_n_per_m),
            sample_rate_hz: config.sample_rate_hz,
            initial_amplitude_m: clean(config.initial_amplitude_m),
            temp_setpoint_c: None,
            temp_c: None,
            device: None,
            device_run_id: None,
            config,
            defaults: Vec::new(),
        }
    }

    /// The temperature a table groups by: the setpoint if the heater was on, else the measured one.
    pub fn nominal_temp_c(&self) -> Option<f64> {
        self.temp_setpoint_c.or(self.temp_c)
    }

    fn folder_name(&self) -> String {
        let stamp: String = self
            .created
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .collect();
        let mut name = format!("{stamp}-N{:.3}", self.load_n);
        if let Some(t) = self.temp_setpoint_c {
            name.push_str(&format!("-T{t:.0}"));
        }
        if let Some(l) = &self.label {
            let clean: String = l
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                        c
                    } else {
                        '_'
                    }
                })
                .take(40)
                .collect();
            if !clean.is_empty() {
                name.push('-');
                name.push_str(&clean);
            }
        }
        name
    }
}

/// Host-side fit of the run's samples (Coulomb–viscous, tribo-physics' Levenberg–Marquardt).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HostFit {
    pub law: String,
    pub mu0: f64,
    pub mu1: f64,
    /// RMS envelope misfit relative to the initial amplitude.
    pub gap: f64,
    pub converged: bool,
    /// Standard errors of μ0 and μ1 (`NaN` in results written before they were recorded).
    #[serde(default = "nan")]
    pub mu0_se: f64,
    #[serde(default = "nan")]
    pub mu1_se: f64,
    /// The fit's verdict (`adequate`, `inadequate`, `not-converged`); `None` in older results.
    #[serde(default)]
    pub verdict: Option<String>,
}

fn nan() -> f64 {
    f64::NAN
}

/// `result.toml`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Results {
    #[serde(default)]
    pub onboard: Option<OnboardResult>,
    #[serde(default)]
    pub host: Option<HostFit>,
    /// Why the host fit failed, if it did.
    #[serde(default)]
    pub host_error: Option<String>,
}

/// A run's samples in SI units, in time order (`t` from the release).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Samples {
    pub t: Vec<f64>,
    pub x: Vec<f64>,
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
    pub ecr_settling: Option<Vec<bool>>,
}

impl Samples {
    pub fn len(&self) -> usize {
        self.t.len()
    }
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }
}

/// Where a run frame belongs in a run (what a second copy of it is compared with).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Slot {
    Header,
    Block(u32),
    Gap(u32),
    Ecr(u32),
    Result,
    End,
}

impl Slot {
    fn of(msg: &DeviceMsg) -> Option<Slot> {
        Some(match msg {
            DeviceMsg::RunStarted(_) => Slot::Header,
            DeviceMsg::Samples(b) => Slot::Block(b.block),
            DeviceMsg::Packed(p) => Slot::Block(p.block),
            DeviceMsg::Gap(g) => Slot::Gap(g.first_sample),
            DeviceMsg::EcrRange(e) => Slot::Ecr(e.first_sample),
            DeviceMsg::Result(_) => Slot::Result,
            DeviceMsg::RunEnded(_) => Slot::End,
            _ => return None,
        })
    }

    fn name(self) -> String {
        match self {
            Slot::Header => "its run header".into(),
            Slot::Block(k) => format!("its block {k}"),
            Slot::Gap(s) => format!("its acquisition gap at sample {s}"),
            Slot::Ecr(s) => format!("its ECR range change at sample {s}"),
            Slot::Result => "its on-board result".into(),
            Slot::End => "its end frame".into(),
        }
    }
}

/// What filing a frame into a run did ([`RunWriter::file_frame`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Filed {
    /// A frame of the run not held before: logged.
    New,
    /// The very frame (same bytes) is already held: not logged again.
    Same,
    /// The run holds another frame in its place: the frame is of another run (not logged). Says
    /// which part differs.
    Differs(String),
    /// Not a run frame (hello, status, …): not logged.
    Other,
}

/// The messages of a log, sorted into a run.
#[derive(Debug, Clone, Default)]
struct Assembled {
    header: Option<RunHeader>,
    blocks: BTreeMap<u32, SampleBlock>,
    result: Option<OnboardResult>,
    end: Option<RunEnd>,
    /// Records that were not frames of this protocol, or packed blocks that did not unpack (count).
    undecodable: usize,
    /// Run frames received twice with different contents.
    conflicts: Vec<String>,
    /// Acquisition gaps the rig reported, by first sample.
    gaps: BTreeMap<u32, Gap>,
    /// ECR range changes the rig reported, by first sample.
    ecr_changes: BTreeMap<u32, EcrRangeChange>,
    /// Every run frame held, as received (sequence number, bytes), by its place in the run.
    raw: BTreeMap<Slot, (u32, Vec<u8>)>,
    /// Some sample block came packed (protocol v2 firmware, which records each ECR range change).
    packed: bool,
    /// The first block index not held (all before it are).
    next_missing: u32,
    /// Blocks held whose counts this tribo cannot unpack (a newer codec).
    undecodable_blocks: Vec<u32>,
}

impl Assembled {
    /// Files one decoded frame (`raw`: its bytes, `seq`: its sequence number).
    fn add(&mut self, seq: u32, raw: &[u8], msg: DeviceMsg) -> Filed {
        let Some(slot) = Slot::of(&msg) else {
            return Filed::Other;
        };
        if let Some((_, held)) = self.raw.get(&slot) {
            if held[..] == *raw {
                return Filed::Same;
            }
            let what = slot.name();
            self.conflicts.push(what.clone());
            return Filed::Differs(what);
        }
        self.packed |= matches!(msg, DeviceMsg::Packed(_));
        match msg {
            DeviceMsg::RunStarted(h) => self.header = Some(h),
            DeviceMsg::Samples(_) | DeviceMsg::Packed(_) => match msg.sample_block() {
                Some(Ok(b)) => {
                    self.blocks.insert(b.block, b);
                    while self.blocks.contains_key(&self.next_missing) {
                        self.next_missing += 1;
                    }
                }
                // A packed block whose counts do not decode (a CRC-valid frame from a newer codec):
                // kept in the log, counted as missing.
                _ => {
                    self.undecodable += 1;
                    if let Slot::Block(k) = slot {
                        self.undecodable_blocks.push(k);
                    }
                }
            },
            DeviceMsg::Result(r) => self.result = Some(r),
            DeviceMsg::RunEnded(e) => self.end = Some(e),
            DeviceMsg::Gap(g) => {
                self.gaps.insert(g.first_sample, g);
            }
            DeviceMsg::EcrRange(e) => {
                self.ecr_changes.insert(e.first_sample, e);
            }
            _ => {}
        }
        self.raw.insert(slot, (seq, raw.to_vec()));
        Filed::New
    }

    /// Whether this event frame is already filed.
    fn has_event(&self, msg: &DeviceMsg) -> bool {
        match msg {
            DeviceMsg::Gap(g) => self.gaps.get(&g.first_sample) == Some(g),
            DeviceMsg::EcrRange(e) => self.ecr_changes.get(&e.first_sample) == Some(e),
            _ => false,
        }
    }

    fn from_records(records: &[Vec<u8>], protocol: Option<u16>) -> Assembled {
        let mut a = Assembled::default();
        for r in records {
            match decode_record(protocol, r) {
                Some(f) => {
                    a.add(f.seq, r, f.msg);
                }
                None => a.undecodable += 1,
            }
        }
        a
    }

    /// Block indices missing before the last one expected.
    fn missing(&self) -> Vec<u32> {
        let expected = match (&self.end, self.blocks.keys().next_back()) {
            (Some(e), _) => e.blocks,
            (None, Some(&last)) => last + 1,
            (None, None) => 0,
        };
        (0..expected)
            .filter(|b| !self.blocks.contains_key(b))
            .collect()
    }

    /// Blocks before which run events (acquisition gaps, ECR range changes) the rig must have sent
    /// are not held, judged from what the held blocks say: a jump in sample index that the gaps
    /// held do not cover exactly, or a packed block (v2 firmware) converted on an ECR range that the
    /// range changes held do not explain. (Events after the last block show in no block: a pull of
    /// the run's end brings them.)
    fn event_holes(&self) -> Vec<u32> {
        let mut holes = vec![];
        let mut prev: Option<&SampleBlock> = None;
        let first_range = self.blocks.get(&0).map(|b| b.ecr_range);
        let mut assumed: Option<(u32, u8)> = None;
        for b in self.blocks.values() {
            if let Some(p) = prev.filter(|p| p.block + 1 == b.block) {
                let end = p.first_sample as u64 + p.samples() as u64;
                let jump = (b.first_sample as u64).saturating_sub(end);
                let covered: u64 = self
                    .gaps
                    .range(end.min(u32::MAX as u64) as u32..b.first_sample)
                    .map(|(_, g)| g.count as u64)
                    .sum();
                if jump != covered {
                    holes.push(b.block);
                    prev = Some(b);
                    continue;
                }
            }
            // The range in force at the block's first sample, from the changes held (firmware
            // before protocol v2 changed ranges without saying so). After a hole, the block's own
            // range stands in for the change not held, so that one lost change is one hole.
            if self.packed {
                let held = self
                    .ecr_changes
                    .range(..=b.first_sample)
                    .next_back()
                    .map(|(&s, c)| (s, c.range));
                let range = match (held, assumed) {
                    (Some((s, _)), Some((since, r))) if since > s => Some(r),
                    (Some((_, r)), _) => Some(r),
                    (None, Some((_, r))) => Some(r),
                    (None, None) => first_range,
                };
                if range.is_some_and(|r| r != b.ecr_range) {
                    holes.push(b.block);
                    assumed = Some((b.first_sample, b.ecr_range));
                }
            }
            prev = Some(b);
        }
        holes
    }

    /// Samples the gaps held account for, against what the end frame says the rig lost.
    fn gaps_unaccounted(&self) -> Option<(u64, u64)> {
        let held: u64 = self.gaps.values().map(|g| g.count as u64).sum();
        let end = self.end?;
        (end.overruns as u64 != held).then_some((held, end.overruns as u64))
    }

    fn completeness(&self) -> Completeness {
        let held = self.blocks.len() as u32;
        Completeness {
            header: self.header.is_some(),
            result: self.result.is_some(),
            end: self.end.is_some(),
            blocks_held: held,
            blocks_expected: self.end.map(|e| e.blocks),
            blocks_known: self
                .end
                .map(|e| e.blocks)
                .or(self.blocks.keys().next_back().map(|b| b + 1))
                .unwrap_or(0),
            missing: self.missing(),
            undecodable: self.undecodable_blocks.clone(),
            event_holes: self.event_holes(),
            gaps_unaccounted: self.gaps_unaccounted(),
            lost_samples: self.gaps.values().map(|g| g.count as u64).sum(),
            conflicts: self.conflicts.len(),
        }
    }

    /// The block a resumed pull should start from: the first one missing (or the next one).
    fn resume_from(&self) -> u32 {
        self.next_missing
    }

    /// The run frames held, in the order the rig sent them (by sequence number).
    fn frames(&self) -> Vec<&[u8]> {
        let mut v: Vec<&(u32, Vec<u8>)> = self.raw.values().collect();
        v.sort_by_key(|(seq, _)| *seq);
        v.into_iter().map(|(_, r)| &r[..]).collect()
    }
}

/// How much of a run is held: what a command says before it calls a run complete.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Completeness {
    /// The run header (configuration, clock) is held.
    pub header: bool,
    /// The on-board result is held (every run the rig ends has one, even aborted ones).
    pub result: bool,
    /// The end frame is held: then the run's number of blocks is known.
    pub end: bool,
    pub blocks_held: u32,
    /// Blocks the run has, from its end frame.
    pub blocks_expected: Option<u32>,
    /// Blocks known to exist: from the end frame, else up to the highest block held.
    pub blocks_known: u32,
    /// Blocks known to exist and not held (those below included).
    pub missing: Vec<u32>,
    /// Blocks received whose counts this tribo cannot unpack (a newer rig's codec: update tribo).
    pub undecodable: Vec<u32>,
    /// Blocks before which run events (gaps, ECR range changes) look missing.
    pub event_holes: Vec<u32>,
    /// Samples the gaps held account for and samples the end frame says were lost, when they
    /// differ.
    pub gaps_unaccounted: Option<(u64, u64)>,
    /// Samples the rig itself lost (its gap frames): part of a complete run, not missing data.
    pub lost_samples: u64,
    /// Run frames received twice with different contents.
    pub conflicts: usize,
}

/// Block indices as ranges: `3, 7–9, 12`.
pub fn block_ranges(blocks: &[u32]) -> String {
    let mut out: Vec<String> = vec![];
    let mut i = 0;
    while i < blocks.len() {
        let mut j = i;
        while j + 1 < blocks.len() && blocks[j + 1] == blocks[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            blocks[i].to_string()
        } else {
            format!("{}–{}", blocks[i], blocks[j])
        });
        i = j + 1;
    }
    out.join(", ")
}

impl Completeness {
    /// Header, every block, the run's events, its result and its end.
    pub fn is_complete(&self) -> bool {
        self.header
            && self.result
            && self.end
            && self.missing.is_empty()
            && self.event_holes.is_empty()
            && self.gaps_unaccounted.is_none()
    }

    /// One line: `complete: 156 of 156 blocks`, or `incomplete: 79 of 156 blocks (missing …)`.
    pub fn summary(&self) -> String {
        let mut s = if self.is_complete() {
            format!(
                "complete: {} of {} blocks",
                self.blocks_held, self.blocks_held
            )
        } else {
            match self.blocks_expected {
                Some(m) => format!("incomplete: {} of {m} blocks", self.blocks_held),
                None => format!(
                    "incomplete: {} of at least {} blocks",
                    self.blocks_held, self.blocks_known
                ),
            }
        };
        let mut why: Vec<String> = vec![];
        if !self.header {
            why.push("no run header".into());
        }
        if !self.missing.is_empty() {
            why.push(format!("missing {}", block_ranges(&self.missing)));
        }
        if !self.undecodable.is_empty() {
            why.push(format!(
                "block{} {} arrived but this tribo cannot unpack {} (a newer rig's codec: update tribo)",
                if self.undecodable.len() == 1 { "" } else { "s" },
                block_ranges(&self.undecodable),
                if self.undecodable.len() == 1 { "it" } else { "them" }
            ));
        }
        if !self.end {
            why.push(
                "the run's end was not received, so how many blocks it has is not known".into(),
            );
        } else if !self.result {
            why.push("the on-board result was not received".into());
        }
        if !self.event_holes.is_empty() {
            why.push(format!(
                "run events (acquisition gaps, ECR range changes) missing before block{} {}",
                if self.event_holes.len() == 1 { "" } else { "s" },
                block_ranges(&self.event_holes)
            ));
        }
        if let Some((held, said)) = self.gaps_unaccounted {
            why.push(format!(
                "the rig reported {said} lost samples, the gap frames held account for {held}"
            ));
        }
        if self.conflicts > 0 {
            why.push(format!(
                "{} frames arrived twice with different contents (kept the first)",
                self.conflicts
            ));
        }
        if self.lost_samples > 0 {
            why.push(format!(
                "the rig's acquisition lost {} samples (its gap frames say which)",
                self.lost_samples
            ));
        }
        if !why.is_empty() {
            s.push_str(&format!(" ({})", why.join("; ")));
        }
        s
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
        StoreError::new(
            ErrorKind::Corrupt,
            format!("{} is damaged: {e}; fix or delete the file", path.display()),
        )
    })
}

/// Writes `value` to `path` atomically (temporary file, fsync, rename).
fn write_toml_atomic<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = toml::to_string(value).map_err(|e| {
        StoreError::new(
            ErrorKind::Invalid,
            format!("cannot encode {}: {e}", path.display()),
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
    pub meta: RunMeta,
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

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn id(&self) -> &str {
        &self.meta.id
    }

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

    pub fn header(&self) -> Option<&RunHeader> {
        self.data.header.as_ref()
    }

    pub fn end(&self) -> Option<&RunEnd> {
        self.data.end.as_ref()
    }

    /// Sample blocks received, in index order.
    pub fn blocks(&self) -> impl Iterator<Item = &SampleBlock> {
        self.data.blocks.values()
    }

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
        let mut s = self.samples_si()?;
        if let Some(e) = &mut s.ecr_ohm {
            fill_gaps(e);
        }
        let cfg = self.config();
        let rig = Rig::new(
            clean(cfg.rig.mass_kg),
            clean(cfg.rig.stiffness_n_per_m),
            clean(cfg.rig.load_n),
        )
        .map_err(|e| {
            StoreError::new(
                ErrorKind::Corrupt,
                format!("{}: rig constants: {e}", self.dir.display()),
            )
        })?;
        let mut r = Record::new(s.t, s.x, s.v, Some(rig), Units::Si);
        r.ft = s.force;
        r.temp = s.temp_c;
        r.ecr = s.ecr_ohm;
        Ok(r)
    }

    /// Writes the samples as CSV in the physics format (`# mass_kg=…` lines, `t_s,x_m,v_m_s,…`).
    pub fn export_csv(&self, path: &Path) -> Result<()> {
        let rec = self.record()?;
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

/// Records a run: appends frames to its log as they arrive.
pub struct RunWriter {
    dir: PathBuf,
    meta: RunMeta,
    log: LogWriter,
    data: Assembled,
    last_sync: Instant,
}

impl RunWriter {
    /// Creates a new run folder under `store` (created if needed) and writes its metadata.
    pub fn create(store: &Path, mut meta: RunMeta) -> Result<RunWriter> {
        std::fs::create_dir_all(store).map_err(|e| {
            StoreError::io(
                format!(
                    "cannot create the store {} (use --store DIR)",
                    store.display()
                ),
                e,
            )
        })?;
        let base = meta.folder_name();
        let mut n = 1;
        let dir = loop {
            let name = if n == 1 {
                base.clone()
            } else {
                format!("{base}-{n}")
            };
            let dir = store.join(&name);
            match std::fs::create_dir(&dir) {
                Ok(()) => {
                    meta.id = name;
                    break dir;
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && n < 1000 => n += 1,
                Err(e) => {
                    return Err(StoreError::io(
                        format!("cannot create run folder {}", dir.display()),
                        e,
                    ))
                }
            }
        };
        meta.status = RunStatus::Recording;
        write_toml_atomic(&dir.join(META_FILE), &meta)?;
        let log = LogWriter::create(
            &dir.join(LOG_FILE),
            meta.device.as_ref().map(|d| d.protocol),
        )?;
        Ok(RunWriter {
            dir,
            meta,
            log,
            data: Assembled::default(),
            last_sync: Instant::now(),
        })
    }

    /// Reopens a run to add frames (after a lost link or a killed recorder), cutting a torn tail.
    /// With `salvage`, a corrupt log is cut after its intact prefix. Returns the writer and what
    /// was cut, if anything.
    pub fn resume(dir: &Path, salvage: bool) -> Result<(RunWriter, Option<Recovery>)> {
        let meta: RunMeta = read_toml(&dir.join(META_FILE))?;
        let (log, contents) = LogWriter::reopen(
            &dir.join(LOG_FILE),
            salvage,
            meta.device.as_ref().map(|d| d.protocol),
        )?;
        let data = Assembled::from_records(&contents.records, contents.header.protocol);
        Ok((
            RunWriter {
                dir: dir.to_owned(),
                meta,
                log,
                data,
                last_sync: Instant::now(),
            },
            contents.recovery,
        ))
    }

    pub fn dir(&self) -> &Path {
        &self.dir
    }

    pub fn meta(&self) -> &RunMeta {
        &self.meta
    }

    pub fn meta_mut(&mut self) -> &mut RunMeta {
        &mut self.meta
    }

    /// Logs one raw wire frame (as received) and files the message it holds. Frames that do not
    /// decode are refused (the link layer asks again for them).
    pub fn append_frame(&mut self, raw: &[u8]) -> Result<()> {
        let f = self.decode(raw)?;
        self.log_frame(raw, f)
    }

    /// Files one raw wire frame (as received) into the run: logs it if the run does not hold it
    /// yet; a frame the run already holds byte for byte is not logged twice; a frame whose place
    /// the run holds with other bytes is of another run, and is not logged either (the caller
    /// decides). Frames that do not decode are refused.
    pub fn file_frame(&mut self, raw: &[u8]) -> Result<Filed> {
        let f = self.decode(raw)?;
        let Some(slot) = Slot::of(&f.msg) else {
            return Ok(Filed::Other);
        };
        if let Some((_, held)) = self.data.raw.get(&slot) {
            return Ok(if held[..] == *raw {
                Filed::Same
            } else {
                Filed::Differs(slot.name())
            });
        }
        self.log_frame(raw, f)?;
        Ok(Filed::New)
    }

    fn decode(&self, raw: &[u8]) -> Result<tribo_wire::Frame<DeviceMsg>> {
        tribo_wire::v1::decode_as(self.log.header().protocol, raw).map_err(|e| {
            StoreError::new(
                ErrorKind::Invalid,
                format!("refusing to log a bad frame: {e}"),
            )
        })
    }

    fn log_frame(&mut self, raw: &[u8], f: tribo_wire::Frame<DeviceMsg>) -> Result<()> {
        let msg = f.msg;
        let is_header = matches!(msg, DeviceMsg::RunStarted(_));
        let is_end = matches!(msg, DeviceMsg::RunEnded(_) | DeviceMsg::Result(_));
        if let DeviceMsg::RunStarted(h) = &msg {
            self.meta.device_run_id = Some(h.run_id);
            if h.temp_c.is_finite() {
                self.meta.temp_c = Some(clean(h.temp_c));
            }
        }
        if is_header {
            // The rig's run id is how `tribo pull` finds this folder again, even if this process
            // is killed before `finish`: written before the header goes into the log, so that no
            // moment leaves a logged header in a folder `tribo pull` cannot find (a folder killed
            // in between holds the run id and no header; the pull asks the rig for the header).
            write_toml_atomic(&self.dir.join(META_FILE), &self.meta)?;
        }
        self.log.append(raw)?;
        self.data.add(f.seq, raw, msg);
        if is_header || is_end || self.last_sync.elapsed() >= Duration::from_secs(1) {
            self.log.sync()?;
            self.last_sync = Instant::now();
        }
        Ok(())
    }

    /// Block `i`, if logged.
    pub fn block(&self, i: u32) -> Option<&SampleBlock> {
        self.data.blocks.get(&i)
    }

    /// Whether this frame is a run event (gap, ECR range change) already logged.
    pub fn has_event(&self, msg: &DeviceMsg) -> bool {
        self.data.has_event(msg)
    }

    /// Acquisition gaps logged so far.
    pub fn gaps(&self) -> impl Iterator<Item = &Gap> {
        self.data.gaps.values()
    }

    /// Whether block `i` is already logged.
    pub fn has_block(&self, i: u32) -> bool {
        self.data.blocks.contains_key(&i)
    }

    pub fn blocks(&self) -> usize {
        self.data.blocks.len()
    }

    pub fn header(&self) -> Option<&RunHeader> {
        self.data.header.as_ref()
    }

    pub fn end(&self) -> Option<&RunEnd> {
        self.data.end.as_ref()
    }

    pub fn onboard(&self) -> Option<&OnboardResult> {
        self.data.result.as_ref()
    }

    pub fn missing_blocks(&self) -> Vec<u32> {
        self.data.missing()
    }

    /// First block a resumed `Pull` should ask for.
    pub fn resume_from(&self) -> u32 {
        self.data.resume_from()
    }

    /// Header, every block and event, result and end present ([`Completeness::is_complete`]).
    pub fn is_complete(&self) -> bool {
        self.data.completeness().is_complete()
    }

    /// How much of the run is held.
    pub fn completeness(&self) -> Completeness {
        self.data.completeness()
    }

    /// Blocks held that this tribo cannot unpack ([`Completeness::undecodable`]).
    pub fn undecodable_blocks(&self) -> &[u32] {
        &self.data.undecodable_blocks
    }

    /// Blocks before which run events look missing ([`Completeness::event_holes`]).
    pub fn event_holes(&self) -> Vec<u32> {
        self.data.event_holes()
    }

    /// The highest block held, if any.
    pub fn last_block(&self) -> Option<u32> {
        self.data.blocks.keys().next_back().copied()
    }

    /// Whether the on-board result is held.
    pub fn has_result(&self) -> bool {
        self.data.result.is_some()
    }

    /// The run frames held, in the rig's order ([`Run::frames`]).
    pub fn frames(&self) -> Vec<&[u8]> {
        self.data.frames()
    }

    /// How many run frames are held.
    pub fn frames_held(&self) -> usize {
        self.data.raw.len()
    }

    /// Syncs the log and writes the metadata with its final status; the status is derived from
    /// what was received unless `aborted`. Returns the run read back.
    pub fn finish(mut self, aborted: bool) -> Result<Run> {
        self.log.sync()?;
        let recorded = if aborted {
            RunStatus::Aborted
        } else {
            RunStatus::Incomplete
        };
        self.meta.status = derive_status(recorded, &self.data);
        write_toml_atomic(&self.dir.join(META_FILE), &self.meta)?;
        Run::open(&self.dir)
    }

    /// Writes the metadata as it is now (e.g. after the link was lost), leaving the log open.
    pub fn checkpoint(&mut self, status: RunStatus) -> Result<()> {
        self.log.sync()?;
        self.meta.status = status;
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

/// Replaces non-finite values by the previous finite one (the first finite one at the start).
fn fill_gaps(v: &mut [f64]) {
    let Some(first) = v.iter().copied().find(|x| x.is_finite()) else {
        return;
    };
    let mut last = first;
    for x in v.iter_mut() {
        if x.is_finite() {
            last = *x;
        } else {
            *x = last;
        }
    }
}
