//! Samples and how they travel: the hardware sample clock, blocks of counts (raw and packed), and
//! the run events among them (acquisition gaps, ECR range changes).

use super::*;

wire_type! {
    /// A hardware sample clock: a timer clocked at `timer_hz` triggers one conversion every
    /// `ticks_per_sample` ticks, so the rate `timer_hz / ticks_per_sample` is an exact rational and the
    /// time of sample `i` is `i * ticks_per_sample / timer_hz` seconds, with no rounding that grows
    /// with `i`.
    #[derive(Copy, Eq, Hash)]
    pub struct SampleClock {
        pub timer_hz: u32,
        pub ticks_per_sample: u32,
    }
}

impl SampleClock {
    /// The clock of a rate that is exactly `rate_hz` (what a record without a clock assumed).
    pub const fn exact(rate_hz: u32) -> Self {
        SampleClock {
            timer_hz: rate_hz,
            ticks_per_sample: 1,
        }
    }

    /// A usable clock: both numbers non-zero.
    pub const fn is_valid(&self) -> bool {
        self.timer_hz > 0 && self.ticks_per_sample > 0
    }

    /// Samples per second (NaN for an invalid clock).
    pub fn rate_hz(&self) -> f64 {
        if !self.is_valid() {
            return f64::NAN;
        }
        self.timer_hz as f64 / self.ticks_per_sample as f64
    }

    /// Time of sample `index`, seconds after sample 0.
    pub fn time_s(&self, index: u64) -> f64 {
        if !self.is_valid() {
            return f64::NAN;
        }
        // Integer part and remainder apart, so that the result is exact to f64 rounding for any index.
        let ticks = index as u128 * self.ticks_per_sample as u128;
        let whole = ticks / self.timer_hz as u128;
        let rest = ticks % self.timer_hz as u128;
        whole as f64 + rest as f64 / self.timer_hz as f64
    }

    /// Time of sample `index`, whole microseconds after sample 0 (rounded down).
    pub fn time_us(&self, index: u64) -> u64 {
        if !self.is_valid() {
            return 0;
        }
        let us = index as u128 * self.ticks_per_sample as u128 * 1_000_000 / self.timer_hz as u128;
        us.min(u64::MAX as u128) as u64
    }

    /// Whole sample periods completed in `us` microseconds: how many samples a clock started `us`
    /// ago has converted (the first one a period after the start).
    pub fn samples_in_us(&self, us: u64) -> u64 {
        if !self.is_valid() {
            return 0;
        }
        let n = us as u128 * self.timer_hz as u128 / (self.ticks_per_sample as u128 * 1_000_000);
        n.min(u64::MAX as u128) as u64
    }

    /// Whether this clock produces exactly `rate_hz` samples per second.
    pub fn is_exactly(&self, rate_hz: u32) -> bool {
        self.is_valid() && self.timer_hz as u64 == rate_hz as u64 * self.ticks_per_sample as u64
    }
}

wire_type! {
    /// [`BLOCK_LEN`] (or fewer, for the last block) consecutive samples of the run's channels,
    /// interleaved: sample `i`, channel position `c` is `counts[i * channels.len() + c]`.
    pub struct SampleBlock {
        pub run_id: u32,
        /// Index of this block in the run, from 0.
        pub block: u32,
        /// Index in the run of the block's first sample (time = index / sample rate).
        pub first_sample: u32,
        /// Device time of the block's first sample.
        pub t_us: u64,
        pub channels: ChannelSet,
        /// ECR transimpedance range during the block and the resistance it measured.
        pub ecr_range: u8,
        pub log10_ecr_ohm: f32,
        pub temp_c: f32,
        pub counts: Counts,
    }
}

impl SampleBlock {
    /// Number of whole samples in the block.
    pub fn samples(&self) -> usize {
        match self.channels.len() {
            0 => 0,
            n => self.counts.len() / n,
        }
    }

    /// Counts of sample `i`, one per channel of the set, if the block has that sample.
    pub fn sample(&self, i: usize) -> Option<&[u16]> {
        let n = self.channels.len();
        self.counts.get(i * n..(i + 1) * n).filter(|_| n > 0)
    }

    /// All counts of one channel, in time order.
    pub fn channel(&self, c: Channel) -> impl Iterator<Item = u16> + '_ {
        let n = self.channels.len();
        let pos = self.channels.position(c);
        self.counts
            .iter()
            .skip(pos.unwrap_or(0))
            .step_by(n.max(1))
            .take(if pos.is_some() { self.samples() } else { 0 })
            .copied()
    }

    /// A well-formed block: counts a whole number of samples of a valid, non-empty set, at most
    /// [`BLOCK_LEN`] of them.
    pub fn is_consistent(&self) -> bool {
        let n = self.channels.len();
        self.channels.0 & !ChannelSet::ALL.0 == 0
            && n > 0
            && self.counts.len().is_multiple_of(n)
            && self.counts.len() / n <= BLOCK_LEN
    }
}

/// The counts of a [`SampleBlock`], sent as raw little-endian bytes (two per count, not varints:
/// counts sit around mid-scale, where a varint would take three bytes).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counts(pub heapless::Vec<u16, MAX_BLOCK_COUNTS>);

impl core::ops::Deref for Counts {
    type Target = [u16];
    fn deref(&self) -> &[u16] {
        &self.0
    }
}

impl Counts {
    /// Appends a count; `Err` when the block is full.
    pub fn push(&mut self, c: u16) -> Result<(), u16> {
        self.0.push(c)
    }

    pub fn clear(&mut self) {
        self.0.clear()
    }

    pub fn from_slice(s: &[u16]) -> Option<Self> {
        heapless::Vec::from_slice(s).ok().map(Counts)
    }
}

impl Serialize for Counts {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        CountsBytes(&self.0).serialize(s)
    }
}

/// Counts serialised as [`Counts`] is: little-endian bytes.
struct CountsBytes<'a>(&'a [u16]);

impl Serialize for CountsBytes<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if self.0.len() > MAX_BLOCK_COUNTS {
            return Err(serde::ser::Error::custom("more counts than a block holds"));
        }
        let mut bytes = [0u8; 2 * MAX_BLOCK_COUNTS];
        for (pair, c) in bytes.chunks_exact_mut(2).zip(self.0.iter()) {
            pair.copy_from_slice(&c.to_le_bytes());
        }
        s.serialize_bytes(&bytes[..2 * self.0.len()])
    }
}

impl<'de> Deserialize<'de> for Counts {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Counts;
            fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                write!(
                    f,
                    "an even number of bytes, at most {}",
                    2 * MAX_BLOCK_COUNTS
                )
            }
            fn visit_bytes<E: serde::de::Error>(self, b: &[u8]) -> Result<Counts, E> {
                if !b.len().is_multiple_of(2) || b.len() > 2 * MAX_BLOCK_COUNTS {
                    return Err(E::invalid_length(b.len(), &self));
                }
                let mut v = heapless::Vec::new();
                for pair in b.chunks_exact(2) {
                    // Cannot fail: the length was checked above.
                    let _ = v.push(u16::from_le_bytes([pair[0], pair[1]]));
                }
                Ok(Counts(v))
            }
        }
        d.deserialize_bytes(V)
    }
}

wire_type! {
    /// Samples `first_sample .. first_sample + count` of run `run_id` were lost: the acquisition
    /// overran. Stored and sent with the run's other frames, so the gap is part of the record.
    #[derive(Copy)]
    pub struct Gap {
        pub run_id: u32,
        pub first_sample: u32,
        pub count: u32,
    }
}

wire_type! {
    /// From sample `first_sample` of run `run_id` on, the ECR channel was converted on `range`; the
    /// first `settling` samples of it were taken while the transimpedance amplifier settled.
    #[derive(Copy)]
    pub struct EcrRangeChange {
        pub run_id: u32,
        pub first_sample: u32,
        pub range: u8,
        pub settling: u16,
    }
}

wire_type! {
    /// A compressed sample block: the v2 form of [`SampleBlock`], every field the same, the counts
    /// packed by [`crate::codec`] ([`PackedBlock::pack`], [`PackedBlock::unpack`]).
    pub struct PackedBlock {
        pub run_id: u32,
        /// Index of this block in the run, from 0.
        pub block: u32,
        /// Index in the run of the block's first sample.
        pub first_sample: u32,
        /// Device time of the block's first sample.
        pub t_us: u64,
        pub channels: ChannelSet,
        /// Number of samples in the block.
        pub samples: u16,
        /// ECR transimpedance range during the block.
        pub ecr_range: u8,
        pub temp_c: f32,
        pub log10_ecr_ohm: f32,
        /// The compressed counts ([`crate::codec`] describes the format). Serialised as bytes:
        /// the same bytes as a sequence of `u8` in postcard (a length, then the bytes), in one
        /// copy rather than one call per byte.
        #[serde(serialize_with = "packed_bytes")]
        pub data: heapless::Vec<u8, MAX_PACKED_BYTES>,
    }
}

fn packed_bytes<S: serde::Serializer>(
    data: &heapless::Vec<u8, MAX_PACKED_BYTES>,
    s: S,
) -> Result<S::Ok, S::Error> {
    s.serialize_bytes(data)
}

/// Largest compressed payload of a [`PackedBlock`]: the raw form (a format byte and two bytes per
/// count), which the codec falls back to when compression would not pay, plus a little room.
pub const MAX_PACKED_BYTES: usize = 2 * MAX_BLOCK_COUNTS + 16;
