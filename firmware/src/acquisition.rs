//! Acquisition: the hardware-timed stream of analog samples and its assembly into the wire's
//! [`SampleBlock`]s.
//!
//! * [`clock`]: the sample clock (timer prescaler and reload for a rate, the rate really produced),
//!   the ADC's scan timing, and the trigger index after a converter restart.
//! * [`ring`]: the DMA ring and its reader, which gives every sample the index the DMA wrote it at
//!   and reports lost samples as a jump in index, exactly.
//! * [`model`]: a software model of the whole converter (timer, DMA ring, reader, induced
//!   faults) for tests and the virtual rig.
//! * [`BlockBuilder`]: the run's samples, by index, into blocks of consecutive samples; a gap closes
//!   the block in progress, so no block ever spans one.

pub mod clock;
pub mod model;
pub mod ring;

pub use clock::{choose, TimerSetting};
pub use model::ConverterModel;
pub use ring::{extend_position, Batch, DmaModel, RingReader, RingView, RING_SCANS, RING_WORDS};

use crate::hal::AnalogSample;
use crate::wire::{Channel, ChannelCal, ChannelSet, Counts, SampleBlock, SampleClock, BLOCK_LEN};

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

/// Assembles the samples of a run into blocks of at most [`BLOCK_LEN`] consecutive samples of the
/// run's channels. Samples come with their index in the run; after a gap the block in progress is
/// closed and the next one starts at the first sample after the gap, so a block's `first_sample`
/// and the sample clock place every sample on the time axis.
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
    /// Samples in `current`.
    filled: usize,
    clock: SampleClock,
    start_us: u64,
    block: u32,
    /// Index in the run of the next sample expected.
    next: u32,
    /// Samples taken (lost ones not counted).
    samples: u32,
    current: Option<SampleBlock>,
}

impl BlockBuilder {
    /// A builder for run `run_id`, whose sample 0 is at device time `start_us` and whose samples
    /// follow `clock`.
    pub fn new(
        run_id: u32,
        channels: ChannelSet,
        temp_cal: ChannelCal,
        clock: SampleClock,
        start_us: u64,
    ) -> Self {
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
            filled: 0,
            clock,
            start_us,
            block: 0,
            next: 0,
            samples: 0,
            current: None,
        }
    }

    /// Samples taken so far (lost ones not counted).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Index in the run of the next sample expected (samples taken + samples lost).
    pub fn next_index(&self) -> u32 {
        self.next
    }

    /// Blocks completed so far.
    pub fn blocks(&self) -> u32 {
        self.block
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

    /// Counts of one sample in the run's channel order (as [`select`] gives them).
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

    /// The samples before run index `index` that were not pushed are lost: closes the block in
    /// progress (returned, if it holds any sample) so that the next one starts after the gap.
    pub fn gap(&mut self, index: u32) -> Option<SampleBlock> {
        if index <= self.next {
            return None;
        }
        self.next = index;
        self.flush()
    }

    /// Adds sample `index` of the run (at or after [`BlockBuilder::next_index`]; an index further on
    /// is a gap, see [`BlockBuilder::gap`], which the caller handles first). Returns the block it
    /// completed, if any (its ECR and temperature fields are left for the caller to fill).
    pub fn push(&mut self, s: &AnalogSample, temp_c: f32, index: u32) -> Option<SampleBlock> {
        let mut sel = [0u16; crate::wire::CHANNELS];
        let n = self.select(s, temp_c, &mut sel);
        self.push_selected(&sel[..n], temp_c, index)
    }

    /// As [`BlockBuilder::push`], for counts already in the run's channel order (from
    /// [`BlockBuilder::select`]).
    pub fn push_selected(
        &mut self,
        counts: &[u16],
        temp_c: f32,
        index: u32,
    ) -> Option<SampleBlock> {
        // A sample behind the stream (cannot happen with a ring reader) is ignored rather than
        // placed twice.
        if index < self.next {
            return None;
        }
        if index > self.next {
            // A caller that did not report a gap: the block in progress is closed here and
            // returned, and this sample starts the next one (a one-sample block is never complete,
            // so at most one block comes back).
            let closed = self.gap(index);
            let done = self.add(counts, temp_c);
            return closed.or(done);
        }
        // The usual case, without moving two optional blocks (a block is 700 bytes).
        self.add(counts, temp_c)
    }

    fn start_block(&mut self, temp_c: f32) {
        let index = self.next;
        self.current = Some(SampleBlock {
            run_id: self.run_id,
            block: self.block,
            first_sample: index,
            t_us: self.start_us + self.clock.time_us(index as u64),
            channels: self.channels,
            ecr_range: 0,
            log10_ecr_ohm: f32::NAN,
            temp_c,
            counts: Counts::default(),
        });
    }

    fn add(&mut self, counts: &[u16], temp_c: f32) -> Option<SampleBlock> {
        if self.current.is_none() {
            self.start_block(temp_c);
        }
        let blk = self.current.as_mut()?;
        for &c in counts.iter().take(self.width) {
            // Cannot fail: a block is closed as soon as it holds BLOCK_LEN samples.
            let _ = blk.counts.push(c);
        }
        self.samples += 1;
        self.next += 1;
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

    const CLOCK: SampleClock = SampleClock {
        timer_hz: 200_000_000,
        ticks_per_sample: 20_000,
    };

    #[test]
    fn blocks_hold_the_selected_channels_in_index_order() {
        let set = ChannelSet::VIBROMETER
            .with(Channel::Ecr)
            .with(Channel::Temperature);
        let cal = ChannelCal::unipolar(200.0);
        let mut b = BlockBuilder::new(7, set, cal, CLOCK, 1_000);
        let mut done = Vec::new();
        for i in 0..(2 * BLOCK_LEN as u16 + 10) {
            if let Some(blk) = b.push(&[i, 1000 + i, 2000 + i, 3000 + i], 50.0, i as u32) {
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
            // 10 kS/s: 100 µs per sample, from the run's start.
            assert_eq!(blk.t_us, 1_000 + 100 * (k * BLOCK_LEN) as u64);
            let first = (k * BLOCK_LEN) as u16;
            assert_eq!(
                blk.sample(0).unwrap(),
                &[first, 1000 + first, 3000 + first, cal.to_count(50.0)]
            );
        }
        assert_eq!(done[2].samples(), 10);
        assert!(b.flush().is_none());
    }

    #[test]
    fn a_gap_closes_the_block_and_the_next_one_starts_after_it() {
        let mut b = BlockBuilder::new(
            1,
            ChannelSet::VIBROMETER,
            ChannelCal::unipolar(200.0),
            CLOCK,
            0,
        );
        let mut done = Vec::new();
        for i in 0..70u32 {
            done.extend(b.push(&[i as u16, 0, 0, 0], 20.0, i));
        }
        // Samples 70..100 are lost.
        done.extend(b.gap(100));
        assert_eq!(b.next_index(), 100);
        for i in 100..180u32 {
            done.extend(b.push(&[i as u16, 0, 0, 0], 20.0, i));
        }
        // A caller that forgets the gap still gets the block closed (and the sample kept).
        done.extend(b.push(&[500, 0, 0, 0], 20.0, 500));
        done.extend(b.flush());
        let spans: Vec<(u32, u32, usize)> = done
            .iter()
            .map(|k| (k.block, k.first_sample, k.samples()))
            .collect();
        assert_eq!(
            spans,
            [
                (0, 0, 64),
                (1, 64, 6),
                (2, 100, 64),
                (3, 164, 16),
                (4, 500, 1)
            ]
        );
        for blk in &done {
            // Every count is its own index: no sample moved across a gap.
            let x: Vec<u32> = blk.channel(Channel::Displacement).map(u32::from).collect();
            let want: Vec<u32> = (blk.first_sample..blk.first_sample + x.len() as u32).collect();
            assert_eq!(x, want);
            assert_eq!(blk.t_us, CLOCK.time_us(blk.first_sample as u64));
        }
        assert_eq!(b.samples(), 70 + 80 + 1);
        // A sample from before the stream's position is never placed twice.
        assert!(b.push(&[0; 4], 20.0, 3).is_none());
        assert_eq!(b.samples(), 151);
    }
}
