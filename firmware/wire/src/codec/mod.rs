//! Block compression: the counts of a [`SampleBlock`] packed into a [`PackedBlock`] and back,
//! bit-exact, with no allocation and no panic on any input.
//!
//! Each channel of a block is coded on its own (counts de-interleaved) with the predictor that
//! suits it best, chosen per block:
//!
//! * **level**: residual = count − a 16-bit base (the block's mean): a channel at rest, where only
//!   the noise moves;
//! * **slope**: residual = first difference: slow or stepwise signals (temperature, ECR, force);
//! * **curve**: residual = second difference: the oscillation itself, sampled hundreds of times per
//!   cycle, whose second difference is a few counts;
//! * **verbatim**: 16 bits per count, when nothing predicts it.
//!
//! Residuals are taken modulo 2¹⁶ (so any counts round-trip, however wild), folded to unsigned by
//! zig-zag (0, −1, 1, −2, … → 0, 1, 2, 3, …) and Rice-coded with a per-channel parameter `k`:
//! `u >> k` in unary (ones closed by a zero), then the `k` low bits. A quotient of [`ESCAPE`] or more
//! is sent as [`ESCAPE`] ones followed by the 16-bit value, so one spike costs 32 bits, not
//! thousands. When the whole block would not be smaller than its raw counts, it is sent raw.
//!
//! Format of [`PackedBlock::data`] (the shape, `channels` and `samples`, is in the block's fields):
//!
//! ```text
//! byte 0 = 0 (RAW):  then exactly 2·n·c bytes: the counts, interleaved, u16 little-endian
//! byte 0 = 1 (RICE): then a bit stream, most significant bit first, for each channel in order:
//!     mode  2 bits   0 level, 1 slope, 2 curve, 3 verbatim
//!     verbatim: n × 16 bits
//!     level:    base 16 bits,                k 4 bits, n residuals
//!     slope:    first count 16 bits,          k 4 bits, n − 1 residuals
//!     curve:    first two counts 2 × 16 bits, k 4 bits, n − 2 residuals
//!               (fewer counts than that: the counts verbatim, k and residuals absent)
//!     k = 15: every residual is 0 and none is sent
//!   then zero bits up to the byte boundary, and nothing after.
//! ```
//!
//! The decoder accepts exactly that grammar: a truncated stream, a wrong length, padding that is not
//! zero, trailing bytes or an unknown format byte are errors ([`CodecError`]), never a panic.

mod bits;
mod predictor;

use crate::msg::{ChannelSet, Counts, DeviceMsg, PackedBlock, SampleBlock, BLOCK_LEN, CHANNELS};
use bits::{BitReader, BitWriter};
use predictor::*;

/// A Rice quotient this large or larger is sent as an escape and the value in 16 bits.
pub const ESCAPE: u32 = 16;
/// `k` that says "every residual of this channel is zero".
const K_ZERO: u32 = 15;
/// Largest Rice parameter used (a residual needs at most 16 bits).
const K_MAX: u32 = 14;

const FORMAT_RAW: u8 = 0;
const FORMAT_RICE: u8 = 1;

/// Why packed data could not be decoded (or a block not packed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CodecError {
    /// No data at all (not even the format byte).
    Empty,
    /// The format byte is neither raw nor Rice: data from a newer codec, or garbage.
    UnknownFormat(u8),
    /// The data ends before every count is decoded.
    Truncated,
    /// Bytes (or non-zero padding bits) follow the last count.
    Trailing,
    /// Raw data whose length is not two bytes per count.
    RawLength,
    /// Channel set or sample count out of range (empty or unknown channels, more than
    /// [`BLOCK_LEN`] samples), or counts that are not a whole number of samples.
    Shape,
    /// The output buffer is too small for the encoding (cannot happen with [`MAX_PACKED_BYTES`]).
    ///
    /// [`MAX_PACKED_BYTES`]: crate::msg::MAX_PACKED_BYTES
    Overflow,
}

impl core::fmt::Display for CodecError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            CodecError::Empty => f.write_str("packed block has no data"),
            CodecError::UnknownFormat(b) => write!(
                f,
                "packed block format {b} is unknown (written by a newer firmware, or damaged)"
            ),
            CodecError::Truncated => f.write_str("packed block data ends too early"),
            CodecError::Trailing => f.write_str("packed block data has bytes after its last count"),
            CodecError::RawLength => f.write_str("raw packed block has the wrong length"),
            CodecError::Shape => {
                f.write_str("packed block has an impossible channel set or length")
            }
            CodecError::Overflow => f.write_str("packed block does not fit its buffer"),
        }
    }
}

#[cfg(any(test, feature = "std"))]
impl std::error::Error for CodecError {}

/// Bytes of the raw form of `n` samples of `c` channels (format byte included).
pub const fn raw_len(samples: usize, channels: usize) -> usize {
    1 + 2 * samples * channels
}

fn check_shape(samples: usize, channels: usize) -> Result<(), CodecError> {
    if channels == 0 || channels > CHANNELS || samples > BLOCK_LEN {
        return Err(CodecError::Shape);
    }
    Ok(())
}

/// Packs `counts` (`samples` × `channels`, interleaved) into `out`; returns the bytes written.
/// The output never exceeds [`raw_len`]`(samples, channels)` bytes. The same as the steps of a
/// [`Packer`] run to the end.
pub fn encode(
    counts: &[u16],
    samples: usize,
    channels: usize,
    out: &mut [u8],
) -> Result<usize, CodecError> {
    let mut p = Packer::new();
    loop {
        if let Some(n) = p.step(counts, samples, channels, out)? {
            return Ok(n);
        }
    }
}

/// [`encode`] one channel at a time, for a caller with a time budget (the firmware packs a block
/// over several polls: a channel of 64 samples is ~9k instructions on its Cortex-M7). Each call
/// of [`Packer::step`] takes the same counts and the same `out`; together they write exactly what
/// [`encode`] writes.
#[derive(Debug, Clone, Copy, Default)]
pub struct Packer {
    /// Next channel to encode.
    channel: usize,
    /// The bit writer's state: bytes written after the format byte, pending bits.
    pos: usize,
    acc: u64,
    bits: u32,
    /// The Rice stream did not fit: the block goes raw.
    raw: bool,
}

impl Packer {
    pub const fn new() -> Self {
        Packer {
            channel: 0,
            pos: 0,
            acc: 0,
            bits: 0,
            raw: false,
        }
    }

    /// Encodes the next channel; once the last is done, finishes the block and returns its length.
    pub fn step(
        &mut self,
        counts: &[u16],
        samples: usize,
        channels: usize,
        out: &mut [u8],
    ) -> Result<Option<usize>, CodecError> {
        check_shape(samples, channels)?;
        if counts.len() != samples * channels {
            return Err(CodecError::Shape);
        }
        let raw = raw_len(samples, channels);
        if out.len() < raw {
            return Err(CodecError::Overflow);
        }
        // Rice first, into at most the raw size; raw when it does not fit there.
        if !self.raw && self.channel < channels {
            let mut w = BitWriter {
                out: &mut out[1..raw],
                pos: self.pos,
                acc: self.acc,
                bits: self.bits,
            };
            if encode_channel(counts, samples, channels, self.channel, &mut w).is_err() {
                self.raw = true;
            } else {
                self.channel += 1;
                (self.pos, self.acc, self.bits) = (w.pos, w.acc, w.bits);
                if self.channel < channels {
                    return Ok(None);
                }
            }
        }
        if !self.raw {
            let w = BitWriter {
                out: &mut out[1..raw],
                pos: self.pos,
                acc: self.acc,
                bits: self.bits,
            };
            if let Ok(n) = w.finish() {
                if 1 + n < raw {
                    out[0] = FORMAT_RICE;
                    return Ok(Some(1 + n));
                }
            }
        }
        out[0] = FORMAT_RAW;
        for (i, c) in counts.iter().enumerate() {
            out[1 + 2 * i..3 + 2 * i].copy_from_slice(&c.to_le_bytes());
        }
        Ok(Some(raw))
    }
}

/// Channel `c` of the Rice stream.
fn encode_channel(
    counts: &[u16],
    n: usize,
    channels: usize,
    c: usize,
    w: &mut BitWriter<'_>,
) -> Result<(), CodecError> {
    let mut lane = [0u16; BLOCK_LEN];
    let mut r = [0u16; BLOCK_LEN];
    // De-interleave (the caller checked counts.len() == n * channels).
    for (x, v) in lane
        .iter_mut()
        .zip(counts.chunks_exact(channels))
        .map(|(x, s)| (x, s.get(c)))
    {
        *x = v.copied().unwrap_or(0);
    }
    let x = &lane[..n];
    let (p, m) = plan(x, &mut r);
    w.put(p.mode as u32, 2)?;
    let warm = warm_up(p.mode, n);
    if p.mode == Mode::Level {
        w.put(p.base as u32, 16)?;
    }
    for &v in &x[..warm] {
        w.put(v as u32, 16)?;
    }
    if p.mode == Mode::Verbatim || warm == n && p.mode != Mode::Level {
        return Ok(());
    }
    w.put(p.k, 4)?;
    if p.k == K_ZERO {
        return Ok(());
    }
    let mask = (1u32 << p.k) - 1;
    for &u in &r[..m] {
        let u = u as u32;
        let q = u >> p.k;
        if q < ESCAPE {
            // q ones, a zero, then the k low bits: one write of q + 1 + k ≤ 31 bits.
            w.put((((1u32 << q) - 1) << (1 + p.k)) | (u & mask), q + 1 + p.k)?;
        } else {
            w.put((1 << ESCAPE) - 1, ESCAPE)?;
            w.put(u, 16)?;
        }
    }
    Ok(())
}

/// Unpacks `data` into `out` (`samples` × `channels` counts, interleaved).
pub fn decode(
    data: &[u8],
    samples: usize,
    channels: usize,
    out: &mut [u16],
) -> Result<(), CodecError> {
    check_shape(samples, channels)?;
    let n = samples;
    let out = out.get_mut(..n * channels).ok_or(CodecError::Overflow)?;
    let (&format, body) = data.split_first().ok_or(CodecError::Empty)?;
    match format {
        FORMAT_RAW => {
            if body.len() != 2 * n * channels {
                return Err(CodecError::RawLength);
            }
            for (o, b) in out.iter_mut().zip(body.chunks_exact(2)) {
                *o = u16::from_le_bytes([b[0], b[1]]);
            }
            Ok(())
        }
        FORMAT_RICE => {
            let mut r = BitReader::new(body);
            for c in 0..channels {
                let at = |i: usize| i * channels + c;
                let mode = Mode::from_bits(r.get(2)?);
                let base = if mode == Mode::Level {
                    r.get(16)? as u16
                } else {
                    0
                };
                let warm = warm_up(mode, n);
                for i in 0..warm {
                    out[at(i)] = r.get(16)? as u16;
                }
                if mode == Mode::Verbatim || warm == n && mode != Mode::Level {
                    continue;
                }
                let k = r.get(4)?;
                for i in warm..n {
                    let u = if k == K_ZERO {
                        0
                    } else {
                        let q = r.unary(ESCAPE)?;
                        if q < ESCAPE {
                            ((q << k) | r.get(k)?) as u16
                        } else {
                            r.get(16)? as u16
                        }
                    };
                    let res = unzigzag(u);
                    let pred = match mode {
                        Mode::Level => base,
                        Mode::Slope => out[at(i - 1)],
                        Mode::Curve => out[at(i - 1)].wrapping_mul(2).wrapping_sub(out[at(i - 2)]),
                        Mode::Verbatim => 0,
                    };
                    out[at(i)] = pred.wrapping_add(res);
                }
            }
            r.finish()
        }
        other => Err(CodecError::UnknownFormat(other)),
    }
}

impl PackedBlock {
    /// Packs a sample block (same run, index, time, ECR and temperature fields; counts compressed).
    /// The same as [`PackedBlock::start`] then [`PackedBlock::pack_step`] until done.
    pub fn pack(b: &SampleBlock) -> Result<PackedBlock, CodecError> {
        let mut p = PackedBlock::start(b)?;
        let mut packer = Packer::new();
        while !p.pack_step(b, &mut packer)? {}
        Ok(p)
    }

    /// A packed block of `b`'s fields whose data is not packed yet (see
    /// [`PackedBlock::pack_step`]).
    pub fn start(b: &SampleBlock) -> Result<PackedBlock, CodecError> {
        let channels = b.channels.len();
        if !b.is_consistent() {
            return Err(CodecError::Shape);
        }
        let samples = b.samples();
        let mut data = heapless::Vec::new();
        data.resize(raw_len(samples, channels), 0)
            .map_err(|_| CodecError::Overflow)?;
        Ok(PackedBlock {
            run_id: b.run_id,
            block: b.block,
            first_sample: b.first_sample,
            t_us: b.t_us,
            channels: b.channels,
            samples: samples as u16,
            ecr_range: b.ecr_range,
            temp_c: b.temp_c,
            log10_ecr_ohm: b.log10_ecr_ohm,
            data,
        })
    }

    /// Packs the next channel of `b` (the block this was started from) with `packer`; true once
    /// the data is complete.
    pub fn pack_step(&mut self, b: &SampleBlock, packer: &mut Packer) -> Result<bool, CodecError> {
        let (samples, channels) = (b.samples(), b.channels.len());
        match packer.step(&b.counts, samples, channels, &mut self.data)? {
            Some(len) => {
                self.data.truncate(len);
                Ok(true)
            }
            None => Ok(false),
        }
    }

    /// The sample block this packs, counts decoded.
    pub fn unpack(&self) -> Result<SampleBlock, CodecError> {
        if self.channels.0 & !ChannelSet::ALL.0 != 0 {
            return Err(CodecError::Shape);
        }
        let (n, c) = (self.samples as usize, self.channels.len());
        check_shape(n, c)?;
        let mut counts = [0u16; BLOCK_LEN * CHANNELS];
        decode(&self.data, n, c, &mut counts)?;
        Ok(SampleBlock {
            run_id: self.run_id,
            block: self.block,
            first_sample: self.first_sample,
            t_us: self.t_us,
            channels: self.channels,
            ecr_range: self.ecr_range,
            log10_ecr_ohm: self.log10_ecr_ohm,
            temp_c: self.temp_c,
            counts: Counts::from_slice(&counts[..n * c]).ok_or(CodecError::Shape)?,
        })
    }
}

impl DeviceMsg {
    /// The sample block this frame carries, whichever its form: a v1 [`DeviceMsg::Samples`] as is,
    /// a v2 [`DeviceMsg::Packed`] unpacked (an error if its data does not decode). `None` for other
    /// messages.
    pub fn sample_block(&self) -> Option<Result<SampleBlock, CodecError>> {
        match self {
            DeviceMsg::Samples(b) => Some(Ok(b.clone())),
            DeviceMsg::Packed(p) => Some(p.unpack()),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests;
