//! The data the host generates for the target: simulated records (16-bit counts), what the host's
//! build of the firmware library made of them, and frames the host encoded.
//!
//! Written by [`crate::generate`] (`cargo xtask target-test` does it before every build) and
//! embedded in the binary with `include_bytes!`. Layout: a postcard [`Header`], then `records`
//! postcard [`Record`]s; the counts and frames are borrowed from the embedded bytes (no copy, no
//! heap).

use serde::{Deserialize, Serialize};
use tribo_firmware::analysis::{Phase, Pipeline, StopReason};
use tribo_firmware::wire::{Configure, OnboardResult, CHANNELS};

/// First bytes of a bundle.
pub const MAGIC: [u8; 8] = *b"TRIBOTT1";

/// Bytes serialised as bytes (serde's `&[u8]` is a sequence; postcard happens to lay both out
/// alike, but this does not rely on it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bytes<'a>(pub &'a [u8]);

impl Serialize for Bytes<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(self.0)
    }
}

impl<'de: 'a, 'a> Deserialize<'de> for Bytes<'a> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        <&'a [u8]>::deserialize(d).map(Bytes)
    }
}

/// The start of the bundle.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Header<'a> {
    pub magic: [u8; 8],
    /// Frames of [`crate::tests::wire::vectors`], encoded on the host, back to back (each ends in 0).
    #[serde(borrow)]
    pub frames: Bytes<'a>,
    /// Number of records that follow.
    pub records: u32,
}

/// How the pipeline stopped (a wire-stable copy of [`Phase`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Stop {
    /// The record ended first.
    NotFinished,
    AtRest,
    InNoise,
    NoMotion,
    MaxDuration,
    BufferFull,
}

impl From<Phase> for Stop {
    fn from(p: Phase) -> Self {
        match p {
            Phase::Holding | Phase::Running => Stop::NotFinished,
            Phase::Finished(StopReason::AtRest) => Stop::AtRest,
            Phase::Finished(StopReason::InNoise) => Stop::InNoise,
            Phase::Finished(StopReason::NoMotion) => Stop::NoMotion,
            Phase::Finished(StopReason::MaxDuration) => Stop::MaxDuration,
            Phase::Finished(StopReason::BufferFull) => Stop::BufferFull,
        }
    }
}

/// What the on-board analysis made of a record.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Analysis {
    /// Samples pushed after release (the pipeline stops taking them when it finishes).
    pub pushed: u32,
    /// Half-cycles recorded.
    pub half_cycles: u32,
    pub stop: Stop,
    pub result: OnboardResult,
}

/// One simulated run of the rig: the counts the converters would give, hold first.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Record<'a> {
    pub name: &'a str,
    /// What was simulated, in words.
    pub about: &'a str,
    /// The run's configuration (channels: all five, in channel order).
    pub configure: Configure,
    /// Friction law simulated: Coulomb μ0 and viscous μ1 (dimensionless, as the analysis reports).
    pub mu0: f64,
    pub mu1: f64,
    /// The first `hold` samples were taken while the magnet held the pin.
    pub hold: u32,
    /// [`CHANNELS`] little-endian `u16` counts per sample (displacement, velocity, force, ECR,
    /// temperature).
    #[serde(borrow)]
    pub counts: Bytes<'a>,
    /// The host's result for this record (same code: [`analyse`]).
    pub host: Analysis,
}

/// Bytes per sample in [`Record::counts`].
pub const SAMPLE_BYTES: usize = 2 * CHANNELS;

impl Record<'_> {
    /// Number of samples, hold included.
    pub fn len(&self) -> usize {
        self.counts.0.len() / SAMPLE_BYTES
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Counts of sample `i` (all channels); zeros past the end.
    pub fn sample(&self, i: usize) -> [u16; CHANNELS] {
        let mut s = [0u16; CHANNELS];
        if let Some(b) = self.counts.0.get(i * SAMPLE_BYTES..(i + 1) * SAMPLE_BYTES) {
            for (c, pair) in s.iter_mut().zip(b.chunks_exact(2)) {
                *c = u16::from_le_bytes([pair[0], pair[1]]);
            }
        }
        s
    }
}

/// The parsed bundle.
#[derive(Debug, Clone, Copy)]
pub struct Bundle<'a> {
    pub header: Header<'a>,
    records: &'a [u8],
}

/// Why bytes are not a bundle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BundleError {
    Magic,
    Header,
    Record(u32),
}

impl<'a> Bundle<'a> {
    /// Parses the header and checks every record decodes.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, BundleError> {
        let (header, records) =
            postcard::take_from_bytes::<Header<'a>>(bytes).map_err(|_| BundleError::Header)?;
        if header.magic != MAGIC {
            return Err(BundleError::Magic);
        }
        let b = Bundle { header, records };
        let mut rest = records;
        for i in 0..header.records {
            let (_, r) = postcard::take_from_bytes::<Record<'a>>(rest)
                .map_err(|_| BundleError::Record(i))?;
            rest = r;
        }
        Ok(b)
    }

    /// The records, in order.
    pub fn records(&self) -> impl Iterator<Item = Record<'a>> + 'a {
        let mut rest = self.records;
        (0..self.header.records).map_while(move |_| {
            let (r, tail) = postcard::take_from_bytes::<Record<'a>>(rest).ok()?;
            rest = tail;
            Some(r)
        })
    }

    /// The record called `name`.
    pub fn record(&self, name: &str) -> Option<Record<'a>> {
        self.records().find(|r| r.name == name)
    }
}

/// Samples handed to the pipeline per measured call (the loop over them is part of the cost, as in
/// any caller).
pub const CHUNK: usize = 256;

/// Costs of one pass of the pipeline over a record (all `None` on the host).
#[derive(Debug, Clone, Copy, Default)]
pub struct PipelineCost {
    /// Instructions of every `push` after release, summed.
    pub push: Option<u64>,
    /// Worst chunk of [`CHUNK`] pushes.
    pub worst_chunk: Option<u64>,
    /// Instructions of `finish` (the end-of-run fit, in one call).
    pub finish: Option<u64>,
    /// Deepest stack of a chunk of pushes or of `finish`, bytes.
    pub stack: Option<u32>,
}

/// Runs the on-board analysis over a record as the application does: the hold samples to
/// [`Pipeline::capture`], then [`Pipeline::release`], then [`Pipeline::push`] until the pipeline
/// finishes (or the record ends), then [`Pipeline::finish`]. The host's expected results and the
/// target's results both come from this function.
///
/// `measure(f)` runs `f` and returns its cost: the target's probe, or a plain call on the host.
pub fn analyse(
    rec: &Record<'_>,
    pipeline: &mut Pipeline,
    measure: &mut dyn FnMut(&mut dyn FnMut()) -> crate::Cost,
) -> Result<(Analysis, PipelineCost), tribo_firmware::analysis::ConfigError> {
    pipeline.reset(&rec.configure)?;
    let n = rec.len();
    let hold = (rec.hold as usize).min(n);
    for i in 0..hold {
        pipeline.capture(&rec.sample(i));
    }
    pipeline.release();
    let mut cost = PipelineCost::default();
    let mut i = hold;
    let mut pushed = 0u32;
    let mut chunk = [[0u16; CHANNELS]; CHUNK];
    while i < n && !pipeline.is_finished() {
        let m = (n - i).min(CHUNK);
        for (k, s) in chunk.iter_mut().take(m).enumerate() {
            *s = rec.sample(i + k);
        }
        let mut taken = 0u32;
        let c = measure(&mut || {
            for s in chunk.iter().take(m) {
                taken += 1;
                if pipeline.push(s) != Phase::Running {
                    break;
                }
            }
        });
        pushed += taken;
        i += m;
        add(&mut cost.push, c.instructions);
        max(&mut cost.worst_chunk, c.instructions);
        max32(&mut cost.stack, c.stack);
    }
    let mut result = None;
    let c = measure(&mut || result = Some(pipeline.finish(0)));
    cost.finish = c.instructions;
    max32(&mut cost.stack, c.stack);
    let result = result.unwrap_or_else(|| pipeline.finish(0));
    Ok((
        Analysis {
            pushed,
            half_cycles: pipeline.half_cycles().len() as u32,
            stop: pipeline.phase().into(),
            result,
        },
        cost,
    ))
}

fn add(acc: &mut Option<u64>, v: Option<u64>) {
    if let Some(v) = v {
        *acc = Some(acc.unwrap_or(0) + v);
    }
}

fn max(acc: &mut Option<u64>, v: Option<u64>) {
    if let Some(v) = v {
        *acc = Some(acc.map_or(v, |a| a.max(v)));
    }
}

fn max32(acc: &mut Option<u32>, v: Option<u32>) {
    if let Some(v) = v {
        *acc = Some(acc.map_or(v, |a| a.max(v)));
    }
}

/// Bit-for-bit equality of two results (`NaN` fields equal when their bits are).
pub fn same_bits(a: &OnboardResult, b: &OnboardResult) -> bool {
    let f = |r: &OnboardResult| {
        let e = |e: &tribo_firmware::wire::Estimate| {
            [e.mu0, e.mu1, e.mu0_se, e.mu1_se].map(f32::to_bits)
        };
        (
            [
                r.frequency_hz,
                r.initial_amplitude_m,
                r.duration_s,
                r.curvature,
            ]
            .map(f32::to_bits),
            e(&r.best),
            e(&r.averaging),
            e(&r.decrement),
        )
    };
    a.run_id == b.run_id
        && a.verdict == b.verdict
        && a.cycles == b.cycles
        && a.shape == b.shape
        && f(a) == f(b)
}

/// Distance in units in the last place between two `f32` (0 when equal; `u32::MAX` across a `NaN`).
pub fn ulps(a: f32, b: f32) -> u32 {
    if a.to_bits() == b.to_bits() {
        return 0;
    }
    if a.is_nan() || b.is_nan() {
        return u32::MAX;
    }
    // Map the sign-magnitude bits onto a monotonic integer line.
    let key = |x: f32| {
        let b = x.to_bits() as i64;
        if b & 0x8000_0000 != 0 {
            0x8000_0000 - b
        } else {
            b
        }
    };
    (key(a) - key(b)).unsigned_abs().min(u32::MAX as u64) as u32
}
