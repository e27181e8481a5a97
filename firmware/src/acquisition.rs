//! Acquisition: the ring the converter fills and the application drains, and the assembly of
//! converted samples into the wire's [`SampleBlock`]s.
//!
//! The ring never overwrites: a sample that finds it full is dropped *and counted*, and the count is
//! what [`crate::hal::SampleSource::adc_lost`] reports, so the application can say how many samples a
//! run lost instead of silently stitching the two sides of a gap together.

use crate::hal::{AnalogSample, ANALOG_CHANNELS};
use crate::wire::{Channel, ChannelCal, ChannelSet, Counts, SampleBlock, BLOCK_LEN};

/// A fixed-capacity FIFO of analog samples with an overrun counter.
#[derive(Debug, Clone)]
pub struct Ring<const N: usize> {
    buf: [AnalogSample; N],
    head: usize,
    len: usize,
    lost: u32,
}

impl<const N: usize> Default for Ring<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Ring<N> {
    pub const fn new() -> Self {
        Ring {
            buf: [[0; ANALOG_CHANNELS]; N],
            head: 0,
            len: 0,
            lost: 0,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub const fn capacity(&self) -> usize {
        N
    }

    /// Samples dropped because the ring was full, since the last [`Ring::clear`].
    pub fn lost(&self) -> u32 {
        self.lost
    }

    /// Empties the ring and zeroes the overrun count (at the start of an acquisition).
    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
        self.lost = 0;
    }

    /// Appends a sample; false (and counted as lost) when full.
    pub fn push(&mut self, s: AnalogSample) -> bool {
        if self.len == N {
            self.lost = self.lost.saturating_add(1);
            return false;
        }
        let i = (self.head + self.len) % N;
        self.buf[i] = s;
        self.len += 1;
        true
    }

    /// Moves the oldest samples into `out`; returns how many.
    pub fn pop_into(&mut self, out: &mut [AnalogSample]) -> usize {
        let n = out.len().min(self.len);
        for o in out.iter_mut().take(n) {
            *o = self.buf[self.head];
            self.head = (self.head + 1) % N;
        }
        self.len -= n;
        n
    }
}

/// Counts of one sample in the channel order of `channels`, written into `out` (at least
/// [`crate::wire::CHANNELS`] long); returns how many. The temperature count is `temp_c` through
/// `temp_cal` (the thermocouple is read over SPI, not by the ADC).
pub fn select(
    channels: ChannelSet,
    temp_cal: ChannelCal,
    s: &AnalogSample,
    temp_c: f32,
    out: &mut [u16],
) -> usize {
    let mut n = 0;
    for c in channels.iter() {
        let v = match c {
            Channel::Temperature => temp_cal.to_count(temp_c),
            other => s[other.index()],
        };
        if let Some(o) = out.get_mut(n) {
            *o = v;
            n += 1;
        }
    }
    n
}

/// Assembles the samples of a run into blocks of [`BLOCK_LEN`] samples of the run's channels.
///
/// Per sample this is a few array writes: the channel order is worked out once, and the
/// temperature count is converted again only when the reading changes (every 100 ms), not per
/// sample (on the M7 the straightforward version cost 280 instructions per five-channel sample).
#[derive(Debug, Clone)]
pub struct BlockBuilder {
    run_id: u32,
    channels: ChannelSet,
    temp_cal: ChannelCal,
    /// Channel index of each count of a sample, in order; `width` of them.
    slots: [u8; crate::wire::CHANNELS],
    width: usize,
    /// The last temperature converted (bits) and its count.
    temp: Option<(u32, u16)>,
    block: u32,
    samples: u32,
    /// Samples in `current`.
    filled: usize,
    current: Option<SampleBlock>,
}

impl BlockBuilder {
    pub fn new(run_id: u32, channels: ChannelSet, temp_cal: ChannelCal) -> Self {
        let channels = ChannelSet(channels.0 & ChannelSet::ALL.0);
        let mut slots = [0u8; crate::wire::CHANNELS];
        let mut width = 0;
        for (slot, c) in slots.iter_mut().zip(channels.iter()) {
            *slot = c.index() as u8;
            width += 1;
        }
        BlockBuilder {
            run_id,
            channels,
            temp_cal,
            slots,
            width,
            temp: None,
            block: 0,
            samples: 0,
            filled: 0,
            current: None,
        }
    }

    /// Samples taken so far.
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Blocks completed so far.
    pub fn blocks(&self) -> u32 {
        self.block
    }

    /// True when the next sample starts a new block (and so needs its time, see
    /// [`BlockBuilder::push`]).
    pub fn starts_block(&self) -> bool {
        self.current.is_none()
    }

    fn temp_count(&mut self, temp_c: f32) -> u16 {
        match self.temp {
            Some((bits, count)) if bits == temp_c.to_bits() => count,
            _ => {
                let count = self.temp_cal.to_count(temp_c);
                self.temp = Some((temp_c.to_bits(), count));
                count
            }
        }
    }

    /// Counts of one sample in the run's channel order (see [`select`]).
    pub fn select(&mut self, s: &AnalogSample, temp_c: f32, out: &mut [u16]) -> usize {
        let temp = self.temp_count(temp_c);
        let mut n = 0;
        for (o, &ch) in out.iter_mut().zip(&self.slots[..self.width]) {
            *o = if ch == Channel::Temperature as u8 {
                temp
            } else {
                s.get(ch as usize).copied().unwrap_or(0)
            };
            n += 1;
        }
        n
    }

    /// Adds one sample taken at `t_us` (only read when the sample starts a block). Returns the
    /// block it completed, if any (its ECR and temperature fields are left for the caller to
    /// fill).
    pub fn push(&mut self, s: &AnalogSample, temp_c: f32, t_us: u64) -> Option<SampleBlock> {
        let mut sel = [0u16; crate::wire::CHANNELS];
        let n = self.select(s, temp_c, &mut sel);
        self.push_selected(&sel[..n], temp_c, t_us)
    }

    /// As [`BlockBuilder::push`], for counts already in the run's channel order (from
    /// [`BlockBuilder::select`]).
    pub fn push_selected(&mut self, counts: &[u16], temp_c: f32, t_us: u64) -> Option<SampleBlock> {
        let blk = self.current.get_or_insert_with(|| SampleBlock {
            run_id: self.run_id,
            block: self.block,
            first_sample: self.samples,
            t_us,
            channels: self.channels,
            ecr_range: 0,
            log10_ecr_ohm: f32::NAN,
            temp_c,
            counts: Counts::default(),
        });
        for &c in counts.iter().take(self.width) {
            // Cannot fail: a block is closed as soon as it holds BLOCK_LEN samples.
            let _ = blk.counts.push(c);
        }
        self.samples += 1;
        self.filled += 1;
        if self.filled >= BLOCK_LEN {
            self.filled = 0;
            self.block += 1;
            return self.current.take();
        }
        None
    }

    /// Closes the partial last block, if any.
    pub fn flush(&mut self) -> Option<SampleBlock> {
        self.filled = 0;
        let b = self.current.take().filter(|b| !b.counts.is_empty());
        if b.is_some() {
            self.block += 1;
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ring_is_fifo_and_counts_every_lost_sample() {
        let mut r: Ring<8> = Ring::new();
        for i in 0..11u16 {
            r.push([i, i + 1, i + 2, i + 3]);
        }
        assert_eq!((r.len(), r.lost()), (8, 3));
        let mut out = [[0u16; 4]; 5];
        assert_eq!(r.pop_into(&mut out), 5);
        assert_eq!(out.map(|s| s[0]), [0, 1, 2, 3, 4]);
        for i in 100..105u16 {
            assert!(r.push([i; 4]));
        }
        assert!(!r.push([0; 4]));
        let mut out = [[0u16; 4]; 10];
        assert_eq!(r.pop_into(&mut out), 8);
        let firsts: Vec<u16> = out[..8].iter().map(|s| s[0]).collect();
        assert_eq!(firsts, [5, 6, 7, 100, 101, 102, 103, 104]);
        assert_eq!(r.lost(), 4);
        r.clear();
        assert_eq!((r.len(), r.lost()), (0, 0));
    }

    #[test]
    fn blocks_hold_the_selected_channels_in_index_order() {
        let set = ChannelSet::VIBROMETER
            .with(Channel::Ecr)
            .with(Channel::Temperature);
        let cal = ChannelCal::unipolar(200.0);
        let mut b = BlockBuilder::new(7, set, cal);
        let mut done = Vec::new();
        for i in 0..(2 * BLOCK_LEN as u16 + 10) {
            if let Some(blk) = b.push(&[i, 1000 + i, 2000 + i, 3000 + i], 50.0, 100 * i as u64) {
                done.push(blk);
            }
        }
        done.extend(b.flush());
        assert_eq!(done.len(), 3);
        assert_eq!(b.samples(), 2 * BLOCK_LEN as u32 + 10);
        for (k, blk) in done.iter().enumerate() {
            assert!(blk.is_consistent());
            assert_eq!(
                (blk.run_id, blk.block, blk.first_sample),
                (7, k as u32, (k * BLOCK_LEN) as u32)
            );
            assert_eq!(blk.t_us, 100 * (k * BLOCK_LEN) as u64);
            let first = (k * BLOCK_LEN) as u16;
            assert_eq!(
                blk.sample(0).unwrap(),
                &[first, 1000 + first, 3000 + first, cal.to_count(50.0)]
            );
        }
        assert_eq!(done[2].samples(), 10);
        assert!(b.flush().is_none());
    }
}
