//! A software model of the whole converter, for tests and the virtual rig: the sample timer, the
//! ADC's scans, the DMA in circular mode over a ring of [`RING_SCANS`] scans, and the board's reading
//! of it (position from NDTR extended by the sample clock, [`RingReader`], restart after an ADC
//! overrun). Only the analog values come from outside: the owner converts each due trigger with
//! the value of its signals at the trigger's time.
//!
//! Two faults can be induced (test flags): a reader that stops reading for a while (the DMA laps
//! it), and an ADC overrun (the DMA stops taking conversions until the reader notices and restarts
//! the converter at the next trigger, exactly as the board does).

use super::clock::{choose, next_trigger};
use super::ring::{
    extend_position, Batch, DmaModel, RingReader, RING_SCANS, RING_WORDS, SCAN_WORDS,
};
use crate::hal::AnalogSample;
use crate::wire::SampleClock;

/// The modelled converter (see the module docs).
#[derive(Debug, Clone)]
pub struct ConverterModel {
    timer_hz: u32,
    clock: Option<SampleClock>,
    running: bool,
    /// Device time the sample timer started (µs); trigger `k` comes `k + 1` periods later.
    start_us: u64,
    /// Latest device time the model was brought to.
    now_us: u64,
    /// Triggers converted (or lost) so far: index of the next one.
    triggers: u64,
    dma: DmaModel<RING_WORDS>,
    reader: RingReader,
    /// An ADC overrun is pending: the next conversion gets half its words through, then the DMA
    /// takes nothing until the reader restarts the converter.
    overrun_pending: bool,
    /// The ADC overran: conversions are lost until the next read.
    overrun: bool,
    /// The reader reads nothing before this device time.
    stalled_until_us: u64,
}

impl ConverterModel {
    /// A stopped converter whose sample timer is clocked at `timer_hz`.
    pub fn new(timer_hz: u32) -> Self {
        ConverterModel {
            timer_hz,
            clock: None,
            running: false,
            start_us: 0,
            now_us: 0,
            triggers: 0,
            dma: DmaModel::new(),
            reader: RingReader::new(RING_SCANS),
            overrun_pending: false,
            overrun: false,
            stalled_until_us: 0,
        }
    }

    /// The clock the timer would run at for `rate_hz`.
    pub fn clock_for(&self, rate_hz: u32) -> Option<SampleClock> {
        choose(self.timer_hz, rate_hz).map(|(_, c)| c)
    }

    /// Starts a new stream at `now_us`: trigger 0 a period later.
    pub fn start(&mut self, rate_hz: u32, now_us: u64) -> Option<SampleClock> {
        let clock = self.clock_for(rate_hz)?;
        self.clock = Some(clock);
        self.running = true;
        self.start_us = now_us;
        self.now_us = now_us;
        self.triggers = 0;
        self.dma.restart();
        self.reader.start();
        self.overrun_pending = false;
        self.overrun = false;
        Some(clock)
    }

    pub fn stop(&mut self) {
        self.running = false;
    }

    pub fn is_running(&self) -> bool {
        self.running
    }

    pub fn clock(&self) -> Option<SampleClock> {
        self.clock
    }

    /// Device time of trigger `k`, µs (rounded down).
    pub fn trigger_time_us(&self, k: u64) -> u64 {
        self.clock
            .map_or(self.start_us, |c| self.start_us + c.time_us(k + 1))
    }

    /// The next trigger, if it is due by `now_us`: its device time. The owner converts it with
    /// [`ConverterModel::convert`] (and asks again).
    pub fn due(&mut self, now_us: u64) -> Option<u64> {
        self.now_us = self.now_us.max(now_us);
        let clock = self.clock.filter(|_| self.running)?;
        let due = clock.samples_in_us(now_us.saturating_sub(self.start_us));
        (self.triggers < due).then(|| self.trigger_time_us(self.triggers))
    }

    /// Converts the due trigger (see [`ConverterModel::due`]) with these values.
    pub fn convert(&mut self, s: &AnalogSample) {
        if !self.running {
            return;
        }
        self.triggers += 1;
        if self.overrun_pending {
            // The overrun strikes mid-scan: two words get through, the rest waits in the ADC.
            self.overrun_pending = false;
            self.overrun = true;
            for &w in s.iter().take(SCAN_WORDS / 2) {
                self.dma.write_word(w);
            }
            return;
        }
        if !self.overrun {
            self.dma.write_scan(s);
        }
    }

    /// Index of the next trigger (what a change made now acts on first).
    pub fn next_index(&self) -> u64 {
        self.triggers
    }

    /// Test flag: the ADC overruns at the next conversion.
    pub fn inject_overrun(&mut self) {
        self.overrun_pending = true;
    }

    /// Test flag: the reader takes nothing until device time `until_us` (the DMA goes on).
    pub fn stall_reader(&mut self, until_us: u64) {
        self.stalled_until_us = until_us;
    }

    /// Reads as the board does: the DMA position from NDTR, extended with the sample clock's
    /// estimate; after an overrun, what the ring holds is read and the converter is restarted at
    /// the next trigger (the samples in between are lost).
    pub fn read(&mut self, out: &mut [AnalogSample]) -> Batch {
        if self.now_us < self.stalled_until_us {
            return Batch {
                first: self.reader.next_index(),
                len: 0,
            };
        }
        let estimate = self.triggers.saturating_sub(self.reader.base()) * SCAN_WORDS as u64;
        let written = extend_position(self.dma.position(), RING_WORDS, estimate);
        let after = self.dma.written();
        let batch = self.reader.read(written, self.dma.ring(), out, || after);
        if self.overrun && batch.len < out.len() {
            // All that got through is read: re-arm. On the board the next trigger's index comes
            // from the timer's counter (clock::next_trigger); here it is known exactly, and the
            // board's arithmetic is checked against it.
            let next = self.clock.map_or(self.triggers, |c| {
                let elapsed_us = self.now_us.saturating_sub(self.start_us);
                let ticks = elapsed_us as u128 * c.timer_hz as u128 / 1_000_000;
                let period = c.ticks_per_sample as u128;
                let counter = (ticks % period) as u32;
                next_trigger(ticks as u64, counter, c.ticks_per_sample)
            });
            debug_assert_eq!(next, self.triggers);
            self.overrun = false;
            self.dma.restart();
            self.reader.restart(self.triggers);
        }
        batch
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(i: u64) -> AnalogSample {
        [i as u16, (i >> 16) as u16, 7, 0xA5A5 ^ i as u16]
    }

    fn run(m: &mut ConverterModel, until_us: u64) {
        while let Some(t) = m.due(until_us) {
            let k = m.next_index();
            assert_eq!(t, m.trigger_time_us(k));
            m.convert(&scan(k));
        }
    }

    fn read_all(m: &mut ConverterModel, got: &mut Vec<u64>, jumps: &mut Vec<(u64, u64)>) {
        let mut out = [[0u16; 4]; 100];
        loop {
            let expect = got.last().map_or(0, |i| i + 1);
            let b = m.read(&mut out);
            if b.first > expect {
                jumps.push((expect, b.first));
            }
            for (k, s) in out[..b.len].iter().enumerate() {
                assert_eq!(s[3], 0xA5A5 ^ s[0]);
                assert_eq!(s[0] as u64 | (s[1] as u64) << 16, b.first + k as u64);
                got.push(b.first + k as u64);
            }
            if b.len < out.len() {
                return;
            }
        }
    }

    #[test]
    fn the_stream_follows_the_timer_and_faults_show_as_exact_jumps() {
        let mut m = ConverterModel::new(200_000_000);
        let c = m.start(10_000, 5_000).unwrap();
        assert!(c.is_exactly(10_000));
        let (mut got, mut jumps) = (Vec::new(), Vec::new());
        // 1 ms polls for 0.5 s.
        for ms in 1..=500 {
            run(&mut m, 5_000 + ms * 1000);
            read_all(&mut m, &mut got, &mut jumps);
        }
        assert_eq!(got.len(), 5_000);
        assert!(jumps.is_empty());
        // The reader stalls 300 ms: 3000 samples for a 2048-scan ring.
        m.stall_reader(5_000 + 800_000);
        for ms in 501..=900 {
            run(&mut m, 5_000 + ms * 1000);
            read_all(&mut m, &mut got, &mut jumps);
        }
        // While stalled (at 800 ms, 8 000 samples due), the ring kept the last 2048.
        assert_eq!(jumps, [(5_000, 8_000 - RING_SCANS as u64)]);
        // An ADC overrun: the next conversion gets half through, the reader notices at its next read
        // and restarts the converter at the next trigger.
        m.inject_overrun();
        run(&mut m, 5_000 + 900_350);
        let overrun_at = 9_000;
        read_all(&mut m, &mut got, &mut jumps);
        run(&mut m, 5_000 + 901_000);
        read_all(&mut m, &mut got, &mut jumps);
        assert_eq!(jumps.len(), 2);
        // Lost: the half-written scan 9000 and the two converted while the DMA was blocked.
        assert_eq!(jumps[1], (overrun_at, overrun_at + 3));
        assert_eq!(*got.last().unwrap(), 9_009);
        assert_eq!(m.next_index(), 9_010);
    }
}
